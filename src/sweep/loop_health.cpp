#include "valvediag/loop_health.hpp"

#include <algorithm>
#include <cmath>
#include <complex>
#include <numeric>
#include <unsupported/Eigen/FFT>

#include "valvediag/identifiability.hpp"

namespace valvediag {

namespace {

double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  const auto mid = v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2);
  std::nth_element(v.begin(), mid, v.end());
  return *mid;
}

// Normalised autocorrelation for lags 0..N-1 through one FFT (zero-padded: no wrap-around).
std::vector<double> autocorrelation(const std::vector<double>& x) {
  const std::size_t N = x.size();
  std::size_t n = 1;
  while (n < 2 * N) n <<= 1;
  std::vector<double> padded(n, 0.0);
  std::copy(x.begin(), x.end(), padded.begin());
  Eigen::FFT<double> fft;
  std::vector<std::complex<double>> X;
  fft.fwd(X, padded);
  for (auto& c : X) c = std::norm(c);
  std::vector<double> r;
  fft.inv(r, X);
  r.resize(N);
  const double r0 = r[0];
  if (!(r0 > 0)) return {};
  for (auto& v : r) v /= r0;
  return r;
}

// OP noise: the spread of second differences of white noise is sqrt(6) sigma; the median keeps
// real moves (steps, ramps) out of it.
double noise_level(const std::vector<double>& u) {
  if (u.size() < 3) return 0.0;
  std::vector<double> d2(u.size() - 2);
  for (std::size_t k = 0; k + 2 < u.size(); ++k) d2[k] = std::abs(u[k + 2] - 2 * u[k + 1] + u[k]);
  return 1.4826 * median(std::move(d2)) / std::sqrt(6.0);
}

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
  h.op_noise = noise_level(d.op);
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

  // Oscillation of the control error.
  std::vector<double> e(d.size());
  h.signal = d.has_sp() ? "sp-pv" : "pv";
  for (std::size_t k = 0; k < d.size(); ++k) e[k] = d.has_sp() ? d.sp[k] - d.pv[k] : d.pv[k];
  const double mean = std::accumulate(e.begin(), e.end(), 0.0) / static_cast<double>(e.size());
  double var = 0.0;
  for (auto& v : e) {
    v -= mean;
    var += v * v;
  }
  var /= static_cast<double>(e.size());
  h.amplitude = std::sqrt(2.0 * var);  // a sine's amplitude from its RMS
  const std::vector<double> r = autocorrelation(e);
  if (r.empty()) return h;
  // Zero crossings of the ACF (linear interpolation), up to 11 of them, within half the record
  // (beyond it the ACF rests on too few products).
  std::vector<double> z;
  for (std::size_t k = 1; k < r.size() / 2 && z.size() < 11; ++k)
    if ((r[k - 1] > 0) != (r[k] > 0))
      z.push_back(static_cast<double>(k - 1) + r[k - 1] / (r[k - 1] - r[k]));
  if (z.size() < 4) return h;  // fewer than 3 half-periods: no evidence of a regular period
  std::vector<double> half(z.size() - 1);
  for (std::size_t i = 0; i + 1 < z.size(); ++i) half[i] = z[i + 1] - z[i];
  const double hm =
      std::accumulate(half.begin(), half.end(), 0.0) / static_cast<double>(half.size());
  double hs = 0.0;
  for (double v : half) hs += (v - hm) * (v - hm);
  hs = std::sqrt(hs / static_cast<double>(half.size() - 1));
  h.regularity = hs > 0 ? hm / (3.0 * hs) : 100.0;
  h.regularity = std::min(h.regularity, 100.0);
  // The ACF's first positive peak after one period: how much of the error the oscillation is.
  const std::size_t k1 = static_cast<std::size_t>(z[1]), k2 = static_cast<std::size_t>(z[2]) + 1;
  double peak = 0.0;
  for (std::size_t k = k1; k <= k2 && k < r.size(); ++k) peak = std::max(peak, r[k]);
  h.period_s = 2.0 * hm * Ts;
  h.oscillating = h.regularity > 1.0 && peak > 0.2 && hm >= 2.0;
  if (!h.oscillating) h.period_s = 0.0;
  return h;
}

std::string unusable_reason(const LoopData& d, const LoopHealth& h, std::size_t min_samples) {
  auto num = [](double v) {
    char b[32];
    std::snprintf(b, sizeof b, "%.3g", v);
    return std::string(b);
  };
  if (d.size() < min_samples)
    return "only " + std::to_string(d.size()) + " samples; at least " +
           std::to_string(min_samples) + " are needed (take a longer window)";
  const auto [pmin, pmax] = std::minmax_element(d.pv.begin(), d.pv.end());
  if (!(*pmax > *pmin)) return "PV does not change: is the transmitter alive?";
  const auto [omin, omax] = std::minmax_element(d.op.begin(), d.op.end());
  if (!(*omax - *omin > 4.0 * h.op_noise) || h.op_span_percent < 0.2)
    return "OP does not move beyond its noise (span " + num(h.op_span_percent) +
           " % of the range): the loop is in manual or the controller is idle";
  const double reversals = h.op_reversals_per_hour * h.duration_s / 3600.0;
  if (reversals < 4)
    return "OP reverses " + num(std::round(reversals)) +
           " times in the window; at least 4 are needed to see the valve's friction";
  if (h.time_at_limits_percent > 95.0)
    return "OP sits at its limits " + num(h.time_at_limits_percent) +
           " % of the time: the valve cannot act on the loop";
  PreisachGrid grid;
  grid.umin = *omin;
  grid.umax = *omax;
  grid.L = 10;
  const Identifiability id = analyse_identifiability(grid, d.op);
  if (id.kind == ExcitationKind::Insufficient) return "OP does not excite the valve: " + id.summary;
  return "";
}

}  // namespace valvediag
