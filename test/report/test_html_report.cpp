// The report library: its pieces, gnuplot as a child process, and the page from a simulated
// sticky loop.
#include <doctest/doctest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <map>
#include <string>

#include "page_checks.hpp"
#include "valvediag/report/diagnosis_report.hpp"
#include "valvediag/report/gnuplot.hpp"
#include "valvediag/report/html_report.hpp"
#include "valvediag/sim/scenarios.hpp"

using namespace valvediag;
using report_test::check_self_contained;
using report_test::count;
using report_test::figure;
using report_test::has;
using report_test::has_plot;

TEST_CASE("html_escape: markup characters as entities, bad bytes replaced, UTF-8 kept") {
  CHECK(html_escape("<a href=\"x\">&'") == "&lt;a href=&quot;x&quot;&gt;&amp;&#39;");
  CHECK(html_escape("\xC2\xB5m, 5 \xE2\x80\x93 6") == "\xC2\xB5m, 5 \xE2\x80\x93 6");
  CHECK(html_escape("a\xFFz") == "a\xEF\xBF\xBDz");
  CHECK(html_escape("\xC0\xAF") == "\xEF\xBF\xBD\xEF\xBF\xBD");  // overlong '/'
  CHECK(html_escape("x\x01y\tz\n") == "x\xEF\xBF\xBDy\tz\n");
  CHECK(html_escape("\xE2\x82") == "\xEF\xBF\xBD\xEF\xBF\xBD");  // truncated sequence
}

TEST_CASE("minmax_decimate keeps the spikes, the ends and the time order") {
  std::vector<double> y(10000);
  for (std::size_t k = 0; k < y.size(); ++k) y[k] = std::sin(0.001 * static_cast<double>(k));
  y[5003] = 50.0;
  y[7777] = -50.0;
  const auto idx = minmax_decimate(y, 0, y.size(), 300);
  CHECK(idx.size() <= 601);
  CHECK(idx.front() == 0);
  CHECK(idx.back() == y.size() - 1);
  for (std::size_t i = 1; i < idx.size(); ++i) CHECK(idx[i] > idx[i - 1]);
  CHECK(std::find(idx.begin(), idx.end(), 5003u) != idx.end());
  CHECK(std::find(idx.begin(), idx.end(), 7777u) != idx.end());
  // Short ranges are kept whole; a sub-range stays inside its bounds.
  CHECK(minmax_decimate(y, 100, 400, 300).size() == 300);
  const auto sub = minmax_decimate(y, 2000, 9000, 100);
  CHECK(sub.front() >= 2000);
  CHECK(sub.back() == 8999);
  CHECK(minmax_decimate(y, 5, 5, 10).empty());
}

TEST_CASE("Bode and step response of the linear block") {
  // y(t) = 0.9 y(t-1) + 0.1 x(t-1): static gain 1, at Nyquist 0.1 / 1.9 and -180 degrees.
  const std::vector<double> a{-0.9}, b{0.1};
  const FrequencyResponse r = frequency_response(a, b, 0, false, 0.5, 200);
  REQUIRE(r.f_hz.size() == 200);
  CHECK(r.f_hz.back() == doctest::Approx(1.0));  // Nyquist at Ts = 0.5 s
  CHECK(r.f_hz.front() == doctest::Approx(0.001));
  CHECK(r.magnitude_db.front() == doctest::Approx(0.0).epsilon(0.01).scale(1));
  CHECK(r.magnitude_db.back() == doctest::Approx(20 * std::log10(0.1 / 1.9)).epsilon(1e-6));
  CHECK(r.phase_deg.back() == doctest::Approx(-180.0).epsilon(1e-6));
  for (std::size_t k = 1; k < r.f_hz.size(); ++k) CHECK(r.phase_deg[k] <= r.phase_deg[k - 1]);
  // A delay of 10 samples: the phase falls far below -360 degrees, unwrapped without jumps.
  const FrequencyResponse d = frequency_response(a, b, 9, false, 0.5, 400);
  CHECK(d.phase_deg.back() < -1000.0);
  for (std::size_t k = 1; k < d.f_hz.size(); ++k)
    CHECK(std::abs(d.phase_deg[k] - d.phase_deg[k - 1]) < 90.0);

  const auto y = step_response(a, b, 2, false, 200);
  CHECK(y[0] == 0.0);
  CHECK(y[2] == 0.0);  // nk = 2: the output moves at sample 3
  CHECK(y[3] == doctest::Approx(0.1));
  CHECK(y[4] == doctest::Approx(0.19));
  CHECK(y.back() == doctest::Approx(1.0).epsilon(1e-6));
  const std::size_t n = settling_samples(a, b, 0, false, 1000);
  CHECK(n >= 44);  // 0.9^k < 1 % from k = 44
  CHECK(n <= 80);
  // Integrating: A = (1 - 0.5 q^-1)(1 - q^-1), the step response ends as a ramp of slope 2.
  const auto ramp = step_response({-0.5}, {1.0}, 0, true, 100);
  CHECK(ramp[99] - ramp[98] == doctest::Approx(2.0));
  const FrequencyResponse ri = frequency_response({-0.5}, {1.0}, 0, true, 1.0, 100);
  CHECK(ri.magnitude_db.front() > 40.0);  // 1 / (1 - q^-1) grows without bound at 0
}

TEST_CASE("inline_svg: declaration dropped, ids and references prefixed") {
  const std::string svg =
      "<?xml version=\"1.0\"?>\n<svg width='10'><defs><path id='gpPt0' d='M0,0'/></defs>"
      "<use xlink:href='#gpPt0'/><g id=\"clip\" clip-path=\"url(#clip)\"></g></svg>\n\n";
  const std::string s = inline_svg(svg, "plot-x");
  CHECK(s.rfind("<svg", 0) == 0);
  CHECK(s.find("<?xml") == std::string::npos);
  CHECK(s.find("id='plot-x-gpPt0'") != std::string::npos);
  CHECK(s.find("href='#plot-x-gpPt0'") != std::string::npos);
  CHECK(s.find("id=\"plot-x-clip\"") != std::string::npos);
  CHECK(s.find("url(#plot-x-clip)") != std::string::npos);
  CHECK(s.back() == '>');
}

TEST_CASE("gnuplot runs as a child: SVG back, errors and hangs reported, no shell") {
  SUBCASE("an SVG comes back on standard output, also when it is larger than a pipe") {
    std::string script = "set terminal svg size 400,300\n$D << EOD\n";
    for (int k = 0; k < 20000; ++k)
      script += std::to_string(k) + " " + std::to_string(std::sin(0.37 * k)) + "\n";
    script += "EOD\nplot $D with lines\n";
    REQUIRE(script.size() > 200000);
    const std::string svg = gnuplot_run(script);
    CHECK(svg.find("<svg") != std::string::npos);
    CHECK(svg.find("</svg>") != std::string::npos);
    CHECK(svg.size() > 65536);
  }
  SUBCASE("a program that does not exist: GnuplotMissing naming the package") {
    GnuplotOptions o;
    o.program = "/nonexistent/dir/gnuplot";
    try {
      gnuplot_run("plot x\n", o);
      FAIL("expected GnuplotMissing");
    } catch (const GnuplotMissing& e) {
      CHECK(std::string(e.what()).find("gnuplot-nox") != std::string::npos);
      CHECK(std::string(e.what()).find("/nonexistent/dir/gnuplot") != std::string::npos);
    }
  }
  SUBCASE("a script error: GnuplotError with gnuplot's own message") {
    try {
      gnuplot_run("set terminal svg\nplot no_such_function(x)\n");
      FAIL("expected GnuplotError");
    } catch (const GnuplotError& e) {
      CHECK(std::string(e.what()).find("no_such_function") != std::string::npos);
    }
  }
  SUBCASE("a hanging gnuplot is stopped at the time limit") {
    GnuplotOptions o;
    o.timeout_s = 0.5;
    const auto t0 = std::chrono::steady_clock::now();
    CHECK_THROWS_AS(gnuplot_run("pause 30\n", o), GnuplotError);
    CHECK(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() < 5.0);
  }
  SUBCASE("a child that exits without reading does not take us down with SIGPIPE") {
    GnuplotOptions o;
    o.program = "true";
    const std::string big(1 << 20, '#');
    CHECK(gnuplot_run(big, o).empty());
  }
  SUBCASE("gnuplot_quote") {
    CHECK(gnuplot_quote("it's") == "'it''s'");
    CHECK(gnuplot_quote("a\nb") == "'a b'");
  }
}

namespace {

struct Fixture {
  LoopData d;
  ModelFit fit;
  ResidualAnalysis where;
  std::vector<HistoryEntry> ladder;

  Fixture(const std::string& scenario, const std::string& model, std::size_t samples) {
    d = run_scenario(scenario_by_name(scenario), 1, samples);
    ModelFitOptions mo;
    mo.validation_fraction = 0.3;
    mo.preisach_L_max = 12;
    fit = fit_model(d.op, d.pv, d.sample_period(), parse_model_spec(model), mo);
    REQUIRE(fit.status != ModelFitStatus::NoStableModel);
    ResidualAnalysisOptions ro;
    ro.model_delay = static_cast<std::size_t>(fit.structure.nk + 1);
    where = analyse_residual(d.op, d.pv, fit.y_sim, fit.first_sample, fit.estimation_end, ro);
    HistoryEntry lin;
    lin.model = "linear";
    lin.fitness_percent = 80;
    lin.validation_fitness_percent = -7;
    ladder = {lin, history_entry(fit, "test")};
  }
  ReportContent content() const {
    ReportContent c;
    c.data = &d;
    c.data_name = "sticky <loop> & \"friends\".csv";
    c.fit = &fit;
    c.where = &where;
    c.ladder = ladder;
    c.notes = {"a note with <markup>"};
    return c;
  }
};

// Several pages are drawn from the same record and fit: each is fitted once, and a case gets a
// copy it may change.
Fixture shared_fixture(const std::string& scenario, const std::string& model, std::size_t samples) {
  static std::map<std::string, Fixture> made;
  const std::string key = scenario + " " + model + " " + std::to_string(samples);
  auto it = made.find(key);
  if (it == made.end()) it = made.emplace(key, Fixture(scenario, model, samples)).first;
  return it->second;
}

}  // namespace

TEST_CASE("the page of a sticky loop: every plot, the shading, the triangle, all text escaped") {
  Fixture fx = shared_fixture("paper-ex1", "preisach:general", 1500);
  REQUIRE(!fx.where.intervals.empty());
  const HtmlReport r = html_report(fx.content());
  const std::string& h = r.html;
  check_self_contained(h);
  CHECK(r.warnings.empty());
  CHECK(r.plots.size() == 10);
  for (const char* id :
       {"plot-trends", "plot-fit", "plot-residual", "plot-resid", "plot-pv-op", "plot-signature",
        "plot-preisach", "plot-bode", "plot-step", "plot-ladder"})
    CHECK_MESSAGE(has_plot(h, id), id);
  // Failing intervals shaded (gnuplot draws the rectangles as filled polygons in #f4b6b6).
  CHECK(count(figure(h, "plot-fit"), "rgb(244, 182, 182)") >= fx.where.intervals.size());
  CHECK(count(figure(h, "plot-residual"), "rgb(244, 182, 182)") >= fx.where.intervals.size());
  CHECK(figure(h, "plot-fit").find("where the model fails") != std::string::npos);
  CHECK(figure(h, "plot-preisach").find("nonzero weights") != std::string::npos);
  CHECK(figure(h, "plot-bode").find("phase (deg)") != std::string::npos);
  CHECK(figure(h, "plot-bode").find("|G| (dB)") != std::string::npos);
  CHECK(figure(h, "plot-step").find("unit step") != std::string::npos);
  // The residual tests: both panels with their 99 % bands, and what each lag outside means.
  const std::string resid = figure(h, "plot-resid");
  CHECK(count(resid, "99 % band") >= 2);
  CHECK(resid.find("on the estimation part (") != std::string::npos);
  CHECK(resid.find("positive lags outside") != std::string::npos);
  CHECK(figure(h, "plot-ladder").find("validation") != std::string::npos);
  CHECK(h.find("id=\"where-intervals\"") != std::string::npos);
  CHECK(h.find("id=\"ladder-table\"") != std::string::npos);
  CHECK(h.find("Not diagnosed") != std::string::npos);  // no diagnosis given
  // Escaped, never raw.
  CHECK(h.find("sticky &lt;loop&gt; &amp; &quot;friends&quot;.csv") != std::string::npos);
  CHECK(h.find("<loop>") == std::string::npos);
  CHECK(h.find("a note with &lt;markup&gt;") != std::string::npos);
  CHECK(h.find("GNUPLOT") != std::string::npos);  // the footer names the plotting tool
}

TEST_CASE("time axes on the data's own clock when it has date-time stamps, else t in seconds") {
  Fixture fx = shared_fixture("paper-ex1", "preisach:general", 1500);
  REQUIRE(!fx.where.intervals.empty());
  const std::string plain = html_report(fx.content()).html;
  CHECK(figure(plain, "plot-trends").find("t (s)") != std::string::npos);
  CHECK(plain.find("time stamps</th>") == std::string::npos);
  // t = 0 at 2024-09-01 21:55:00 of the historian's stamps (day 19967 since 1970-01-01); the
  // 1500 samples at Ts 0.5 s end at 22:07:29.5.
  fx.d.clock_at_zero_s = 19967.0 * 86400 + 21 * 3600 + 55 * 60;
  const HtmlReport r = html_report(fx.content());
  const std::string& h = r.html;
  CHECK(r.warnings.empty());
  for (const char* id : {"plot-trends", "plot-fit", "plot-residual"}) {
    const std::string f = figure(h, id);
    CHECK_MESSAGE(f.find("time: 2024-09-01 21:55:00 .. 2024-09-01 22:07:29") != std::string::npos,
                  id);
    CHECK_MESSAGE(f.find(">22:00<") != std::string::npos, id);  // a tick label on the clock
    CHECK_MESSAGE(f.find("t (s)") == std::string::npos, id);
  }
  // The failing intervals are still shaded, now on the clock's axis.
  CHECK(count(figure(h, "plot-fit"), "rgb(244, 182, 182)") >= fx.where.intervals.size());
  CHECK(h.find("<th>time stamps</th><td>2024-09-01 21:55:00 .. 2024-09-01 22:07:29") !=
        std::string::npos);
  const auto& iv = fx.where.intervals.front();
  char from[16];
  const int s0 = static_cast<int>(fx.d.t[iv.begin]);
  std::snprintf(from, sizeof from, "%02d:%02d:%02d", 21 + (55 * 60 + s0) / 3600,
                (55 * 60 + s0) / 60 % 60, s0 % 60);
  CHECK(h.find(std::string("<td>2024-09-01 ") + from + "</td>") != std::string::npos);
}

TEST_CASE("a diagnosis's limit cycle shows as a row of the summary, escaped") {
  Fixture fx = shared_fixture("paper-ex1", "preisach:general", 1500);
  Diagnosis dg;
  dg.steps.push_back({fx.fit, fx.where, {}, {}});
  dg.limit_cycle.oscillating = true;
  dg.limit_cycle.summary = "PV oscillates <odd>";
  ReportContent c = fx.content();
  c.diagnosis = &dg;
  const std::string h = html_report(c).html;
  CHECK(h.find(">limit cycle<") != std::string::npos);
  CHECK(h.find("PV oscillates &lt;odd&gt;") != std::string::npos);
  dg.limit_cycle.oscillating = false;
  CHECK(html_report(c).html.find(">limit cycle<") == std::string::npos);
}

TEST_CASE("a recorded valve position: its signature beside the model's, and the test's row") {
  Fixture fx = shared_fixture("paper-ex1", "preisach:general", 1500);
  REQUIRE(fx.d.has_mv());
  Diagnosis dg;
  dg.steps.push_back({fx.fit, fx.where, {}, {}});
  dg.valve_travel.tested = dg.valve_travel.decided = true;
  dg.valve_travel.verdict = "stiction";
  dg.valve_travel.summary = "the measured valve position has friction <8.4>";
  ReportContent c = fx.content();
  c.diagnosis = &dg;
  const std::string h = html_report(c).html;
  const std::string sig = figure(h, "plot-signature");
  CHECK(sig.find("measured position (MV)") != std::string::npos);
  CHECK(sig.find("measured valve position (%)") != std::string::npos);  // own axis: Preisach units
  CHECK(sig.find("valve-travel test") != std::string::npos);
  CHECK(h.find(">valve travel<") != std::string::npos);
  CHECK(h.find("has friction &lt;8.4&gt;") != std::string::npos);
  fx.d.mv.clear();  // not recorded: the model's signature alone, no row
  dg.valve_travel = {};
  const std::string n = html_report(c).html;
  CHECK(figure(n, "plot-signature").find("measured position (MV)") == std::string::npos);
  CHECK(n.find(">valve travel<") == std::string::npos);
}

TEST_CASE("a model without a Preisach valve: a note in place of the triangle") {
  Fixture fx("paper-ex1", "stiction", 1500);
  const HtmlReport r = html_report(fx.content());
  check_self_contained(r.html);
  CHECK(!has_plot(r.html, "plot-preisach"));
  CHECK(figure(r.html, "plot-preisach").find("--model preisach") != std::string::npos);
  CHECK(has_plot(r.html, "plot-signature"));
  CHECK(has_plot(r.html, "plot-bode"));
  CHECK(r.plots.size() == 9);
  // In % of OP: the y = x of a valve that follows OP, and the direction of travel in two colours.
  const std::string sig = figure(r.html, "plot-signature");
  CHECK(sig.find("y = x") != std::string::npos);
  CHECK(sig.find("OP rising") != std::string::npos);
  CHECK(sig.find("OP falling") != std::string::npos);
  CHECK(figure(r.html, "plot-pv-op").find("OP falling") != std::string::npos);
}

TEST_CASE("gnuplot missing: an error, or the page with notes in place of the plots") {
  Fixture fx = shared_fixture("linear-clean", "linear", 1000);
  ReportOptions o;
  o.gnuplot.program = "/nonexistent/gnuplot";
  CHECK_THROWS_AS(html_report(fx.content(), o), GnuplotMissing);
  o.require_plots = false;
  const HtmlReport r = html_report(fx.content(), o);
  check_self_contained(r.html);
  CHECK(r.plots.empty());
  CHECK(r.html.find("<svg") == std::string::npos);
  CHECK(count(r.html, "gnuplot-nox") >= 9);  // each plot but the triangle (no Preisach valve)
  CHECK(!r.warnings.empty());
  ReportOptions none;
  none.plots = false;
  const HtmlReport q = html_report(fx.content(), none);
  CHECK(q.html.find("<svg") == std::string::npos);
  CHECK(q.html.find("--no-plots") != std::string::npos);
}

TEST_CASE("a long record stays small: plots are decimated") {
  Fixture fx("linear-clean", "linear", 25000);
  const HtmlReport r = html_report(fx.content());
  check_self_contained(r.html);
  CHECK(r.plots.size() == 9);  // no Preisach valve in `linear`
  MESSAGE("HTML size for 25000 samples: " << r.html.size() / 1024 << " KB, gnuplot "
                                          << r.plot_seconds << " s");
  CHECK(r.html.size() < 800 * 1024);
}

TEST_CASE("html_report refuses a fit that does not belong to the data") {
  Fixture fx = shared_fixture("linear-clean", "linear", 1000);
  LoopData other = fx.d;
  other.t.resize(500);
  other.op.resize(500);
  other.pv.resize(500);
  ReportContent c = fx.content();
  c.data = &other;
  CHECK_THROWS_AS(html_report(c), std::invalid_argument);
  c.fit = nullptr;
  CHECK_THROWS_AS(html_report(c), std::invalid_argument);
}

TEST_CASE("the page of a record without a model: why, the loop-health figures, OP's trend") {
  LoopData d = run_scenario(scenario_by_name("paper-ex1"), 1, 1500);
  d.pv.clear();  // OP alone, as the stiction database's benchmark loops
  d.sp.clear();
  d.mv.clear();
  LoopHealth h;
  h.oscillating = true;
  h.period_s = 118.4;
  h.amplitude = 6.25;
  h.regularity = 4.2;
  h.signal = "op";
  h.op_reversals_per_hour = 61;
  h.op_noise = 0.05;
  DataPageContent c;
  c.data = &d;
  c.data_name = "bench <mat> & loop";
  c.verdict = "not-enough-data";
  c.reason = "no PV in the record (OP only)";
  c.health = &h;
  c.notes = {"read <loop>"};
  const HtmlReport r = html_data_page(c);
  const std::string& p = r.html;
  check_self_contained(p);
  CHECK(r.warnings.empty());
  CHECK(r.plots == std::vector<std::string>{"plot-trends"});
  CHECK(has_plot(p, "plot-trends"));
  CHECK(has(figure(p, "plot-trends"), "Trend: OP"));
  CHECK(has(figure(p, "plot-trends"), "PV was not recorded"));
  CHECK(has(figure(p, "plot-trends"), "<text>OP</text>"));
  CHECK_FALSE(has(figure(p, "plot-trends"), "<text>PV</text>"));
  CHECK(has(p, "<tr><th>recorded</th><td>OP</td></tr>"));
  CHECK(has(p, "<tr><th>model</th><td>none</td></tr>"));
  CHECK(has(p, "<tr><th>why</th><td>no PV in the record (OP only)</td></tr>"));
  CHECK(has(p, "<span class=\"verdict\">not-enough-data</span>"));
  CHECK(has(p, "yes, in OP: period 118 s, amplitude 6.250, regularity 4.20"));
  CHECK(has(p, "61.0 per hour (beyond the OP noise band 0.05)"));
  CHECK(has(p, "bench &lt;mat&gt; &amp; loop"));
  CHECK(has(p, "read &lt;loop&gt;"));
  CHECK_FALSE(has(p, "<mat>"));

  // With PV: both panels; a PV of another length is refused, as is no data.
  LoopData full = run_scenario(scenario_by_name("paper-ex1"), 1, 1500);
  c.data = &full;
  c.health = nullptr;
  c.findings = {{"whole record", "a slow load fits it better <97.8 %>"}};
  const std::string q = html_data_page(c).html;
  CHECK(has(figure(q, "plot-trends"), "Trends: OP, PV and SP"));
  CHECK_FALSE(has(q, "id=\"health\""));
  CHECK(has(q, "<tr><th>whole record</th><td>a slow load fits it better &lt;97.8 %&gt;</td></tr>"));
  full.pv.resize(10);
  CHECK_THROWS_AS(html_data_page(c), std::invalid_argument);
  c.data = nullptr;
  CHECK_THROWS_AS(html_data_page(c), std::invalid_argument);
}

TEST_CASE("the ladder table: one row per model, estimation and validation changes apart") {
  auto entry = [](const char* model, double est, double val) {
    HistoryEntry e;
    e.model = model;
    e.fitness_percent = est;
    e.validation_fitness_percent = val;
    return e;
  };
  // A climb run twice, then a fit without a held-out part.
  const std::vector<HistoryEntry> h = {entry("linear", 80.0, 60.0), entry("stiction", 90.0, 85.5),
                                       entry("linear", 81.0, 61.0), entry("stiction", 91.0, 86.0),
                                       entry("stiction+disturbance", 93.5, NAN)};
  const std::string t = format_ladder(h);
  INFO(t);
  std::vector<std::string> lines;
  for (std::size_t a = 0, b; (b = t.find('\n', a)) != std::string::npos; a = b + 1)
    lines.push_back(t.substr(a, b - a));
  REQUIRE(lines.size() == 5);  // header, three models, the note on the two left out
  CHECK(lines[0].find("estimation    change  validation    change") != std::string::npos);
  CHECK(lines[1].find("linear") != std::string::npos);
  CHECK(lines[1].find("81.00 %") != std::string::npos);  // its latest fit
  // The changes against the row above, each part in its own column.
  CHECK(lines[2].find("91.00 %    +10.00     86.00 %    +25.00") != std::string::npos);
  // No held-out part: a dash, never "n/a%" or a change against nothing.
  CHECK(lines[3].find("93.50 %     +2.50           -         -") != std::string::npos);
  CHECK(t.find("n/a") == std::string::npos);
  CHECK(lines[4].find("2 earlier fits") != std::string::npos);
}
