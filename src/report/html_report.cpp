#include "valvediag/report/html_report.hpp"

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cmath>
#include <complex>
#include <cstdint>
#include <cstdio>
#include <ctime>
#include <future>
#include <numbers>
#include <sstream>
#include <stdexcept>

#include "number_format.hpp"
#include "valvediag/core/autocorrelation.hpp"
#include "valvediag/report/fit_report.hpp"
#include "valvediag/util/text_stats.hpp"
#include "valvediag/util/utc_time.hpp"

namespace valvediag {

// ---------------------------------------------------------------------------------------------
// Pieces

std::string html_escape(std::string_view text) {
  std::string o;
  o.reserve(text.size() + text.size() / 8);
  const auto* s = reinterpret_cast<const unsigned char*>(text.data());
  const std::size_t n = text.size();
  for (std::size_t i = 0; i < n;) {
    const unsigned char c = s[i];
    if (c < 0x80) {
      switch (c) {
        case '&':
          o += "&amp;";
          break;
        case '<':
          o += "&lt;";
          break;
        case '>':
          o += "&gt;";
          break;
        case '"':
          o += "&quot;";
          break;
        case '\'':
          o += "&#39;";
          break;
        default:
          if ((c < 0x20 && c != '\n' && c != '\t') || c == 0x7f)
            o += "\xEF\xBF\xBD";
          else
            o += static_cast<char>(c);
      }
      ++i;
      continue;
    }
    // A well-formed UTF-8 sequence passes through; anything else becomes U+FFFD.
    std::size_t len = 0;
    std::uint32_t cp = 0;
    if ((c & 0xE0) == 0xC0) {
      len = 2;
      cp = c & 0x1F;
    } else if ((c & 0xF0) == 0xE0) {
      len = 3;
      cp = c & 0x0F;
    } else if ((c & 0xF8) == 0xF0) {
      len = 4;
      cp = c & 0x07;
    }
    bool ok = len > 0 && i + len <= n;
    for (std::size_t k = 1; ok && k < len; ++k) {
      if ((s[i + k] & 0xC0) != 0x80) ok = false;
      cp = (cp << 6) | (s[i + k] & 0x3F);
    }
    if (ok) {
      static const std::uint32_t min_cp[] = {0, 0, 0x80, 0x800, 0x10000};
      ok = cp >= min_cp[len] && cp <= 0x10FFFF && !(cp >= 0xD800 && cp <= 0xDFFF);
    }
    if (ok) {
      o.append(text.substr(i, len));
      i += len;
    } else {
      o += "\xEF\xBF\xBD";
      ++i;
    }
  }
  return o;
}

std::vector<std::size_t> minmax_decimate(const std::vector<double>& y, std::size_t from,
                                         std::size_t to, std::size_t buckets) {
  to = std::min(to, y.size());
  std::vector<std::size_t> idx;
  if (from >= to) return idx;
  const std::size_t n = to - from;
  if (buckets == 0 || n <= 2 * buckets) {
    for (std::size_t k = from; k < to; ++k) idx.push_back(k);
    return idx;
  }
  idx.reserve(2 * buckets + 2);
  for (std::size_t b = 0; b < buckets; ++b) {
    const std::size_t lo = from + n * b / buckets, hi = from + n * (b + 1) / buckets;
    if (lo >= hi) continue;
    std::size_t kmin = lo, kmax = lo;
    for (std::size_t k = lo; k < hi; ++k) {
      if (!(y[k] >= y[kmin])) kmin = k;  // NaN never wins
      if (!(y[k] <= y[kmax])) kmax = k;
    }
    if (std::isnan(y[kmin])) kmin = kmax;
    idx.push_back(std::min(kmin, kmax));
    if (kmin != kmax) idx.push_back(std::max(kmin, kmax));
  }
  // The last sample always shows, so the trace reaches the end of the record.
  if (idx.back() != to - 1) idx.push_back(to - 1);
  return idx;
}

namespace {

// Coefficients of the full A(q^-1) = 1 + a1 q^-1 + ... (times 1 - q^-1 when integrating).
std::vector<double> full_a(const std::vector<double>& a, bool integrating) {
  std::vector<double> A{1.0};
  A.insert(A.end(), a.begin(), a.end());
  if (!integrating) return A;
  std::vector<double> B(A.size() + 1, 0.0);
  for (std::size_t i = 0; i < A.size(); ++i) {
    B[i] += A[i];
    B[i + 1] -= A[i];
  }
  return B;
}

}  // namespace

FrequencyResponse frequency_response(const std::vector<double>& a, const std::vector<double>& b,
                                     int nk, bool integrating, double Ts, std::size_t points) {
  FrequencyResponse r;
  if (!(Ts > 0) || points < 2) return r;
  const std::vector<double> A = full_a(a, integrating);
  const double fn = 0.5 / Ts, f0 = fn / 1000.0;
  double prev = 0.0, offset = 0.0;
  for (std::size_t k = 0; k < points; ++k) {
    const double f =
        f0 * std::pow(fn / f0, static_cast<double>(k) / static_cast<double>(points - 1));
    const double w = 2 * std::numbers::pi * f * Ts;  // rad per sample
    std::complex<double> num = 0.0, den = 0.0;
    for (std::size_t i = 0; i < b.size(); ++i)
      num += b[i] * std::polar(1.0, -w * static_cast<double>(nk + 1 + static_cast<int>(i)));
    for (std::size_t i = 0; i < A.size(); ++i)
      den += A[i] * std::polar(1.0, -w * static_cast<double>(i));
    const std::complex<double> g = num / den;
    double ph = std::arg(g) * 180.0 / std::numbers::pi;
    if (k > 0) {
      while (ph + offset - prev > 180.0) offset -= 360.0;
      while (ph + offset - prev < -180.0) offset += 360.0;
    }
    ph += offset;
    prev = ph;
    r.f_hz.push_back(f);
    r.magnitude_db.push_back(20.0 * std::log10(std::max(std::abs(g), 1e-300)));
    r.phase_deg.push_back(ph);
  }
  return r;
}

std::vector<double> step_response(const std::vector<double>& a, const std::vector<double>& b,
                                  int nk, bool integrating, std::size_t n) {
  const std::vector<double> A = full_a(a, integrating);
  std::vector<double> y(n, 0.0);
  for (std::size_t k = 0; k < n; ++k) {
    double v = 0.0;
    for (std::size_t i = 0; i < b.size(); ++i) {
      const long lag = nk + 1 + static_cast<long>(i);
      if (static_cast<long>(k) >= lag) v += b[i];  // x = 1 from sample 0 on
    }
    for (std::size_t i = 1; i < A.size() && i <= k; ++i) v -= A[i] * y[k - i];
    y[k] = v;
  }
  return y;
}

std::size_t settling_samples(const std::vector<double>& a, const std::vector<double>& b, int nk,
                             bool integrating, std::size_t cap) {
  cap = std::max<std::size_t>(cap, 20);
  // An integrating block never settles: the ramp shows once its derivative (B/A') has settled.
  const std::vector<double> y = step_response(a, b, nk, false, cap);
  const double yf = y.back();
  std::size_t last = 0;
  for (std::size_t k = 0; k < y.size(); ++k)
    if (std::abs(y[k] - yf) > 0.01 * std::abs(yf)) last = k;
  const double factor = integrating ? 2.0 : 1.3;
  const auto n = static_cast<std::size_t>(factor * static_cast<double>(last + 1)) + 2;
  return std::clamp<std::size_t>(n, 20, cap);
}

std::string inline_svg(const std::string& svg, const std::string& prefix) {
  std::string s = svg;
  const auto start = s.find("<svg");
  if (start != std::string::npos) s.erase(0, start);
  std::string o;
  o.reserve(s.size() + 4096);
  // id='x' / id="x" -> id='prefix-x'; href='#x' and url(#x) -> the same prefixed name.
  for (std::size_t i = 0; i < s.size();) {
    auto starts = [&](const char* w) {
      return s.compare(i, std::char_traits<char>::length(w), w) == 0;
    };
    if ((starts(" id='") || starts(" id=\""))) {
      o.append(s, i, 5);
      o += prefix + "-";
      i += 5;
    } else if (starts("href='#") || starts("href=\"#")) {
      o.append(s, i, 7);
      o += prefix + "-";
      i += 7;
    } else if (starts("url(#")) {
      o.append(s, i, 5);
      o += prefix + "-";
      i += 5;
    } else {
      o += s[i++];
    }
  }
  while (!o.empty() && (o.back() == '\n' || o.back() == ' ')) o.pop_back();
  return o;
}

ModelFit model_fit_of(const IdentificationResult& r, const std::vector<double>& u,
                      const std::vector<double>& y, double Ts) {
  (void)Ts;
  ModelFit f;
  f.spec = parse_model_spec("preisach:general");
  f.first_sample = r.first_sample;
  f.estimation_end = r.estimation_end;
  f.elapsed_s = r.elapsed_s;
  f.evaluations = static_cast<int>(r.configurations.size());
  if (r.status != IdentificationStatus::Ok) {
    f.status = ModelFitStatus::NoStableModel;
    f.stop_reason = "no stable Preisach-ARX configuration";
    return f;
  }
  const HammersteinModel& m = r.model;
  f.structure = {m.structure.na, m.structure.nb, m.structure.nk};
  f.a = m.a;
  f.b = m.b;
  f.c = m.c;
  f.fitness_percent = r.fitness_percent;
  f.validation_fitness_percent = r.validation_fitness_percent;
  const FitSeries s = fit_series(r, u, y);
  f.x_hat = s.x_hat;
  f.y_sim = s.y_sim;
  f.preisach = m;
  f.stop_reason = r.best.stop_reason;
  int nonzero = 0;
  for (double v : m.mu) nonzero += v > 0;
  f.effects.push_back({"preisach",
                       "general",
                       {{"L", static_cast<double>(m.grid.L), "levels"},
                        {"nonzero_weights", static_cast<double>(nonzero), ""},
                        {"umin", m.grid.umin, "OP"},
                        {"umax", m.grid.umax, "OP"}}});
  return f;
}

// ---------------------------------------------------------------------------------------------
// The page

namespace {

std::string num(double v, int prec = 2) {
  return report_format::fixed(v, prec);
}
std::string signed_num(double v, int prec = 2) {
  return report_format::signed_fixed(v, prec);
}

// Numbers in gnuplot data blocks: short, '?' (missing) for NaN and infinities.
std::string dnum(double v) {
  if (!std::isfinite(v)) return "?";
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.6g", v);
  return buf;
}

std::string e(std::string_view s) {
  return html_escape(s);
}

std::string pct(double v) {
  return std::isfinite(v) ? num(v) + " %" : "n/a";
}

double t_at(const std::vector<double>& t, std::size_t k) {
  if (t.empty()) return static_cast<double>(k);
  return k < t.size() ? t[k] : t.back();
}

// Model names from a history file in gnuplot tick labels: only a harmless alphabet.
std::string label_text(const std::string& s) {
  std::string o;
  for (char c : s)
    o += (std::isalnum(static_cast<unsigned char>(c)) || c == '+' || c == ':' || c == '-' ||
          c == '_' || c == '.')
             ? c
             : '?';
  return o.size() > 40 ? o.substr(0, 40) : o;
}

// The time axis of the trend plots: seconds from t = 0, or the data's own clock when it has
// date-time stamps (LoopData::clock_at_zero_s), labelled as the stamps read.
struct TimeAxis {
  double origin = 0.0;  // added to t
  bool clock = false;
  double first = 0.0, last = 0.0;  // the record's first and last t

  explicit TimeAxis(const LoopData& d) {
    clock = std::isfinite(d.clock_at_zero_s) && !d.t.empty();
    if (clock) origin = d.clock_at_zero_s;
    if (!d.t.empty()) first = d.t.front(), last = d.t.back();
  }
  double at(double t) const { return origin + t; }
  // An x coordinate: the clock needs more digits than the data's values.
  std::string x(double t) const {
    if (!std::isfinite(t)) return "?";
    char buf[40];
    std::snprintf(buf, sizeof buf, "%.13g", at(t));
    return buf;
  }
  // gnuplot's x tick format and label for the bottom plot of a figure.
  std::string labels() const {
    if (!clock) return "set format x '%g'\nset xlabel 't (s)'\n";
    const double span = last - first;
    const char* fmt = span <= 600 ? "%H:%M:%S" : span <= 86400 ? "%H:%M" : "%d %b %H:%M";
    return std::string("set xtics time\nset format x '") + fmt +
           "' timedate\nset xlabel 'time: " + stamp(first) + " .. " + stamp(last) +
           " (as stamped in the data)'\n";
  }
  // "2024-09-01 21:55:00": t on the data's clock, to the second.
  std::string stamp(double t) const {
    return utc_text(static_cast<std::time_t>(std::floor(at(t))), "%Y-%m-%d %H:%M:%S");
  }
};

const char* kFailFill = "#f4b6b6";  // the shading of the intervals where the model fails
const char* kValFill = "#e6edf7";   // the held-out (validation) part

class Plot {
 public:
  Plot(int w, int h) {
    s_ << "set terminal svg size " << w << "," << h
       << " fixed noenhanced font 'sans,11' background rgb 'white'\n"
          "set encoding utf8\nset datafile missing '?'\n"
          "set grid lc rgb '#dddddd' lw 1\nset border lc rgb '#444444'\n"
          "set key tmargin right horizontal nobox\n"
          "set tics nomirror\nset autoscale xfix\n";
  }
  // A data block of the rows given: each row's cells already formatted.
  std::string block(const std::vector<std::string>& rows) {
    const std::string name = "$D" + std::to_string(++blocks_);
    s_ << name << " << EOD\n";
    for (const auto& r : rows) s_ << r << "\n";
    s_ << "EOD\n";
    return name;
  }
  // A time series t, y over the decimated indices, t on the axis given.
  std::string series(const TimeAxis& axis, const std::vector<double>& t,
                     const std::vector<double>& y, std::size_t from, std::size_t to,
                     std::size_t buckets) {
    std::vector<std::string> rows;
    for (std::size_t k : minmax_decimate(y, from, to, buckets))
      rows.push_back(axis.x(t_at(t, k)) + " " + dnum(y[k]));
    return block(rows);
  }
  std::ostringstream& out() { return s_; }
  std::string script() const { return s_.str(); }

 private:
  std::ostringstream s_;
  int blocks_ = 0;
};

// Shades the failing intervals (and the held-out part) of the current plot.
void shade(Plot& p, const ReportContent& c) {
  const auto& t = c.data->t;
  const TimeAxis axis(*c.data);
  int obj = 0;
  if (c.fit->estimation_end > 0 && c.fit->estimation_end < t.size())
    p.out() << "set object " << ++obj << " rect from " << axis.x(t[c.fit->estimation_end])
            << ", graph 0 to " << axis.x(t.back()) << ", graph 1 behind fc rgb '" << kValFill
            << "' fs solid 1.0 noborder\n";
  if (c.where != nullptr)
    for (const auto& iv : c.where->intervals) {
      const double t0 = t_at(t, iv.begin), t1 = t_at(t, iv.end > 0 ? iv.end - 1 : 0);
      p.out() << "set object " << ++obj << " rect from " << axis.x(t0) << ", graph 0 to "
              << axis.x(std::max(t1, t0 + 1e-3)) << ", graph 1 behind fc rgb '" << kFailFill
              << "' fs solid 1.0 noborder\n";
    }
}

std::string shade_keys(const ReportContent& c) {
  std::string k;
  if (c.where != nullptr && !c.where->intervals.empty())
    k += ", keyentry with boxes fs solid 1.0 fc rgb '" + std::string(kFailFill) +
         "' title 'where the model fails'";
  if (c.fit->estimation_end > 0 && c.fit->estimation_end < c.data->size())
    k += ", keyentry with boxes fs solid 1.0 fc rgb '" + std::string(kValFill) +
         "' title 'held out (validation)'";
  return k;
}

struct PlotJob {
  std::string id, title, caption;
  std::string script;   // empty: not drawn
  std::string missing;  // why it is not drawn
};

PlotJob trends_plot(const LoopData& d, std::size_t buckets) {
  Plot p(960, d.has_pv() ? 460 : 260);
  const TimeAxis axis(d);
  const std::size_t n = d.size();
  const std::string pv = d.has_pv() ? p.series(axis, d.t, d.pv, 0, n, buckets) : "";
  const std::string sp = d.has_pv() && d.has_sp() ? p.series(axis, d.t, d.sp, 0, n, buckets) : "";
  const std::string op = p.series(axis, d.t, d.op, 0, n, buckets);
  const std::string mv = d.has_mv() ? p.series(axis, d.t, d.mv, 0, n, buckets) : "";
  auto& o = p.out();
  o << "set lmargin 10\nset rmargin 3\n";
  if (!pv.empty()) {
    o << "set multiplot layout 2,1\n"
      << (axis.clock ? "set xtics time\n" : "") << "set format x ''\nset ylabel 'PV'\n";
    o << "plot " << pv << " with lines lw 1.2 lc rgb '#1f5fa8' title 'PV'";
    if (!sp.empty()) o << ", " << sp << " with lines lw 1.2 dt 2 lc rgb '#2e8b57' title 'SP'";
    o << "\n";
  }
  o << axis.labels() << "set ylabel 'OP (%)'\n";
  o << "plot " << op << " with lines lw 1.2 lc rgb '#c05010' title 'OP'";
  if (!mv.empty())
    o << ", " << mv << " with lines lw 1.2 lc rgb '#7a3fa0' title 'valve position (MV)'";
  o << "\n";
  if (!pv.empty()) o << "unset multiplot\n";
  const char* caption =
      !d.has_pv()  ? "Controller output; PV was not recorded."
      : d.has_sp() ? "Process variable with its set point (top) and controller output (bottom)."
                   : "Process variable (top) and controller output (bottom); the data has no "
                     "set point.";
  return {"plot-trends", d.has_pv() ? "Trends: OP, PV and SP" : "Trend: OP", caption, p.script(),
          ""};
}

PlotJob fit_plot(const ReportContent& c, std::size_t buckets) {
  const LoopData& d = *c.data;
  const ModelFit& f = *c.fit;
  Plot p(960, 340);
  const std::size_t n = d.size();
  const TimeAxis axis(d);
  const std::string pv = p.series(axis, d.t, d.pv, 0, n, buckets);
  const std::string sim = p.series(axis, d.t, f.y_sim, f.first_sample, n, buckets);
  shade(p, c);
  p.out() << "set lmargin 10\nset rmargin 3\n"
          << axis.labels() << "set ylabel 'PV'\n"
          << "plot " << pv << " with lines lw 1.2 lc rgb '#555555' title 'measured PV', " << sim
          << " with lines lw 1.2 lc rgb '#d62728' title 'simulated PV (model)'" << shade_keys(c)
          << "\n";
  std::string cap = "The model is driven by OP alone (simulated output).";
  if (c.where != nullptr)
    cap += " Shaded red: the " + std::to_string(c.where->intervals.size()) +
           " interval(s) where the residual stands out beyond its white-noise level.";
  if (f.estimation_end < n) cap += " Shaded blue: the held-out part (validation).";
  return {"plot-fit", "Measured and simulated PV", cap, p.script(), ""};
}

PlotJob residual_plot(const ReportContent& c, std::size_t buckets) {
  const LoopData& d = *c.data;
  const ModelFit& f = *c.fit;
  Plot p(960, 300);
  std::vector<double> r(d.size(), std::nan(""));
  for (std::size_t k = f.first_sample; k < d.size(); ++k) r[k] = d.pv[k] - f.y_sim[k];
  const TimeAxis axis(d);
  const std::string res = p.series(axis, d.t, r, f.first_sample, d.size(), buckets);
  shade(p, c);
  auto& o = p.out();
  o << "set lmargin 10\nset rmargin 3\n" << axis.labels() << "set ylabel 'PV - simulated PV'\n";
  o << "plot " << res
    << " with lines lw 1 lc rgb '#333333' title 'residual', 0 with lines lc rgb "
       "'#999999' notitle";
  if (c.where != nullptr && c.where->noise_level > 0) {
    const double lvl = 2.5 * c.where->noise_level;
    o << ", " << dnum(lvl)
      << " with lines dt 2 lc rgb '#d62728' title '+/- 2.5 x white-noise level', " << dnum(-lvl)
      << " with lines dt 2 lc rgb '#d62728' notitle";
  }
  o << shade_keys(c) << "\n";
  std::string cap = "Residual of the simulated output.";
  if (c.where != nullptr)
    cap += " RMS " + num(c.where->rms, 3) + ", white-noise level " + num(c.where->noise_level, 3) +
           ".";
  return {"plot-residual", "Residual: measured minus simulated PV", cap, p.script(), ""};
}

// MATLAB's `resid` on the estimation part: the residual's autocorrelation and its
// cross-correlation with OP, over lags as long as the linear block takes to settle (25 to 250).
PlotJob resid_plot(const ReportContent& c) {
  const LoopData& d = *c.data;
  const ModelFit& f = *c.fit;
  const double Ts = d.sample_period();
  const std::size_t from = f.first_sample, to = std::min(f.estimation_end, d.size());
  PlotJob job{"plot-resid", "Residual tests: autocorrelation, and correlation with OP", "", "", ""};
  if (to <= from + 8) {
    job.missing = "Too few estimation samples for the residual tests.";
    return job;
  }
  std::vector<double> e, u;
  for (std::size_t k = from; k < to; ++k) {
    e.push_back(d.pv[k] - f.y_sim[k]);
    u.push_back(d.op[k]);
  }
  const std::size_t settle = settling_samples(f.a, f.b, f.structure.nk, f.integrating,
                                              std::max<std::size_t>(e.size(), 25));
  const std::size_t lags = std::min(std::clamp<std::size_t>(settle, 25, 250), (e.size() - 2) / 2);
  const ResidualCorrelation r = residual_correlation(e, u, lags);
  if (r.autocorrelation.empty()) {
    job.missing = "The residual is constant: nothing to test.";
    return job;
  }
  Plot p(960, 300);
  std::vector<std::string> ra, rc;
  for (std::size_t k = 0; k < r.autocorrelation.size(); ++k)
    ra.push_back(dnum(static_cast<double>(k) * Ts) + " " + dnum(r.autocorrelation[k]));
  const auto M = static_cast<double>(r.max_lag);
  for (std::size_t i = 0; i < r.cross_correlation.size(); ++i)
    rc.push_back(dnum((static_cast<double>(i) - M) * Ts) + " " + dnum(r.cross_correlation[i]));
  const std::string ba = p.block(ra), bc = rc.empty() ? "" : p.block(rc);
  auto& o = p.out();
  const auto band = [&o](double b) {
    o << ", " << dnum(b) << " with lines dt 2 lc rgb '#d62728' title '99 % band', " << dnum(-b)
      << " with lines dt 2 lc rgb '#d62728' notitle";
  };
  o << "set multiplot layout 1,2\nset lmargin 9\nset rmargin 2\nset yrange [-1:1]\n"
       "set xlabel 'lag (s)'\nset ylabel 'autocorrelation'\n";
  o << "plot " << ba << " with impulses lw 1.5 lc rgb '#1f5fa8' title 'residual'";
  band(r.autocorrelation_band);
  o << "\nset ylabel 'correlation'\nset xlabel 'lag (s): OP before the residual > 0'\n";
  if (bc.empty()) {
    o << "plot 0 with lines lc rgb '#999999' title 'OP is constant'\n";
  } else {
    o << "plot " << bc << " with impulses lw 1.5 lc rgb '#1f5fa8' title 'residual with OP'";
    band(r.cross_correlation_band);
    o << "\n";
  }
  o << "unset multiplot\n";
  int auto_out = 0, cross_out = 0;
  for (std::size_t k = 1; k < r.autocorrelation.size(); ++k)
    auto_out += std::abs(r.autocorrelation[k]) > r.autocorrelation_band;
  for (std::size_t i = r.max_lag + 1; i < r.cross_correlation.size(); ++i)
    cross_out += std::abs(r.cross_correlation[i]) > r.cross_correlation_band;
  job.caption =
      "As MATLAB's resid, on the estimation part (" + std::to_string(r.samples) +
      " samples), lags up to " + num(M * Ts, M * Ts >= 10 ? 0 : 1) +
      " s. A model that leaves only noise keeps both inside the 99 % bands. Left: " +
      std::to_string(auto_out) + " of " + std::to_string(r.max_lag) +
      " lags outside: error that lasts (a missing effect, a slow load, too few poles). Right: " +
      (rc.empty() ? std::string("no test, OP does not move.")
                  : std::to_string(cross_out) + " of " + std::to_string(r.max_lag) +
                        " positive lags outside: OP that still moves PV in a way the model does "
                        "not carry (a valve effect, the delay, the order). In closed loop the "
                        "negative lags show the controller answering the residual: expected.");
  job.script = p.script();
  return job;
}

// The samples a path x -> y keeps: consecutive points closer than 0.2 % of both ranges are
// dropped; a very long noisy record keeps every m-th of the rest.
std::vector<std::size_t> path_points(const std::vector<double>& x, const std::vector<double>& y) {
  const auto [xmin, xmax] = std::minmax_element(x.begin(), x.end());
  const auto [ymin, ymax] = std::minmax_element(y.begin(), y.end());
  const double dx = 0.002 * (*xmax - *xmin), dy = 0.002 * (*ymax - *ymin);
  std::vector<std::size_t> keep;
  double lx = std::nan(""), ly = std::nan("");
  for (std::size_t k = 0; k < x.size(); ++k)
    if (!(std::abs(x[k] - lx) <= dx && std::abs(y[k] - ly) <= dy) || k + 1 == x.size()) {
      keep.push_back(k);
      lx = x[k];
      ly = y[k];
    }
  if (keep.size() > 6000) {
    std::vector<std::size_t> kept;
    const std::size_t m = keep.size() / 3000 + 1;
    for (std::size_t i = 0; i < keep.size(); i += m) kept.push_back(keep[i]);
    keep.swap(kept);
  }
  return keep;
}

// A path x -> y over path_points as one data block.
std::string path_block(Plot& p, const std::vector<double>& x, const std::vector<double>& y) {
  std::vector<std::string> rows;
  for (std::size_t k : path_points(x, y)) rows.push_back(dnum(x[k]) + " " + dnum(y[k]));
  return p.block(rows);
}

// A path x -> y as two blocks: the segments where x rises and those where it falls, so a
// hysteresis loop shows which way it is travelled. The direction turns only once x has come back
// 1 % of its range from its last extreme: noise on x does not flicker the colours.
std::pair<std::string, std::string> directional_path(Plot& p, const std::vector<double>& x,
                                                     const std::vector<double>& y) {
  const std::vector<std::size_t> k = path_points(x, y);
  const auto [xmin, xmax] = std::minmax_element(x.begin(), x.end());
  const double turn = 0.01 * (*xmax - *xmin);
  std::vector<std::string> rows[2];
  std::size_t end[2] = {k.size(), k.size()};  // where each block's last segment ended
  int dir = 0;                                // 0 rising, 1 falling
  double extreme = k.empty() ? 0.0 : x[k[0]];
  for (std::size_t i = 0; i + 1 < k.size(); ++i) {
    const double next = x[k[i + 1]];
    if (dir == 0 ? next > extreme : next < extreme) extreme = next;
    if (dir == 0 ? next < extreme - turn : next > extreme + turn) {
      dir = 1 - dir;
      extreme = next;
    }
    auto& r = rows[dir];
    if (end[dir] != i) {
      if (!r.empty()) r.emplace_back("");  // a break in the line
      r.push_back(dnum(x[k[i]]) + " " + dnum(y[k[i]]));
    }
    r.push_back(dnum(next) + " " + dnum(y[k[i + 1]]));
    end[dir] = i + 1;
  }
  return {p.block(rows[0]), p.block(rows[1])};
}

constexpr const char* kRising = "#1f5fa8";
constexpr const char* kFalling = "#e07b00";

PlotJob signature_plot(const ReportContent& c) {
  const LoopData& d = *c.data;
  const ModelFit& f = *c.fit;
  Plot p(470, 420);
  const auto [up, down] = directional_path(p, d.op, f.x_hat);
  const bool pre = f.preisach.has_value();
  const bool mv = d.has_mv();
  const std::string m = mv ? path_block(p, d.op, d.mv) : "";
  p.out() << "set xlabel 'OP (%)'\nset ylabel '"
          << (pre ? "estimated valve position (model units)" : "valve position (%)") << "'\n";
  // The Preisach output is in model units: the measured position then gets its own axis.
  if (mv && pre) p.out() << "set y2label 'measured valve position (%)'\nset y2tics\n";
  p.out() << "plot ";
  if (mv)
    p.out() << m << " with lines lw 1 lc rgb '#999999' title 'measured position (MV)'"
            << (pre ? " axes x1y2" : "") << ", ";
  // In % of OP a valve that follows OP lies on y = x; the Preisach position has no such line.
  if (!pre) p.out() << "x with lines dt 3 lc rgb '#666666' title 'y = x', ";
  p.out() << up << " with lines lw 1 lc rgb '" << kRising << "' title 'OP rising', " << down
          << " with lines lw 1 lc rgb '" << kFalling << "' title 'OP falling'\n";
  std::string cap =
      pre ? "The identified Preisach valve driven by the recorded OP (x = gamma(u)' mu, "
            "||b|| = 1: the scale is carried by the linear block). Flat stretches are "
            "where the valve sticks."
          : "The identified valve effects driven by the recorded OP. Flat stretches are "
            "where the valve sticks; a valve that follows OP lies on the dotted y = x.";
  cap += " Blue while OP rises, orange while it falls: a sticky valve lags OP both ways.";
  if (mv)
    cap +=
        " Grey: the recorded valve position, from which the valve-travel test reads the "
        "friction directly.";
  return {"plot-signature", "Valve signature: OP vs valve position", cap, p.script(), ""};
}

// PV against OP, no model needed: the loop's own signature.
PlotJob pv_op_plot(const LoopData& d) {
  Plot p(470, 420);
  const auto [up, down] = directional_path(p, d.op, d.pv);
  p.out() << "set xlabel 'OP (%)'\nset ylabel 'PV'\n";
  p.out() << "plot " << up << " with lines lw 1 lc rgb '" << kRising << "' title 'OP rising', "
          << down << " with lines lw 1 lc rgb '" << kFalling << "' title 'OP falling'\n";
  return {"plot-pv-op", "PV against OP",
          "The measurements alone, blue while OP rises and orange while it falls. A sticky valve "
          "draws cycles: OP moves on while PV holds, then PV jumps; a clean valve in a slow loop "
          "draws a band around one line.",
          p.script(), ""};
}

PlotJob preisach_plot(const ReportContent& c) {
  const ModelFit& f = *c.fit;
  PlotJob job{"plot-preisach", "Preisach weights on the Preisach triangle", "", "", ""};
  if (!f.preisach) {
    job.missing = "The model (" + to_string(f.spec) +
                  ") has no Preisach valve, so there are no weights to draw. Run the report with "
                  "--model preisach to see the valve as a Preisach triangle.";
    return job;
  }
  const HammersteinModel& m = *f.preisach;
  const PreisachGrid& g = m.grid;
  Plot p(470, 420);
  std::vector<std::string> all, nz;
  double wmax = 0.0;
  int nonzero = 0;
  for (int i = 1; i <= g.L; ++i)
    for (int j = i; j <= g.L; ++j) {
      const auto k = static_cast<std::size_t>(g.relay_index(i, j));
      const double w = k < m.mu.size() ? m.mu[k] : 0.0;
      const double beta = g.threshold(i) + g.delta() / 2, alpha = g.threshold(j) + g.delta() / 2;
      all.push_back(dnum(beta) + " " + dnum(alpha));
      if (w > 0) {
        nz.push_back(dnum(beta) + " " + dnum(alpha) + " " + dnum(w));
        wmax = std::max(wmax, w);
        ++nonzero;
      }
    }
  const std::string ball = p.block(all);
  const std::string bnz = nz.empty() ? "" : p.block(nz);
  const double h = g.delta() / 2, lo = g.umin, hi = g.umax;
  auto& o = p.out();
  o << "set size ratio -1\nset xrange [" << dnum(lo) << ":" << dnum(hi) << "]\nset yrange ["
    << dnum(lo) << ":" << dnum(hi) << "]\n"
    << "set xlabel 'beta: OP where the relay switches down (%)'\n"
       "set ylabel 'alpha: OP where it switches up (%)'\n"
       "set palette defined (0 '#fff5d6', 0.5 '#f08c28', 1 '#8c1a0a')\n"
       "set cbrange [0:"
    << dnum(wmax > 0 ? wmax : 1.0) << "]\n";
  o << "plot " << ball << " using 1:2:(" << dnum(h) << "):(" << dnum(h)
    << ") with boxxyerror fs empty lc rgb '#bbbbbb' title 'relays (" << g.relay_count() << ")'";
  if (!bnz.empty())
    o << ", " << bnz << " using 1:2:(" << dnum(h) << "):(" << dnum(h)
      << "):3 with boxxyerror fs solid 1.0 border lc rgb '#444444' fc palette title "
         "'nonzero weights ("
      << nonzero << ")'";
  o << ", x with lines dt 2 lc rgb '#888888' notitle\n";
  job.caption = "Each square is one relay (i, j) of the discretized Preisach model (L = " +
                std::to_string(g.L) + ", OP " + num(g.umin, 1) + " .. " + num(g.umax, 1) +
                " %), placed at the OP where it switches down (beta) and up (alpha); colour: its "
                "identified weight. Weight on the diagonal is a static gain; weight away from it "
                "is hysteresis: the further from the diagonal, the wider the stick band.";
  job.script = p.script();
  return job;
}

PlotJob bode_plot(const ReportContent& c) {
  const ModelFit& f = *c.fit;
  const double Ts = c.data->sample_period();
  const FrequencyResponse r = frequency_response(f.a, f.b, f.structure.nk, f.integrating, Ts, 300);
  Plot p(960, 460);
  std::vector<std::string> rows;
  for (std::size_t k = 0; k < r.f_hz.size(); ++k)
    rows.push_back(dnum(r.f_hz[k]) + " " + dnum(r.magnitude_db[k]) + " " + dnum(r.phase_deg[k]));
  const std::string b = p.block(rows);
  auto& o = p.out();
  o << "set multiplot layout 2,1\nset lmargin 10\nset rmargin 3\nset logscale x\nset format x ''\n"
       "set key off\nset ylabel '|G| (dB)'\nset arrow 1 from "
    << dnum(0.5 / Ts) << ", graph 0 to " << dnum(0.5 / Ts)
    << ", graph 1 nohead dt 3 lc rgb '#888888'\n"
    << "plot " << b << " using 1:2 with lines lw 1.5 lc rgb '#1f5fa8'\n"
    << "set format x '%g'\nset xlabel 'frequency (Hz); Nyquist " << dnum(0.5 / Ts)
    << " Hz at Ts = " << dnum(Ts) << " s'\nset ylabel 'phase (deg)'\n"
    << "plot " << b << " using 1:3 with lines lw 1.5 lc rgb '#d62728'\nunset multiplot\n";
  return {"plot-bode", "Bode diagram of the linear block",
          "Magnitude and phase of B(q)/A(q) at the identified Ts = " + num(Ts, 3) +
              " s, from Nyquist/1000 up to Nyquist (" + num(0.5 / Ts, 3) + " Hz). " +
              (f.preisach ? "The Preisach valve carries the scale (||b|| = 1), so the magnitude "
                            "is relative."
                          : "Input: valve position (%), output: PV."),
          p.script(), ""};
}

PlotJob step_plot(const ReportContent& c) {
  const ModelFit& f = *c.fit;
  const double Ts = c.data->sample_period();
  const std::size_t most = std::clamp<std::size_t>(c.data->size(), 200, 5000);
  const std::size_t n = settling_samples(f.a, f.b, f.structure.nk, f.integrating, most);
  const std::vector<double> y = step_response(f.a, f.b, f.structure.nk, f.integrating, n);
  Plot p(960, 300);
  // Zero-order hold steps while they show; a long response as a line through every m-th sample.
  const std::size_t m = y.size() / 400 + 1;
  std::vector<std::string> rows;
  for (std::size_t k = 0; k < y.size(); k += m)
    rows.push_back(dnum(static_cast<double>(k) * Ts) + " " + dnum(y[k]));
  if ((y.size() - 1) % m != 0)
    rows.push_back(dnum(static_cast<double>(y.size() - 1) * Ts) + " " + dnum(y.back()));
  const std::string b = p.block(rows);
  p.out() << "set lmargin 10\nset rmargin 3\nset key off\nset autoscale xfix\n"
             "set xlabel 't (s) after a unit step of the valve position'\nset ylabel 'PV change'\n"
          << "plot " << b << (m == 1 ? " with steps" : " with lines")
          << " lw 1.5 lc rgb '#1f5fa8'\n";
  std::string cap = "Response of B(q)/A(q) to a unit step at t = 0: delay " +
                    num((f.structure.nk + 1) * Ts, 2) +
                    " s (nk + 1 = " + std::to_string(f.structure.nk + 1) + " samples)";
  if (f.integrating)
    cap += "; the process integrates, so the response is a ramp.";
  else if (!y.empty())
    cap += ", static gain " + num(y.back(), 4) + ".";
  return {"plot-step", "Step response of the linear block", cap, p.script(), ""};
}

PlotJob ladder_plot(const ReportContent& c) {
  PlotJob job{"plot-ladder", "Model ladder: fitness per step", "", "", ""};
  if (c.ladder.empty()) {
    job.missing =
        "No model history for this data yet: each fit, diagnosis and report adds to "
        "it (see valvediag ladder).";
    return job;
  }
  Plot p(960, 340);
  std::vector<std::string> rows;
  for (std::size_t i = 0; i < c.ladder.size(); ++i) {
    const auto& h = c.ladder[i];
    rows.push_back(std::to_string(i + 1) + " \"" + std::to_string(i + 1) + ". " +
                   label_text(h.model) + "\" " + dnum(h.fitness_percent) + " " +
                   dnum(h.validation_fitness_percent));
  }
  const std::string b = p.block(rows);
  p.out() << "set lmargin 10\nset rmargin 3\nset bmargin 6\n"
             "set ylabel 'fitness (%)'\nset yrange [-100<*:100]\nset xrange [0.5:"
          << c.ladder.size() << ".5]\nset xtics rotate by -25 nomirror\n"
          << "plot " << b
          << " using 1:3:xtic(2) with linespoints pt 7 ps 0.8 lw 1.5 lc rgb '#1f5fa8' title "
             "'estimation', "
          << b
          << " using 1:4 with linespoints pt 5 ps 0.8 lw 1.5 lc rgb '#d62728' title "
             "'validation'\n";
  job.caption =
      "Every fit of this data, in order (its model history). "
      "Fitness below -100 % is cut off.";
  job.script = p.script();
  return job;
}

// ---- HTML pieces ----

const char* kStyle = R"(
body { font-family: sans-serif; margin: 1.5em auto; max-width: 1000px; color: #222; line-height: 1.4; }
h1 { font-size: 1.5em; margin-bottom: 0.2em; }
h2 { font-size: 1.2em; border-bottom: 1px solid #ccc; margin-top: 1.6em; }
table { border-collapse: collapse; margin: 0.5em 0; font-size: 0.92em; }
th, td { border: 1px solid #ccc; padding: 0.2em 0.6em; text-align: left; vertical-align: top; }
th { background: #f2f2f2; }
td.num { text-align: right; font-variant-numeric: tabular-nums; }
table.header th { width: 12em; }
figure { margin: 1em 0; }
figure svg { max-width: 100%; height: auto; display: block; }
figcaption { font-weight: bold; margin-bottom: 0.3em; }
p.caption { font-size: 0.9em; color: #444; margin: 0.3em 0 0; }
.pair { display: flex; flex-wrap: wrap; gap: 1em; }
.pair figure { flex: 1 1 460px; }
.note { background: #fff8e0; border: 1px solid #e8d48a; padding: 0.4em 0.7em; }
.verdict { font-weight: bold; }
code { background: #f4f4f4; padding: 0 0.2em; }
footer { margin-top: 2em; font-size: 0.85em; color: #666; }
)";

std::string poly_text(const std::vector<double>& c, int first_power, bool leading_one) {
  std::ostringstream o;
  if (leading_one) o << "1";
  for (std::size_t i = 0; i < c.size(); ++i) {
    const double v = c[i];
    const int pw = first_power + static_cast<int>(i);
    const bool first = !leading_one && i == 0;
    o << (first ? (v < 0 ? "-" : "") : (v < 0 ? " - " : " + ")) << num(std::abs(v), 4) << " q^-"
      << pw;
  }
  return o.str();
}

void row(std::ostringstream& o, const std::string& head, const std::string& html_value) {
  o << "<tr><th>" << e(head) << "</th><td>" << html_value << "</td></tr>\n";
}

// The record's rows of a page's summary: name, source, samples (`span_note` after the time
// span), sample period.
void record_rows(std::ostringstream& o, const LoopData& d, const std::string& name,
                 const std::string& span_note) {
  row(o, "data", e(name));
  if (!d.source.empty() && d.source != name) row(o, "source", e(d.source));
  row(o, "samples",
      std::to_string(d.size()) + " (t " + e(num(d.t.front(), 1)) + " .. " + e(num(d.t.back(), 1)) +
          " s" + e(span_note) + ")");
  if (const TimeAxis axis(d); axis.clock)
    row(o, "time stamps",
        e(axis.stamp(axis.first)) + " .. " + e(axis.stamp(axis.last)) +
            " (as stamped in the data)");
  row(o, "sample period Ts", e(num(d.sample_period(), 3)) + " s");
}

void header_section(std::ostringstream& o, const ReportContent& c) {
  const LoopData& d = *c.data;
  const ModelFit& f = *c.fit;
  o << "<section id=\"summary\">\n<table class=\"header\">\n";
  record_rows(o, d, c.data_name, "");
  row(o, "generated", e(c.generated));
  std::string model = "<code>" + e(to_string(f.spec)) + "</code> (na " +
                      std::to_string(f.structure.na) + ", nb " + std::to_string(f.structure.nb) +
                      ", nk " + std::to_string(f.structure.nk) +
                      (f.integrating ? ", integrating" : "") + ")";
  if (!f.a.empty() || !f.b.empty()) {
    model +=
        "<br>A(q) = " + e(poly_text(f.a, 1, true)) + (f.integrating ? " (times 1 - q^-1)" : "");
    model += "<br>B(q) = " + e(poly_text(f.b, f.structure.nk + 1, false));
  }
  for (const auto& fe : f.effects)
    if (!fe.parameters.empty())
      model += "<br>" + e(fe.name + (fe.variant.empty() ? "" : " (" + fe.variant + ")") + ": " +
                          report_format::parameters(fe.parameters));
  row(o, "model", model);
  row(o, "fitness",
      e(num(f.fitness_percent)) + " % on estimation data, " +
          (std::isfinite(f.validation_fitness_percent)
               ? e(num(f.validation_fitness_percent)) + " % on validation data (the last " +
                     e(num(100.0 * static_cast<double>(d.size() - f.estimation_end) /
                               static_cast<double>(d.size()),
                           0)) +
                     " %, held out)"
               : std::string("no validation split")) +
          " (simulated output)");
  row(o, "verdict",
      c.verdict.empty()
          ? std::string(c.diagnosis != nullptr ? "not judged" : "not diagnosed")
          : "<span class=\"verdict\">" + e(c.verdict) + "</span>" +
                (c.unusable.empty() ? std::string()
                                    : ": " + e(c.unusable) +
                                          " (the fits are shown, not judged; a sweep does "
                                          "not fit such a record)") +
                (c.verdict_basis.empty() ? std::string()
                                         : "<br><small>" + e(c.verdict_basis) + "</small>"));
  if (c.diagnosis != nullptr && c.diagnosis->limit_cycle.oscillating)
    row(o, "limit cycle", e(c.diagnosis->limit_cycle.summary));
  if (c.diagnosis != nullptr && c.diagnosis->whole_record.tested)
    row(o, "whole record", e(c.diagnosis->whole_record.summary));
  if (c.diagnosis != nullptr && !c.diagnosis->valve_travel.summary.empty())
    row(o, "valve travel", e(c.diagnosis->valve_travel.summary));
  if (c.where != nullptr)
    row(o, "residual",
        "RMS " + e(num(c.where->rms, 3)) + ", white-noise level " +
            e(num(c.where->noise_level, 3)) + ", " + std::to_string(c.where->reversals) +
            " OP reversals");
  o << "</table>\n";
  for (const auto& n : c.notes) o << "<p class=\"note\">" << e(n) << "</p>\n";
  o << "</section>\n";
}

void where_section(std::ostringstream& o, const ReportContent& c) {
  o << "<section id=\"where\">\n<h2>Where the model fails</h2>\n";
  if (c.where == nullptr) {
    o << "<p class=\"note\">No residual analysis.</p>\n</section>\n";
    return;
  }
  const ResidualAnalysis& a = *c.where;
  const auto& t = c.data->t;
  o << "<p>Residual RMS " << e(num(a.rms, 3)) << " against a white-noise level of "
    << e(num(a.noise_level, 3)) << " on the estimation data.</p>\n";
  o << "<h3>Intervals</h3>\n";
  if (a.intervals.empty()) {
    o << "<p>No interval where the residual stands out beyond its white-noise level.</p>\n";
  } else {
    const TimeAxis axis(*c.data);
    o << "<table id=\"where-intervals\"><tr>"
      << (axis.clock ? "<th>from (time stamp)</th><th>to (time stamp)</th>" : "")
      << "<th>t from (s)</th><th>t to (s)</th><th>samples</th>"
         "<th>residual RMS</th><th>share of the squared error</th></tr>\n";
    for (const auto& iv : a.intervals)
      o << "<tr>"
        << (axis.clock ? "<td>" + e(axis.stamp(t_at(t, iv.begin))) + "</td><td>" +
                             e(axis.stamp(t_at(t, iv.end > 0 ? iv.end - 1 : 0))) + "</td>"
                       : std::string())
        << "<td class=\"num\">" << e(num(t_at(t, iv.begin), 1)) << "</td><td class=\"num\">"
        << e(num(t_at(t, iv.end > 0 ? iv.end - 1 : 0), 1)) << "</td><td class=\"num\">"
        << iv.end - iv.begin << "</td><td class=\"num\">" << e(num(iv.rms, 3))
        << "</td><td class=\"num\">" << e(num(100 * iv.share, 0)) << " %</td></tr>\n";
    o << "</table>\n";
  }
  o << "<h3>Operating regions</h3>\n";
  std::vector<const ResidualRegion*> regs;
  for (const auto& g : a.regions)
    if (g.excess >= 1.5 && g.share >= 0.1) regs.push_back(&g);
  std::sort(regs.begin(), regs.end(), [](auto* x, auto* y) { return x->excess > y->excess; });
  if (regs.empty()) {
    o << "<p>No operating region carries much more than its share of the error.</p>\n";
  } else {
    o << "<table id=\"where-regions\"><tr><th>kind</th><th>region</th><th>share of the error</th>"
         "<th>share of the samples</th><th>mean residual</th></tr>\n";
    for (const auto* g : regs)
      o << "<tr><td>" << e(g->kind) << "</td><td>" << e(g->label) << "</td><td class=\"num\">"
        << e(num(100 * g->share, 0)) << " %</td><td class=\"num\">"
        << e(num(g->excess > 0 ? 100 * g->share / g->excess : 0.0, 0))
        << " %</td><td class=\"num\">" << e(num(g->mean, 3)) << "</td></tr>\n";
    o << "</table>\n";
  }
  o << "<h3>Residual tests</h3>\n<table id=\"where-tests\"><tr><th>test</th><th>score</th>"
       "<th>points to</th><th>detail</th></tr>\n";
  for (const auto& ts : a.tests) {
    std::string effects;
    for (std::size_t i = 0; i < ts.effects.size(); ++i) effects += (i ? ", " : "") + ts.effects[i];
    if (effects.empty()) effects = "none (reported only)";
    o << "<tr" << (ts.score >= 0.3 ? " style=\"font-weight:bold\"" : "") << "><td>" << e(ts.name)
      << "</td><td class=\"num\">" << e(num(ts.score, 2)) << "</td><td>" << e(effects)
      << "</td><td>" << e(ts.detail) << "</td></tr>\n";
  }
  o << "</table>\n</section>\n";
}

void diagnosis_section(std::ostringstream& o, const ReportContent& c) {
  o << "<section id=\"diagnosis\">\n<h2>Diagnosis: which effect is missing</h2>\n";
  if (c.diagnosis == nullptr || c.diagnosis->steps.empty()) {
    o << "<p class=\"note\">Not diagnosed (run <code>valvediag diagnose</code>, or the report "
         "without --no-diagnose).</p>\n</section>\n";
    return;
  }
  const Diagnosis& d = *c.diagnosis;
  const auto& t = c.data->t;
  if (!c.diagnosis_command.empty())
    o << "<p>Run as <code>" << e(c.diagnosis_command) << "</code>.</p>\n";
  if (d.steps.size() > 1) {
    o << "<p>Ladder climbed:</p>\n<ol>\n";
    for (std::size_t i = 0; i < d.steps.size(); ++i) {
      const auto& f = d.steps[i].fit;
      o << "<li><code>" << e(to_string(f.spec)) << "</code>: " << e(pct(f.fitness_percent))
        << " estimation, " << e(pct(f.validation_fitness_percent)) << " validation";
      if (i > 0)
        o << " ("
          << e(signed_num(f.validation_fitness_percent -
                          d.steps[i - 1].fit.validation_fitness_percent))
          << ")";
      o << "</li>\n";
    }
    o << "</ol>\n";
  }
  const auto& s = d.last();
  o << "<p>Model diagnosed: <code>" << e(to_string(s.fit.spec)) << "</code>, "
    << e(num(s.fit.fitness_percent)) << " % estimation, "
    << e(num(s.fit.validation_fitness_percent)) << " % validation. Each effect not in it is "
    << "added in a trial fit and scored on estimation and held-out data (the smaller gain "
       "counts), with the residual tests that point to it.</p>\n";
  if (const std::string jn = judge_note(s); !jn.empty()) o << "<p>Judge: " << e(jn) << ".</p>\n";
  o << "<table id=\"findings\"><tr><th>rank</th><th>effect</th><th>score</th>"
       "<th>gain, validation / estimation "
       "(points)</th><th title=\"change of BIC of the one-step prediction of PV from the trial's "
       "valve position and dead time; negative: it predicts better than the model\">"
       "prediction BIC</th><th>evidence</th><th>explanation</th></tr>\n";
  int rank = 0;
  for (const auto& f : s.findings) {
    o << "<tr" << (f.supported ? " style=\"font-weight:bold\"" : "") << "><td class=\"num\">"
      << ++rank << "</td><td>" << e(f.effect) << "</td><td class=\"num\">" << e(num(f.score, 2))
      << "</td><td class=\"num\">" << e(signed_num(f.validation_gain_percent)) << " / "
      << e(signed_num(f.estimation_gain_percent)) << "</td><td class=\"num\">"
      << e(std::isfinite(f.prediction_bic_change) ? signed_num(f.prediction_bic_change, 0)
                                                  : std::string("-"))
      << "</td><td>"
      << e(f.evidence_test.empty() ? "-" : f.evidence_test + " " + num(f.evidence, 2))
      << "</td><td>" << e(f.explanation);
    if (!f.parameters.empty())
      o << "<br><small>" << e(report_format::parameters(f.parameters)) << "</small>";
    if (!f.indistinguishable_from.empty())
      o << "<br><small>as good as <code>" << e(f.indistinguishable_from)
        << "</code> on this data: the data cannot tell them apart</small>";
    if (const std::string note = held_valve_note(f); !note.empty())
      o << "<br><small>" << e(note) << "</small>";
    o << "</td></tr>\n";
  }
  o << "</table>\n";
  if (!s.findings.empty() && s.findings.front().supported) {
    const auto& f = s.findings.front();
    if (!f.intervals.empty() || !f.regions.empty()) {
      o << "<p>Where <code>" << e(f.effect) << "</code> shows:</p>\n<ul>\n";
      const TimeAxis axis(*c.data);
      for (const auto& iv : f.intervals) {
        const double a0 = t_at(t, iv.begin), a1 = t_at(t, iv.end > 0 ? iv.end - 1 : 0);
        o << "<li>t " << e(num(a0, 1)) << " .. " << e(num(a1, 1)) << " s";
        if (axis.clock) o << " (" << e(axis.stamp(a0)) << " .. " << e(axis.stamp(a1)) << ")";
        o << ", " << e(num(100 * iv.share, 0)) << " % of the error</li>\n";
      }
      for (const auto& g : f.regions)
        o << "<li>" << e(g.label) << " carries " << e(num(100 * g.share, 0))
          << " % of the error</li>\n";
      o << "</ul>\n";
    }
  } else if (!s.findings.empty()) {
    o << "<p>No effect is clearly missing: the best candidate, <code>"
      << e(s.findings.front().effect)
      << "</code>, gains too little to be worth its parameters.</p>\n";
  }
  o << "<p>Verdict: <span class=\"verdict\">" << e(c.verdict.empty() ? "not judged" : c.verdict)
    << "</span>. " << e(c.verdict_basis.empty() ? "" : c.verdict_basis + " ") << e(d.conclusion)
    << "</p>\n</section>\n";
}

void ladder_section(std::ostringstream& o, const ReportContent& c) {
  o << "<section id=\"ladder\">\n<h2>Model ladder</h2>\n";
  if (c.ladder.empty()) {
    o << "<p>No model history for this data yet.</p>\n</section>\n";
    return;
  }
  o << "<table id=\"ladder-table\"><tr><th>#</th><th>model</th><th>estimation</th>"
       "<th>validation</th><th>change</th><th>(na, nb, nk)</th><th>parameters</th><th>by</th>"
       "<th>time (UTC)</th></tr>\n";
  for (std::size_t i = 0; i < c.ladder.size(); ++i) {
    const auto& h = c.ladder[i];
    std::string change;
    if (i > 0) {
      const auto& p = c.ladder[i - 1];
      const bool val = std::isfinite(h.validation_fitness_percent) &&
                       std::isfinite(p.validation_fitness_percent);
      change = val ? signed_num(h.validation_fitness_percent - p.validation_fitness_percent) +
                         " validation"
                   : signed_num(h.fitness_percent - p.fitness_percent) + " estimation";
    }
    o << "<tr><td class=\"num\">" << i + 1 << "</td><td><code>" << e(h.model)
      << "</code></td><td class=\"num\">" << e(pct(h.fitness_percent)) << "</td><td class=\"num\">"
      << e(pct(h.validation_fitness_percent)) << "</td><td class=\"num\">" << e(change)
      << "</td><td>(" << h.na << ", " << h.nb << ", " << h.nk << ")</td><td>"
      << e(report_format::parameters(h.parameters)) << "</td><td>" << e(h.command) << "</td><td>"
      << e(h.time) << "</td></tr>\n";
  }
  o << "</table>\n</section>\n";
}

std::string gnuplot_version(const std::string& svg) {
  const auto p = svg.find("Produced by GNUPLOT");
  if (p == std::string::npos) return "";
  const auto end = svg.find('<', p);
  std::string v = svg.substr(p + 12, end == std::string::npos ? 40 : end - p - 12);
  while (!v.empty() && v.back() == ' ') v.pop_back();
  return v;
}

// The plots of a page, each drawn by its own gnuplot, run concurrently (each takes a fraction of
// a second). svg[i] is empty for a plot not drawn: its job's `missing` says why, else
// `not_drawn` (gnuplot missing, or plots left out) does.
struct DrawnPlots {
  std::vector<std::string> svg;
  std::string not_drawn;
  std::string gnuplot_version;
};

DrawnPlots draw(std::vector<PlotJob>& jobs, const ReportOptions& opt, HtmlReport& rep) {
  DrawnPlots d;
  d.svg.resize(jobs.size());
  const auto t0 = std::chrono::steady_clock::now();
  if (!opt.plots) {
    d.not_drawn = "Plots left out (--no-plots).";
  } else {
    std::vector<std::future<std::string>> runs;
    for (const auto& j : jobs)
      runs.push_back(std::async(std::launch::async, [&opt, script = j.script] {
        return script.empty() ? std::string() : gnuplot_run(script, opt.gnuplot);
      }));
    std::exception_ptr missing;
    for (std::size_t i = 0; i < jobs.size(); ++i) {
      try {
        d.svg[i] = runs[i].get();
      } catch (const GnuplotMissing& ex) {
        if (!missing) missing = std::current_exception();
        d.not_drawn = ex.what();
      } catch (const GnuplotError& ex) {
        rep.warnings.push_back(jobs[i].id + ": " + ex.what());
        jobs[i].missing = std::string("This plot could not be drawn: ") + ex.what();
      }
    }
    if (missing) {
      if (opt.require_plots) std::rethrow_exception(missing);
      for (auto& s : d.svg) s.clear();
      rep.warnings.push_back(d.not_drawn);
    }
  }
  rep.plot_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  for (const auto& s : d.svg)
    if (d.gnuplot_version.empty() && !s.empty()) d.gnuplot_version = gnuplot_version(s);
  return d;
}

void figure(std::ostringstream& o, const PlotJob& j, const DrawnPlots& d, std::size_t i,
            HtmlReport& rep) {
  o << "<figure id=\"" << j.id << "\" class=\"plot\">\n<figcaption>" << e(j.title)
    << "</figcaption>\n";
  if (!d.svg[i].empty()) {
    o << inline_svg(d.svg[i], j.id) << "\n";
    if (!j.caption.empty()) o << "<p class=\"caption\">" << e(j.caption) << "</p>\n";
    rep.plots.push_back(j.id);
  } else {
    const std::string why = !j.missing.empty()     ? j.missing
                            : !d.not_drawn.empty() ? d.not_drawn
                                                   : std::string("Not drawn.");
    o << "<p class=\"note\">" << e(why) << "</p>\n";
  }
  o << "</figure>\n";
}

void page_head(std::ostringstream& o, const std::string& data_name) {
  o << "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n"
    << "<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n"
    << "<title>valvediag report: " << e(data_name) << "</title>\n<style>" << kStyle
    << "</style>\n</head>\n<body>\n";
  o << "<h1>Control valve report: " << e(data_name) << "</h1>\n";
}

void page_foot(std::ostringstream& o, const std::string& generator, const std::string& generated,
               const DrawnPlots& d) {
  o << "<footer>Written by " << e(generator) << " on " << e(generated)
    << (d.gnuplot_version.empty() ? std::string()
                                  : "; plots by " + e(d.gnuplot_version) + " (SVG terminal)")
    << ". One self-contained file: no scripts, no external resources.</footer>\n";
  o << "</body>\n</html>\n";
}

// "1 h 20 min", "12 min", "45 s": a record's length as people say it.
std::string duration_text(double s) {
  if (!(s >= 0)) return "n/a";
  if (s < 120) return num(s, 0) + " s";
  const long m = std::lround(s / 60.0);
  if (m < 120) return std::to_string(m) + " min";
  return std::to_string(m / 60) + " h " + std::to_string(m % 60) + " min";
}

}  // namespace

HtmlReport html_report(const ReportContent& c, const ReportOptions& opt) {
  if (c.data == nullptr || c.fit == nullptr)
    throw std::invalid_argument("html_report: data and fit are required");
  const LoopData& d = *c.data;
  const ModelFit& f = *c.fit;
  if (d.size() < 2 || d.op.size() != d.size() || d.pv.size() != d.size())
    throw std::invalid_argument("html_report: the data needs t, op and pv of equal length");
  if (f.status == ModelFitStatus::NoStableModel || f.y_sim.size() != d.size() ||
      f.x_hat.size() != d.size())
    throw std::invalid_argument("html_report: the fit has no model for this data");
  ReportContent content = c;
  if (content.generated.empty()) content.generated = utc_timestamp();

  std::vector<PlotJob> jobs{trends_plot(d, opt.buckets),
                            fit_plot(content, opt.buckets),
                            residual_plot(content, opt.buckets),
                            resid_plot(content),
                            signature_plot(content),
                            preisach_plot(content),
                            pv_op_plot(d),
                            bode_plot(content),
                            step_plot(content),
                            ladder_plot(content)};
  HtmlReport rep;
  const DrawnPlots drawn = draw(jobs, opt, rep);
  auto fig = [&](std::ostringstream& o, std::size_t i) { figure(o, jobs[i], drawn, i, rep); };

  std::ostringstream o;
  page_head(o, content.data_name);
  header_section(o, content);
  o << "<section id=\"plots-data\">\n<h2>The data and the fit</h2>\n";
  fig(o, 0);
  fig(o, 1);
  fig(o, 2);
  fig(o, 3);
  o << "</section>\n<section id=\"plots-valve\">\n<h2>The valve</h2>\n<div class=\"pair\">\n";
  fig(o, 4);
  fig(o, 5);
  o << "</div>\n<div class=\"pair\">\n";
  fig(o, 6);
  o << "</div>\n</section>\n<section id=\"plots-process\">\n<h2>The process (linear "
       "block)</h2>\n";
  fig(o, 7);
  fig(o, 8);
  o << "</section>\n";
  where_section(o, content);
  diagnosis_section(o, content);
  o << "<section id=\"plots-ladder\">\n<h2>Model ladder: the error as effects are added</h2>\n";
  fig(o, 9);
  o << "</section>\n";
  ladder_section(o, content);
  page_foot(o, content.generator, content.generated, drawn);
  rep.html = o.str();
  return rep;
}

HtmlReport html_data_page(const DataPageContent& c, const ReportOptions& opt) {
  if (c.data == nullptr) throw std::invalid_argument("html_data_page: data is required");
  const LoopData& d = *c.data;
  if (d.size() < 2 || d.op.size() != d.size() || (d.has_pv() && d.pv.size() != d.size()))
    throw std::invalid_argument("html_data_page: the data needs t and op (and pv) of equal length");
  const std::string generated = c.generated.empty() ? utc_timestamp() : c.generated;
  std::vector<PlotJob> jobs{trends_plot(d, opt.buckets)};
  HtmlReport rep;
  const DrawnPlots drawn = draw(jobs, opt, rep);

  std::ostringstream o;
  page_head(o, c.data_name);
  o << "<section id=\"summary\">\n<table class=\"header\">\n";
  record_rows(o, d, c.data_name, ", " + duration_text(d.t.back() - d.t.front()));
  row(o, "recorded",
      std::string("OP") + (d.has_pv() ? ", PV" : "") + (d.has_sp() ? ", SP" : "") +
          (d.has_mv() ? ", valve position (MV)" : ""));
  row(o, "generated", e(generated));
  row(o, "model", "none");
  row(o, "why", e(c.reason));
  row(o, "verdict", "<span class=\"verdict\">" + e(c.verdict) + "</span>");
  for (const auto& [head, text] : c.findings) row(o, head, e(text));
  o << "</table>\n";
  for (const auto& n : c.notes) o << "<p class=\"note\">" << e(n) << "</p>\n";
  o << "</section>\n";

  if (c.health != nullptr) {
    const LoopHealth& h = *c.health;
    const std::string what = h.signal == "op"   ? "OP"
                             : h.signal == "pv" ? "PV"
                                                : "the control error SP - PV";
    o << "<section id=\"health\">\n<h2>Loop health (no model needed)</h2>\n"
         "<table class=\"header\">\n";
    row(o, "oscillation",
        h.oscillating
            ? "yes, in " + e(what) + ": period " + e(num(h.period_s, 0)) + " s, amplitude " +
                  e(num(h.amplitude, 3)) + ", regularity " + e(num(h.regularity, 2))
        : h.period_s > 0 ? "no regular cycle in " + e(what) + " (period " + e(num(h.period_s, 0)) +
                               " s, regularity " + e(num(h.regularity, 2)) + ", under 1)"
                         : "none found in " + e(what));
    row(o, "OP reversals",
        e(num(h.op_reversals_per_hour, 1)) + " per hour (beyond the OP noise band " +
            e(strprintf("%.3g", h.op_noise)) + ")");
    row(o, "OP travel", e(num(h.op_travel_percent_per_hour, 1)) + " % of the OP range per hour");
    row(o, "OP span", e(num(h.op_span_percent, 1)) + " % of the OP range");
    row(o, "time at OP limits", e(num(h.time_at_limits_percent, 1)) + " %");
    o << "</table>\n</section>\n";
  }
  o << "<section id=\"plots-data\">\n<h2>The data</h2>\n";
  figure(o, jobs[0], drawn, 0, rep);
  o << "</section>\n";
  page_foot(o, c.generator, generated, drawn);
  rep.html = o.str();
  return rep;
}

}  // namespace valvediag
