#include "valvediag/sweep/loop_health.hpp"

#include <algorithm>
#include <cmath>
#include <numeric>

#include "valvediag/core/identifiability.hpp"
#include "valvediag/diagnose/limit_cycle.hpp"
#include "valvediag/util/text_stats.hpp"

namespace valvediag {

namespace {

struct TurningPoints {
  int reversals = 0;
  double path = 0.0;  // length of the OP path between turning points
};

// Reversals counted with hysteresis `band`: a move back from the last extreme by more than the
// band is a reversal; smaller wiggles are noise.
TurningPoints turning_points(const std::vector<double>& u, double band) {
  TurningPoints tp;
  if (u.empty()) return tp;
  double anchor = u[0], extreme = u[0];
  int dir = 0;  // +1 rising, -1 falling, 0 not yet moving
  for (double v : u) {
    if (dir == 0) {
      if (v > anchor + band) dir = 1;
      if (v < anchor - band) dir = -1;
      if (dir != 0) extreme = v;
      continue;
    }
    if ((dir > 0 && v > extreme) || (dir < 0 && v < extreme)) {
      extreme = v;
    } else if (std::abs(v - extreme) > band) {
      tp.path += std::abs(extreme - anchor);
      anchor = extreme;
      extreme = v;
      dir = -dir;
      ++tp.reversals;
    }
  }
  if (dir != 0) tp.path += std::abs(extreme - anchor);
  return tp;
}

// Subtracts the least-squares straight line through x over the sample index.
void remove_line(std::vector<double>& x) {
  const double n = static_cast<double>(x.size());
  const double tm = (n - 1.0) / 2.0;  // mean index
  const double xm = std::accumulate(x.begin(), x.end(), 0.0) / n;
  double sxx = 0.0, sxy = 0.0;
  for (std::size_t k = 0; k < x.size(); ++k) {
    const double dt = static_cast<double>(k) - tm;
    sxx += dt * dt;
    sxy += dt * (x[k] - xm);
  }
  const double slope = sxx > 0 ? sxy / sxx : 0.0;
  for (std::size_t k = 0; k < x.size(); ++k) x[k] -= xm + slope * (static_cast<double>(k) - tm);
}

// A sample a million times the signal's usual size (its median, the spread of its middle 98 %,
// or 1 unit): below the readers' 1e12 bound, yet no measurement. Left in, it stretches OP's span
// so that every real move falls within one level and the record ends as "not enough data"
// without saying why. "" when there is none; else the first such sample, named.
std::string spike_in(const std::vector<double>& v, const std::vector<double>& t, const char* name) {
  if (v.size() < 3) return "";
  std::vector<double> s(v);
  auto at = [&](double q) {
    const auto k = static_cast<std::ptrdiff_t>(q * static_cast<double>(s.size() - 1));
    std::nth_element(s.begin(), s.begin() + k, s.end());
    return s[static_cast<std::size_t>(k)];
  };
  const double lo = at(0.01), mid = at(0.5), hi = at(0.99);
  const double usual = std::max({std::abs(mid), hi - lo, 1.0});
  for (std::size_t i = 0; i < v.size(); ++i)
    if (std::abs(v[i] - mid) > 1e6 * usual)
      return strprintf(
          "%s sample %zu (t = %.6g s) is %.6g, a million times its usual size (98 %% of it lies "
          "in %.6g .. %.6g): a spike, a historian's bad-value marker or a corrupt cell; remove "
          "that row or fill it in",
          name, i + 1, t[i], v[i], lo, hi);
  return "";
}

}  // namespace

LoopHealth loop_health(const LoopData& d, const OpRange& range) {
  LoopHealth h;
  h.samples = d.size();
  if (d.size() < 2) return h;
  const double Ts = d.sample_period();
  h.duration_s = d.t.back() - d.t.front() + Ts;
  const double hours = h.duration_s / 3600.0;
  const double width = std::max(range.hi - range.lo, 1e-12);

  // OP figures.
  h.op_noise = noise_sigma(d.op);
  const auto [mn, mx] = std::minmax_element(d.op.begin(), d.op.end());
  h.op_span_percent = 100.0 * (*mx - *mn) / width;
  const double band = std::max(0.001 * width, 3.0 * h.op_noise);
  const TurningPoints tp = turning_points(d.op, band);
  h.op_reversals_per_hour = tp.reversals / hours;
  h.op_travel_percent_per_hour = 100.0 * tp.path / width / hours;
  const double edge = 0.005 * width;
  std::size_t at_limits = 0;
  for (double u : d.op)
    if (u <= range.lo + edge || u >= range.hi - edge) ++at_limits;
  h.time_at_limits_percent = 100.0 * static_cast<double>(at_limits) / static_cast<double>(d.size());

  // Oscillation of the control error; of OP when PV was not recorded (the controller passes
  // the loop's oscillation on to OP, so OP-only records still show it).
  const bool op_only = d.pv.size() != d.size();
  std::vector<double> e(d.size());
  h.signal = op_only ? "op" : d.has_sp() ? "sp-pv" : "pv";
  for (std::size_t k = 0; k < d.size(); ++k)
    e[k] = op_only ? d.op[k] : d.has_sp() ? d.sp[k] - d.pv[k] : d.pv[k];
  // About its straight line, not only its mean: a drift over the record is not an oscillation,
  // and left in it pushes the ACF's zero crossings past half the record (on the stiction
  // database's benchmark, 35 of its 66 loops labelled oscillating are found instead of 30,
  // with none of the 26 others either way).
  remove_line(e);
  double var = 0.0;
  for (double v : e) var += v * v;
  var /= static_cast<double>(e.size());
  h.amplitude = std::sqrt(2.0 * var);  // a sine's amplitude from its RMS
  const Oscillation osc = detect_oscillation(e);
  h.regularity = osc.regularity;
  h.oscillating = osc.oscillating;
  h.period_s = osc.period_samples * Ts;
  return h;
}

std::string unusable_reason(const LoopData& d, const LoopHealth& h, std::size_t min_samples) {
  for (const auto& [v, name] : {std::pair{&d.op, "OP"}, std::pair{&d.pv, "PV"},
                                std::pair{&d.sp, "SP"}, std::pair{&d.mv, "MV"}})
    if (std::string s = spike_in(*v, d.t, name); !s.empty()) return s;
  if (d.pv.size() != d.size())
    return "no PV in the record (OP only): the loop-health figures come from OP; a model of the "
           "valve needs PV";
  if (d.size() < min_samples)
    return "only " + std::to_string(d.size()) + " samples; at least " +
           std::to_string(min_samples) + " are needed (take a longer window)";
  const auto [pmin, pmax] = std::minmax_element(d.pv.begin(), d.pv.end());
  if (!(*pmax > *pmin)) return "PV does not change: is the transmitter alive?";
  const auto [omin, omax] = std::minmax_element(d.op.begin(), d.op.end());
  if (!(*omax - *omin > 4.0 * h.op_noise) || h.op_span_percent < 0.2)
    return strprintf(
        "OP does not move beyond its noise (span %.3g %% of the range): the loop is in manual or "
        "the controller is idle",
        h.op_span_percent);
  // Two reversals (up, down and up again) close one loop of the valve's hysteresis, so its band
  // shows on both sides. Measured on simulated records with 2 or 3 reversals: 10 of 20 sticky
  // valves found and none of 9 linear ones called sticky; the limit was 4 before.
  // A count again: the per-hour figure times the hours is 2 only up to rounding (1.9999...).
  const double reversals = std::round(h.op_reversals_per_hour * h.duration_s / 3600.0);
  if (reversals < 2)
    return strprintf(
        "OP reverses %.3g times in the window; at least 2 (up, down and up again) are needed to "
        "see the valve's friction on both sides",
        reversals);
  if (h.time_at_limits_percent > 95.0)
    return strprintf("OP sits at its limits %.3g %% of the time: the valve cannot act on the loop",
                     h.time_at_limits_percent);
  PreisachGrid grid;
  grid.umin = *omin;
  grid.umax = *omax;
  grid.L = 10;
  const Identifiability id = analyse_identifiability(grid, d.op);
  if (id.kind == ExcitationKind::Insufficient) return "OP does not excite the valve: " + id.summary;
  return "";
}

}  // namespace valvediag
