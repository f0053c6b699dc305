// One loop's assessment on simulated loops with a known answer, the results' JSON round trip,
// ranking, the results store's trend, and the isolated job runner (time limit, crash, exception).
#include <doctest/doctest.h>
#include <sqlite3.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <stdexcept>
#include <string>
#include <system_error>
#include <thread>
#include <utility>

#include "../../src/cli/isolated_jobs.hpp"
#include "../common/plant_csv.hpp"
#include "../common/sanitized.hpp"
#include "../common/sqlite_exec.hpp"
#include "valvediag/diagnose/verdict.hpp"
#include "valvediag/io/csv_reader.hpp"
#include "valvediag/model/model_fit.hpp"
#include "valvediag/model/model_spec.hpp"
#include "valvediag/report/sweep_report.hpp"
#include "valvediag/sim/scenarios.hpp"
#include "valvediag/sweep/loop_assessment.hpp"
#include "valvediag/sweep/sweep_store.hpp"

using namespace valvediag;
namespace fs = std::filesystem;

namespace {

// A database file and the -wal and -shm files SQLite keeps beside it, removed when the test ends.
// Declared before the connections, so they are closed first: a database removed while still open
// leaves its -wal and -shm behind.
struct TempDb {
  fs::path path;
  explicit TempDb(fs::path p) : path(std::move(p)) { remove(); }
  ~TempDb() { remove(); }
  TempDb(const TempDb&) = delete;
  TempDb& operator=(const TempDb&) = delete;
  void remove() const {
    for (const char* suffix : {"", "-wal", "-shm"}) {
      std::error_code ec;
      fs::remove(path.string() + suffix, ec);
    }
  }
};

}  // namespace

constexpr std::size_t kSamples = 3000;

TEST_CASE("assess_loop: a sticky loop is called stiction with its band, a clean one is not" *
          valvediag::test::release_only()) {
  const LoopData sticky = run_scenario(scenario_by_name("paper-ex1"), 1, kSamples);
  const LoopAssessment s = assess_loop(sticky, "FIC101");
  INFO(s.reason);
  CHECK(s.verdict == "stiction");
  CHECK(s.error.empty());
  REQUIRE(s.ladder.size() >= 2);
  CHECK(s.ladder.front().model == "linear");
  CHECK(!s.first_missing.empty());
  CHECK(s.validation_fitness_percent > s.ladder.front().validation_fitness_percent + 2.0);
  CHECK(s.severity >= 6.0);
  CHECK(s.health.op_reversals_per_hour > 0);

  const LoopData clean = run_scenario(scenario_by_name("linear-clean"), 1, kSamples);
  const LoopAssessment c = assess_loop(clean, "FIC102");
  INFO(c.reason);
  CHECK(c.verdict == "no-valve-problem");
  CHECK(std::isnan(c.stiction_percent));
  CHECK(c.severity < 3.0);

  LoopData idle = clean;
  for (auto& u : idle.op) u = 40.0;
  const LoopAssessment i = assess_loop(idle, "FIC103");
  CHECK(i.verdict == "not-enough-data");
  CHECK(i.reason.find("OP does not move") == 0);
  CHECK(i.severity == 0.0);

  // OP alone (a .mat benchmark loop) cycling with a 2-minute period: not judged, but ranked
  // above an idle loop.
  LoopData op_only;
  for (int k = 0; k < 3000; ++k) {
    op_only.t.push_back(k);
    op_only.op.push_back(50.0 + 5.0 * std::sin(2.0 * M_PI * k / 120.0) + 0.1 * std::sin(0.9 * k));
  }
  const LoopAssessment o = assess_loop(op_only, "FIC104");
  CHECK(o.verdict == "not-enough-data");
  CHECK(o.reason.find("no PV in the record") == 0);
  CHECK(o.health.oscillating);
  CHECK(o.health.period_s == doctest::Approx(120).epsilon(0.05));
  CHECK(o.severity == 1.0);
  std::vector<LoopAssessment> v{i, o};
  rank(v);
  CHECK(v.front().loop == "FIC104");
}

// The paper's Example 1 at seed 8 reverses OP only 3 times in 3000 samples: enough to close the
// valve's hysteresis loop and size the band (fs 8.4 % of travel). It was not-enough-data when 4
// reversals were asked for.
TEST_CASE("assess_loop: a sticky valve whose OP reverses 3 times is judged and sized") {
  const LoopData d = run_scenario(scenario_by_name("paper-ex1"), 8, 3000);
  const LoopHealth h = loop_health(d);
  CHECK(std::round(h.op_reversals_per_hour * h.duration_s / 3600.0) == 3);
  CHECK(unusable_reason(d, h).empty());
#ifndef VALVEDIAG_SANITIZED  // the diagnosis's figures, not the path (tested above)
  const LoopAssessment a = assess_loop(d, "FIC101");
  INFO(a.reason);
  CHECK(a.verdict == "stiction");
  CHECK(a.stiction_percent == doctest::Approx(8.4).epsilon(0.1));
#endif
}

// A Preisach valve's size comes from its refined He figures, with the range of fs the data fit
// as well; a fitted He valve's range is its band's profile likelihood (band_interval), given the
// sample period and options it was fitted with.
TEST_CASE("friction_size: a Preisach valve's band and He's come with their intervals") {
  const LoopData d = run_scenario(scenario_by_name("paper-ex1"), 1, 3000);
  ModelFitOptions o;
  o.structure = {1, 1, 1, 1, 3, 6};
  o.preisach_L_min = 16;
  o.preisach_L_max = 16;
  const double Ts = d.sample_period();
  const ModelFit p = fit_model(d.op, d.pv, Ts, parse_model_spec("preisach:general"), o);
  REQUIRE(p.preisach.has_value());
  const FrictionSize a = friction_size(p, d.op, d.pv);
  CHECK(a.band_percent == doctest::Approx(8.4).epsilon(0.2));
  REQUIRE(std::isfinite(a.band_lo_percent));
  CHECK(a.band_lo_percent <= a.band_percent);
  CHECK(a.band_percent <= a.band_hi_percent);
  CHECK(a.band_hi_percent - a.band_lo_percent < 2.0);
  const ModelFit he = fit_model(d.op, d.pv, Ts, parse_model_spec("stiction"), o);
  const FrictionSize b = friction_size(he, d.op, d.pv);
  CHECK(b.band_percent == doctest::Approx(8.4).epsilon(0.1));
  CHECK(std::isnan(b.band_lo_percent));  // without the fit's setting: not known
  CHECK(std::isnan(b.band_hi_percent));
  const FrictionSize c = friction_size(he, d.op, d.pv, {}, 0, FitSetting{Ts, o});
  CHECK(c.band_percent == b.band_percent);
  REQUIRE(std::isfinite(c.band_lo_percent));
  CHECK(c.band_lo_percent <= c.band_percent);
  CHECK(c.band_percent <= c.band_hi_percent);
  CHECK(c.band_lo_percent <= 8.4);
  CHECK(8.4 <= c.band_hi_percent);
  CHECK(c.band_hi_percent - c.band_lo_percent < 2.0);
}

LoopData sticky_plant_record(const std::string& file) {
  return read_loop_csv(std::string(VALVEDIAG_DATA_DIR) + "/plant-loops/stiction/" + file,
                       test::plant_csv_options());
}

// A sticky plant valve that slips once in the held-out tail is judged on the whole record
// (whole_record_test.hpp); its band comes from that fit, with the fit's range too.
TEST_CASE("assess_loop: a band found on the whole record comes with its range") {
  const LoopData d = sticky_plant_record("stic_2411FIC20102_1113_0005_Stick1=0.69853.txt");
  const LoopAssessment a = assess_loop(d, "FIC20102");
  INFO(a.reason);
  REQUIRE(a.verdict == "stiction");
  CHECK(a.whole_record.confirmed);
  REQUIRE(std::isfinite(a.stiction_percent));
  REQUIRE(std::isfinite(a.stiction_lo_percent));
  CHECK(a.stiction_lo_percent <= a.stiction_percent);
  CHECK(a.stiction_percent <= a.stiction_hi_percent);
  // Measured: 1.50 % with 1.35-1.65 %.
  CHECK(a.stiction_hi_percent - a.stiction_lo_percent < 1.0);
  CHECK_FALSE(a.stiction_hi_open);
}

// A valve that slips about once in the record: its band fits up to the record's OP span, the
// search's top, so the data bound it from below only and the range says so (stiction_hi_open)
// instead of passing the span off as an upper bound.
TEST_CASE("assess_loop: a band the data do not bound from above is open above" *
          valvediag::test::release_only()) {
  const LoopData d = sticky_plant_record("stic_2411FIC20102_0823_1527_Stick1=0.84495.txt");
  const LoopAssessment a = assess_loop(d, "FIC20102");
  INFO(a.reason);
  REQUIRE(a.verdict == "stiction");
  REQUIRE(std::isfinite(a.stiction_lo_percent));
  CHECK(a.stiction_hi_open);
  // Measured: fs 1.94 % fitted, the data fit 1.84 % or more; OP spans 23.71-25.65 % (the
  // assessment's range is 0-100 %).
  const auto [lo, hi] = std::minmax_element(d.op.begin(), d.op.end());
  CHECK(a.stiction_hi_percent == doctest::Approx(*hi - *lo).epsilon(1e-6));
  CHECK(a.stiction_lo_percent < a.stiction_hi_percent);
  CHECK(a.stiction_lo_percent <= a.stiction_percent);
  const nlohmann::json j = assessment_json(a);
  CHECK(j["stiction_hi_open"] == true);
  CHECK(assessment_from_json(j).stiction_hi_open);
  CHECK(sweep_csv({a}).find(",1\n") != std::string::npos);
}

TEST_CASE("results survive their JSON round trip; rank puts the worst valve first") {
  LoopAssessment a;
  a.loop = "FIC101";
  a.source = "site.sqlite (run 3)";
  a.verdict = "stiction";
  a.stiction_percent = 2.5;
  a.slip_jump_percent = 1.0;
  a.stiction_lo_percent = 2.1;
  a.stiction_hi_percent = 3.25;
  a.stiction_hi_open = true;
  a.model = "stiction";
  a.fitness_percent = 91.5;
  a.validation_fitness_percent = 88.0;
  a.first_missing = "stiction";
  a.ladder = {{"linear", 60.0, 58.0}, {"stiction", 91.5, 88.0}};
  a.health.oscillating = true;
  a.health.period_s = 120;
  a.health.op_reversals_per_hour = 60;
  a.limit_cycle.oscillating = true;
  a.limit_cycle.period_s = 118;
  a.limit_cycle.phase_deg = -97;
  a.limit_cycle.model_share = 0.8;
  a.limit_cycle.stick_slip = true;
  a.limit_cycle.apparent_band = 2.4;
  a.limit_cycle.summary = "PV oscillates";
  a.whole_record.tested = true;
  a.whole_record.confirmed = true;
  a.whole_record.memory_model = "stiction:kano";
  a.whole_record.start_fitness = 32.5;
  a.whole_record.memory_fitness = 56.5;
  a.whole_record.relative_gain = 0.355;
  a.whole_record.load_fitness = 57.5;
  a.whole_record.load_bic_margin = 57.0;
  a.whole_record.rival = "characteristic";
  a.whole_record.rival_fitness = 36.0;
  a.whole_record.rival_bic_margin = 41.0;
  a.whole_record.summary = "on the whole record";
  a.severity = severity(a);
  const LoopAssessment b = assessment_from_json(nlohmann::json::parse(assessment_json(a).dump()));
  CHECK(b.loop == a.loop);
  CHECK(b.verdict == a.verdict);
  CHECK(b.stiction_percent == 2.5);
  CHECK(b.stiction_lo_percent == 2.1);
  CHECK(b.stiction_hi_percent == 3.25);
  CHECK(b.stiction_hi_open);
  CHECK(b.ladder.size() == 2);
  // Results written before the interval existed read as "not known".
  nlohmann::json older = assessment_json(a);
  older.erase("stiction_lo_percent");
  older.erase("stiction_hi_percent");
  older.erase("stiction_hi_open");
  const LoopAssessment o = assessment_from_json(older);
  CHECK(std::isnan(o.stiction_lo_percent));
  CHECK(std::isnan(o.stiction_hi_percent));
  CHECK_FALSE(o.stiction_hi_open);
  CHECK(o.stiction_percent == 2.5);
  // The CSV carries it in three columns after the ones scripts already read by position.
  const std::string one = sweep_csv({a});
  const std::string header = one.substr(0, one.find('\n'));
  CHECK(header.size() > 57);
  CHECK(header.substr(header.size() - 57) ==
        ",stiction_lo_percent,stiction_hi_percent,stiction_hi_open");
  CHECK(one.find(",2.1000,3.2500,1\n") != std::string::npos);
  CHECK(sweep_html({}, {a}, {}).find("(&ge; 2.10)") != std::string::npos);
  LoopAssessment bounded = a;  // a range the data bound on both sides
  bounded.stiction_hi_open = false;
  CHECK(sweep_html({}, {bounded}, {}).find("(2.10-3.25)") != std::string::npos);
  CHECK(sweep_csv({bounded}).find(",2.1000,3.2500,0\n") != std::string::npos);
  // A loop whose data names its tag: the page shows the tag, the file's name under it.
  LoopAssessment tagged = a;
  tagged.loop = "stic_2111FIC46005_0902";
  tagged.tag = "2111FIC46005";
  CHECK(assessment_from_json(assessment_json(tagged)).tag == "2111FIC46005");
  CHECK(o.tag.empty());  // results written before tags
  CHECK(sweep_html({}, {tagged}, {})
            .find("<td class=\"l\">2111FIC46005<br><small>stic_2111FIC46005_0902</small></td>") !=
        std::string::npos);
  CHECK(sweep_html({}, {a}, {}).find("<td class=\"l\">FIC101</td>") != std::string::npos);
  CHECK(b.ladder[1].validation_fitness_percent == 88.0);
  CHECK(b.health.oscillating);
  CHECK(b.health.period_s == 120);
  CHECK(b.limit_cycle.oscillating);
  CHECK(b.limit_cycle.period_s == 118);
  CHECK(b.limit_cycle.phase_deg == -97);
  CHECK(b.limit_cycle.model_share == 0.8);
  CHECK(b.limit_cycle.stick_slip);
  CHECK_FALSE(b.limit_cycle.integrating);
  CHECK(b.limit_cycle.apparent_band == 2.4);
  CHECK(b.limit_cycle.summary == "PV oscillates");
  CHECK(b.whole_record.tested);
  CHECK(b.whole_record.confirmed);
  CHECK(b.whole_record.memory_model == "stiction:kano");
  CHECK(b.whole_record.start_fitness == 32.5);
  CHECK(b.whole_record.memory_fitness == 56.5);
  CHECK(b.whole_record.relative_gain == 0.355);
  CHECK(b.whole_record.load_fitness == 57.5);
  CHECK(b.whole_record.load_bic_margin == 57.0);
  CHECK(b.whole_record.rival == "characteristic");
  CHECK(b.whole_record.rival_fitness == 36.0);
  CHECK(b.whole_record.rival_bic_margin == 41.0);
  CHECK(b.whole_record.preferred.empty());
  CHECK(b.whole_record.summary == "on the whole record");
  CHECK(b.severity == doctest::Approx(6 + 1 + 1.25));

  LoopAssessment n;  // NaN figures travel as null and come back NaN
  n.loop = "LIC201";
  n.verdict = "no-valve-problem";
  n.severity = severity(n);
  const LoopAssessment m = assessment_from_json(assessment_json(n));
  CHECK(std::isnan(m.stiction_percent));
  CHECK_FALSE(m.whole_record.tested);
  CHECK(std::isnan(m.whole_record.relative_gain));
  CHECK(std::isnan(m.whole_record.rival_bic_margin));
  CHECK(std::isnan(m.fitness_percent));
  CHECK_THROWS_WITH_AS(assessment_from_json(nlohmann::json{{"verdict", "x"}}),
                       "a loop's result has no 'loop' name", std::runtime_error);
  CHECK_THROWS_AS(sweep_loops_from_json(nlohmann::json{{"loops", 3}}), std::runtime_error);

  LoopAssessment e;
  e.loop = "AIC9";
  e.verdict = "error";
  e.severity = severity(e);
  LoopAssessment small = a;
  small.loop = "FIC100";
  small.stiction_percent = 0.5;
  small.severity = severity(small);
  std::vector<LoopAssessment> v{e, n, small, a};
  rank(v);
  CHECK(v[0].loop == "FIC101");
  CHECK(v[1].loop == "FIC100");
  CHECK(v[2].loop == "LIC201");
  CHECK(v[3].loop == "AIC9");
  const std::string table = format_sweep_table(v);
  CHECK(table.find("verdicts: stiction 2 no-valve-problem 1 error 1 (4 loops)") !=
        std::string::npos);
  const std::string csv = sweep_csv(v);
  CHECK(csv.find("1,FIC101,stiction,") != std::string::npos);
  const std::string html = sweep_html(SweepInfo{}, v, {"reports/FIC101.html"});
  CHECK(html.find("<a href=\"reports/FIC101.html\">FIC101</a>") != std::string::npos);
  // The page counts each verdict and says what it asks of the engineer; no row for a verdict
  // no loop has.
  CHECK(html.find("<td class=\"l\">stiction</td><td>2</td>") != std::string::npos);
  CHECK(html.find("<td class=\"l\">error</td><td>1</td>") != std::string::npos);
  CHECK(html.find("<td class=\"l\">deadband</td>") == std::string::npos);
  CHECK(html.find(verdict_advice("stiction")) != std::string::npos);
  CHECK(html.find("<div class=\"wide\">") != std::string::npos);
  // The severity chart: a bar per loop in rank order, as long as its severity on a 0-10 scale of
  // 520 px (FIC101: 6 + 1 oscillating + 2.5 / 2 = 8.25, 429 px), labelled with verdict and band;
  // the loop whose analysis failed has no bar.
  const auto chart_at = html.find("<figure id=\"severity-chart\">");
  REQUIRE(chart_at != std::string::npos);
  const std::string chart = html.substr(chart_at, html.find("</figure>", chart_at) - chart_at);
  CHECK(v[0].severity == doctest::Approx(8.25));
  std::size_t bars = 0;
  for (auto at = chart.find("<rect"); at != std::string::npos; at = chart.find("<rect", at + 1))
    ++bars;
  CHECK(bars == 3);
  CHECK(chart.find("width=\"429\" height=\"13\" fill=\"#d9534f\"/><text x=\"664\" y=\"34\" "
                   "fill=\"#333333\">stiction 2.50 %</text>") != std::string::npos);
  CHECK(chart.find(">FIC101</text>") < chart.find(">FIC100</text>"));
  CHECK(chart.find(">AIC9</text>") != std::string::npos);
  for (const char* v : {"stiction", "deadband", "other-nonlinearity", "no-valve-problem",
                        "not-enough-data", "error"})
    CHECK_MESSAGE(!verdict_advice(v).empty(), v);
  CHECK(verdict_advice("wobble").empty());
}

TEST_CASE(
    "split check: a clear sticky valve holds at every split; the summary marks one that does not" *
    valvediag::test::release_only()) {
  AssessOptions opt;
  const LoopData sticky = run_scenario(scenario_by_name("paper-ex1"), 1, kSamples);
  opt.check_splits = {0.25, 0.35};
  const LoopAssessment s = assess_loop(sticky, "FIC101", opt);
  INFO(s.reason);
  CHECK(s.verdict == "stiction");
  REQUIRE(s.split_verdicts.size() == opt.check_splits.size());
  for (std::size_t i = 0; i < opt.check_splits.size(); ++i) {
    CHECK(s.split_verdicts[i].validate == opt.check_splits[i]);
    CHECK(s.split_verdicts[i].verdict == "stiction");
  }
  const int shares = static_cast<int>(opt.check_splits.size()) + 1;
  CHECK(split_agreement(s) == std::pair{shares, shares});
  LoopAssessment unchecked = s;
  unchecked.split_verdicts.clear();
  CHECK(split_agreement(unchecked) == std::pair{1, 1});
  CHECK(severity(unchecked) == s.severity);  // agreement costs nothing

  LoopAssessment fragile = s;
  fragile.loop = "FIC102";
  fragile.split_verdicts = {s.split_verdicts[0], SplitVerdict{0.35, "no-valve-problem"}};
  CHECK(split_agreement(fragile) == std::pair{2, 3});
  CHECK(severity(fragile) == s.severity);
  const std::vector<LoopAssessment> v{s, fragile};
  const std::string table = format_sweep_table(v);
  CHECK(table.find(" splits\n") != std::string::npos);
  CHECK(table.find(" 2/3\n") != std::string::npos);
  CHECK(table.find("1 loop(s) whose verdict depends on where the record is split") !=
        std::string::npos);
  CHECK(sweep_csv(v).find(",2/3,,,\n") != std::string::npos);
  const LoopAssessment back =
      assessment_from_json(nlohmann::json::parse(assessment_json(fragile).dump()));
  REQUIRE(back.split_verdicts.size() == 2);
  CHECK(back.split_verdicts[1].validate == 0.35);
  CHECK(back.split_verdicts[1].verdict == "no-valve-problem");
  CHECK(format_sweep_table({unchecked}).find("splits") == std::string::npos);
}

TEST_CASE("the results store keeps each sweep and gives a loop's trend, oldest first") {
  const TempDb tmp(fs::temp_directory_path() /
                   ("valvediag-store-" + std::to_string(::getpid()) + ".sqlite"));
  const fs::path& db = tmp.path;
  {
    SweepStore store(db.string());
    for (int k = 0; k < 3; ++k) {
      SweepInfo info;
      info.started_utc = "2026-11-2" + std::to_string(k) + "T02:00:00Z";
      const auto id = store.begin_sweep(info);
      LoopAssessment a;
      a.loop = "FIC101";
      a.verdict = k < 2 ? "no-valve-problem" : "stiction";
      a.stiction_percent = k < 2 ? LoopAssessment::kNaN : 1.5 * k;
      store.add_result(id, a);
      store.end_sweep(id, info, "done");
    }
  }
  SweepStore again(db.string());  // reopened: everything was committed
  const auto t = again.trend("FIC101", 2);
  REQUIRE(t.size() == 2);
  CHECK(t[0].started_utc == "2026-11-21T02:00:00Z");
  CHECK(t[1].result.verdict == "stiction");
  CHECK(t[1].result.stiction_percent == 3.0);
  CHECK(again.trend("NOPE").empty());
  CHECK(again.assessed_loops() == std::vector<std::string>{"FIC101"});
  CHECK(!recorded_end_s(db.string(), "FIC101"));  // no recording tables: an error, not a guess
}

using test::exec_sql;

TEST_CASE("the results store migrates a database of the first release and refuses a newer one") {
  const TempDb tmp(fs::temp_directory_path() /
                   ("valvediag-migrate-" + std::to_string(::getpid()) + ".sqlite"));
  const fs::path& db = tmp.path;
  // The tables as the first release wrote them (no version row, no validate column), with a
  // recording table beside them as on a site database.
  exec_sql(db, R"sql(
    CREATE TABLE runs(id INTEGER PRIMARY KEY, started_utc TEXT NOT NULL);
    CREATE TABLE sweeps(id INTEGER PRIMARY KEY, started_utc TEXT NOT NULL, finished_utc TEXT,
      source TEXT, shard TEXT, window_s REAL, status TEXT NOT NULL DEFAULT 'running');
    CREATE TABLE sweep_results(sweep_id INTEGER NOT NULL REFERENCES sweeps(id),
      loop TEXT NOT NULL, verdict TEXT NOT NULL, severity REAL, stiction_percent REAL,
      slip_jump_percent REAL, model TEXT, fitness_percent REAL, validation_fitness_percent REAL,
      first_missing TEXT, oscillating INTEGER, period_s REAL, op_reversals_per_hour REAL,
      op_travel_percent_per_hour REAL, time_at_limits_percent REAL, error TEXT,
      result_json TEXT NOT NULL, PRIMARY KEY(sweep_id, loop));
    INSERT INTO sweeps(started_utc, status) VALUES('2026-10-01T02:00:00Z', 'done');)sql");
  LoopAssessment old;
  old.loop = "FIC101";
  old.verdict = "stiction";
  old.stiction_percent = 2.5;
  exec_sql(db,
           "INSERT INTO sweep_results(sweep_id, loop, verdict, result_json) VALUES(1, "
           "'FIC101', 'stiction', '" +
               assessment_json(old).dump() + "')");
  auto bytes = [&] {
    std::ifstream f(db, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(f), {});
  };
  const std::string before = bytes();
  try {  // trend's read-only store does not migrate: it says how the tables get there
    SweepStore reader(db.string(), SweepStore::Access::ReadOnly);
    FAIL("first-release tables were read without their migration");
  } catch (const std::runtime_error& e) {
    CHECK(std::string(e.what()).find("its sweep tables are version 1, from an older valvediag; the "
                                     "next sweep into it brings them to version 2") !=
          std::string::npos);
  }
  CHECK(bytes() == before);  // nothing written
  {
    SweepStore store(db.string());  // migrates
    SweepInfo info;
    info.started_utc = "2026-11-27T02:00:00Z";
    info.validation_fraction = 0.4;
    const auto id = store.begin_sweep(info);
    LoopAssessment a = old;
    a.stiction_percent = 3.0;
    store.add_result(id, a);
    store.end_sweep(id, info, "done");
    const auto t = store.trend("FIC101");
    REQUIRE(t.size() == 2);
    CHECK(t[0].result.stiction_percent == 2.5);  // the old result survived the migration
    CHECK(t[0].validation_fraction == 0.3);      // the only share the first release held out
    CHECK(t[1].validation_fraction == 0.4);
  }
  {
    SweepStore again(db.string());  // already current: opening changes nothing
    CHECK(again.trend("FIC101").size() == 2);
  }
  {
    SweepStore reader(db.string(), SweepStore::Access::ReadOnly);
    CHECK(reader.trend("FIC101").size() == 2);
    CHECK(reader.assessed_loops() == std::vector<std::string>{"FIC101"});
  }
  {
    const TempDb empty(fs::temp_directory_path() /
                       ("valvediag-empty-" + std::to_string(::getpid()) + ".sqlite"));
    exec_sql(empty.path, "CREATE TABLE runs(id INTEGER PRIMARY KEY)");  // a recording only
    SweepStore reader(empty.path.string(), SweepStore::Access::ReadOnly);
    CHECK(reader.assessed_loops().empty());
    CHECK(reader.trend("FIC101").empty());
  }
  exec_sql(db, "UPDATE schema_versions SET version = 99 WHERE component = 'sweeps'");
  for (const auto access : {SweepStore::Access::ReadWrite, SweepStore::Access::ReadOnly}) {
    try {
      SweepStore newer(db.string(), access);
      FAIL("a database from a newer release was opened");
    } catch (const std::runtime_error& e) {
      const std::string m = e.what();
      CHECK(m.find(db.string()) != std::string::npos);
      CHECK(m.find("version 99, written by a newer valvediag") != std::string::npos);
      CHECK(m.find("update valvediag") != std::string::npos);
    }
  }
}

TEST_CASE("isolated jobs: results, exceptions, crashes and time limits stay with their job") {
  using valvediag::cli::JobOutcome;
  using valvediag::cli::run_isolated;
  std::vector<JobOutcome> out(5);
  std::vector<int> order;
  const auto t0 = std::chrono::steady_clock::now();
  run_isolated(
      5, 2, 1.0,
      [](std::size_t i) -> std::string {
        if (i == 1) throw std::runtime_error("bad data in loop 1");
        if (i == 2) {
          std::signal(SIGABRT, SIG_DFL);  // doctest's crash handler is inherited: not ours
          std::abort();
        }
        if (i == 3) std::this_thread::sleep_for(std::chrono::seconds(30));
        return "result " + std::to_string(i) + std::string(200000, 'x');  // beyond a pipe buffer
      },
      [&](std::size_t i, const JobOutcome& o) {
        out[i] = o;
        order.push_back(static_cast<int>(i));
      });
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  CHECK(order.size() == 5);
  CHECK(out[0].status == JobOutcome::Status::Ok);
  CHECK(out[0].output.rfind("result 0", 0) == 0);
  CHECK(out[0].output.size() == 8 + 200000);
  CHECK(out[4].status == JobOutcome::Status::Ok);
  CHECK(out[1].status == JobOutcome::Status::Failed);
  CHECK(out[1].message == "bad data in loop 1");
  CHECK(out[2].status == JobOutcome::Status::Crashed);
  CHECK(out[2].message.find("signal 6") != std::string::npos);
  CHECK(out[3].status == JobOutcome::Status::TimedOut);
  CHECK(out[3].elapsed_s >= 1.0);
  CHECK(wall < 20.0);  // the sleeping job was killed, not waited for

  // A job killed at its time limit takes its own jobs with it: the sweep's loop job reads a
  // .mat file in a job of its own, which may be stuck in libmatio.
  const fs::path pid_file =
      fs::temp_directory_path() / ("valvediag_test_nested_" + std::to_string(::getpid()) + ".pid");
  fs::remove(pid_file);
  JobOutcome outer;
  run_isolated(
      1, 1, 1.0,
      [&](std::size_t) -> std::string {
        run_isolated(
            1, 1, 300.0,
            [&](std::size_t) -> std::string {
              std::ofstream(pid_file) << ::getpid() << "\n";
              std::this_thread::sleep_for(std::chrono::seconds(300));
              return "";
            },
            [](std::size_t, const JobOutcome&) {});
        return "";
      },
      [&](std::size_t, const JobOutcome& o) { outer = o; });
  CHECK(outer.status == JobOutcome::Status::TimedOut);
  long inner = 0;
  std::ifstream(pid_file) >> inner;
  REQUIRE(inner > 0);
  // Gone, or a zombie left for init to reap (a container's init may not reap it).
  auto alive = [](long pid) {
    if (::kill(static_cast<pid_t>(pid), 0) != 0) return false;
    std::ifstream stat("/proc/" + std::to_string(pid) + "/stat");
    std::string line;
    std::getline(stat, line);
    const auto close = line.rfind(')');
    return close != std::string::npos && close + 2 < line.size() && line[close + 2] != 'Z';
  };
  bool gone = false;
  for (int i = 0; i < 100 && !gone; ++i) {
    gone = !alive(inner);
    if (!gone) std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  CHECK(gone);
  if (!gone) ::kill(static_cast<pid_t>(inner), SIGKILL);
  fs::remove(pid_file);

  std::atomic<bool> stop{true};  // a stop before the start runs nothing
  int ran = 0;
  run_isolated(
      3, 1, 5.0, [](std::size_t) { return std::string(); },
      [&](std::size_t, const JobOutcome&) { ++ran; }, &stop);
  CHECK(ran == 0);
}
