#include "valvediag/diagnose/limit_cycle.hpp"

#include <algorithm>
#include <cmath>
#include <complex>
#include <cstdio>
#include <numeric>

#include "valvediag/core/autocorrelation.hpp"
#include "valvediag/util/text_stats.hpp"

namespace valvediag {

namespace {

constexpr double kPi = 3.14159265358979323846;

// Complex amplitude of x[b, b+n) at `period` samples about its mean. A sine of amplitude A gives
// |result| = A over whole cycles. (No straight line is removed: over two periods a line takes
// a share of the sine itself, while a drift leaks little into so short a segment.)
std::complex<double> cycle_amplitude(const std::vector<double>& x, std::size_t b, std::size_t n,
                                     double period) {
  const double m = static_cast<double>(n);
  double mean = 0.0;
  for (std::size_t k = 0; k < n; ++k) mean += x[b + k];
  mean /= m;
  std::complex<double> s = 0.0;
  for (std::size_t k = 0; k < n; ++k) {
    const double w = -2.0 * kPi * static_cast<double>(k) / period;
    s += (x[b + k] - mean) * std::complex<double>(std::cos(w), std::sin(w));
  }
  return 2.0 * s / m;
}

}  // namespace

double noise_sigma(const std::vector<double>& x) {
  if (x.size() < 3) return 0.0;
  std::vector<double> d2(x.size() - 2);
  for (std::size_t k = 0; k + 2 < x.size(); ++k) d2[k] = std::abs(x[k + 2] - 2 * x[k + 1] + x[k]);
  return 1.4826 * median(std::move(d2)) / std::sqrt(6.0);
}

Oscillation detect_oscillation(const std::vector<double>& x) {
  Oscillation o;
  if (x.size() < 8) return o;
  const std::vector<double> r = autocorrelation(x);
  if (r.empty()) return o;
  // Zero crossings of the ACF (linear interpolation), up to 11 of them, within half the record
  // (beyond it the ACF rests on too few products).
  std::vector<double> z;
  for (std::size_t k = 1; k < r.size() / 2 && z.size() < 11; ++k)
    if ((r[k - 1] > 0) != (r[k] > 0))
      z.push_back(static_cast<double>(k - 1) + r[k - 1] / (r[k - 1] - r[k]));
  if (z.size() < 4) return o;  // fewer than 3 half-periods: no evidence of a regular period
  std::vector<double> half(z.size() - 1);
  for (std::size_t i = 0; i + 1 < z.size(); ++i) half[i] = z[i + 1] - z[i];
  const double hm =
      std::accumulate(half.begin(), half.end(), 0.0) / static_cast<double>(half.size());
  double hs = 0.0;
  for (double v : half) hs += (v - hm) * (v - hm);
  hs = std::sqrt(hs / static_cast<double>(half.size() - 1));
  o.regularity = std::min(hs > 0 ? hm / (3.0 * hs) : 100.0, 100.0);
  // The ACF's first positive peak after one period: how much of the signal the oscillation is.
  const std::size_t k1 = static_cast<std::size_t>(z[1]), k2 = static_cast<std::size_t>(z[2]) + 1;
  for (std::size_t k = k1; k <= k2 && k < r.size(); ++k) o.acf_peak = std::max(o.acf_peak, r[k]);
  o.period_samples = 2.0 * hm;
  o.oscillating = o.regularity > 1.0 && o.acf_peak > 0.2 && hm >= 2.0;
  if (!o.oscillating) o.period_samples = 0.0;
  return o;
}

LimitCycle limit_cycle_test(const std::vector<double>& u, const std::vector<double>& y,
                            const std::vector<double>& y_model, double Ts, bool integrating,
                            const TrialEvidence& trials, const LimitCycleOptions& opt) {
  LimitCycle c;
  c.integrating = integrating;
  c.memory_gain = trials.memory_gain;
  const double left = 100.0 - trials.start_fitness - trials.memory_gain;  // error memory leaves
  if (trials.rival_gain - trials.memory_gain >= 0.2 * left) c.rival = trials.rival;
  const Oscillation osc = detect_oscillation(y);
  c.oscillating = osc.oscillating;
  if (!osc.oscillating || u.size() != y.size()) {
    c.summary = "PV does not oscillate regularly: the limit-cycle test does not apply";
    return c;
  }
  // The ACF's zero crossings give the period to a few per cent; the cycle's power over two-period
  // segments peaks at the true one (a wrong period leaks amplitude out of the bin).
  auto power = [&y](double p) {
    const auto L = static_cast<std::size_t>(std::llround(2.0 * p));
    double s = 0.0;
    for (std::size_t b = 0; L > 0 && b + L <= y.size(); b += L)
      s += std::norm(cycle_amplitude(y, b, L, p));
    return s;
  };
  double P = osc.period_samples, best = power(P);
  for (int k = -10; k <= 10; ++k) {
    const double p = osc.period_samples * (1.0 + 0.01 * k);
    if (const double w = power(p); w > best) {
      best = w;
      P = p;
    }
  }
  c.period_s = P * Ts;
  // Segments of two periods each: the phase between OP and PV is averaged through their cross
  // spectrum, so a period that wanders over a long record does not cancel the cycle out.
  const auto L = static_cast<std::size_t>(std::llround(2.0 * P));
  bool model_ok = y_model.size() == y.size();
  for (std::size_t k = 0; model_ok && k < y_model.size(); ++k) model_ok = std::isfinite(y_model[k]);
  std::complex<double> Suy = 0.0;
  double Suu = 0.0, Syy = 0.0, See = 0.0;
  std::size_t segments = 0;
  for (std::size_t b = 0; b + L <= y.size(); b += L, ++segments) {
    const std::complex<double> U = cycle_amplitude(u, b, L, P), Y = cycle_amplitude(y, b, L, P);
    Suy += std::conj(U) * Y;
    Suu += std::norm(U);
    Syy += std::norm(Y);
    if (model_ok) See += std::norm(Y - cycle_amplitude(y_model, b, L, P));
  }
  if (segments == 0 || !(Suu > 0) || !(Syy > 0)) {
    c.summary = segments == 0 ? "PV oscillates but the record holds less than two periods"
                              : "PV oscillates but OP has no part at the cycle's frequency";
    return c;
  }
  const double ns = static_cast<double>(segments);
  c.op_amplitude = std::sqrt(Suu / ns);
  const double phase = std::arg(Suy);
  c.phase_deg = phase * 180.0 / kPi;
  const double s = std::abs(std::sin(phase));
  c.odd = s > std::sqrt(0.5);
  c.apparent_band = 2.0 * c.op_amplitude * s;
  if (model_ok) c.model_share = 1.0 - std::sqrt(See / Syy);
  const std::string head = strprintf(
      "PV oscillates with a period of %.0f s and lies %.0f deg from OP", c.period_s, c.phase_deg);
  const bool op_moves = c.op_amplitude > opt.min_op_amplitude_noise * noise_sigma(u);
  if (integrating)
    c.summary = head +
                "; the process integrates, so the phase does not tell stick-slip (Horch's "
                "test is for self-regulating loops)";
  else if (!op_moves)
    c.summary = head + "; OP's part of the cycle lies within its noise, so the phase is not known";
  else if (!c.odd)
    c.summary = head +
                " (an even OP-PV cross-correlation): the controller's proportional action "
                "shapes the cycle, as in a loop tuned too tightly, not a stick-slip cycle";
  else if (std::isnan(c.model_share))
    c.summary = head +
                " (odd), but no model driven by OP was fitted (no stable linear part), so "
                "it is not known whether OP drives the cycle";
  else if (!(c.model_share >= opt.min_model_share))
    c.summary = head + strprintf(
                           " (odd), but the model driven by OP carries only %.0f %% of PV's cycle: "
                           "an oscillation from outside the loop, not the valve",
                           100 * c.model_share);
  else if (!(c.memory_gain >= opt.min_memory_gain))
    c.summary = head + strprintf(
                           " (odd), but no valve model with memory gains on held-out data (%+.1f "
                           "points): a slow oscillation the controller compensates, as one from "
                           "outside the loop, looks the same",
                           c.memory_gain);
  else if (!c.rival.empty())
    c.summary = head + " (odd), but `" + c.rival +
                "` explains the data clearly better than a valve with memory (" +
                strprintf("%+.1f against %+.1f points", trials.rival_gain, c.memory_gain) +
                "): not a stick-slip cycle";
  else {
    c.stick_slip = true;
    c.summary =
        head + strprintf(
                   " (an odd OP-PV cross-correlation, Horch's stick-slip signature): the "
                   "controller integrates through the cycle, OP drives %.0f %% of it and a "
                   "valve with memory gains %+.1f points; apparent stiction %.3g (OP units)",
                   100 * c.model_share, c.memory_gain, c.apparent_band);
  }
  return c;
}

}  // namespace valvediag
