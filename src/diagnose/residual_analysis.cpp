#include "valvediag/diagnose/residual_analysis.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numeric>
#include <stdexcept>

#include "valvediag/util/text_stats.hpp"

namespace valvediag {

namespace {

double clamp01(double v) {
  return std::isfinite(v) ? std::clamp(v, 0.0, 1.0) : 0.0;
}

// Robust standard deviation of the white part: MAD of the first difference / sqrt(2).
double noise_level(const std::vector<double>& r) {
  if (r.size() < 3) return 0.0;
  std::vector<double> d(r.size() - 1);
  for (std::size_t t = 1; t < r.size(); ++t) d[t - 1] = r[t] - r[t - 1];
  const double m = median(d);
  for (auto& v : d) v = std::abs(v - m);
  return 1.4826 * median(d) / std::sqrt(2.0);
}

// Normalized cross-correlation of r(t) with x(t - k), k = 0..max_lag.
std::vector<double> ccf(const std::vector<double>& r, const std::vector<double>& x, int max_lag) {
  const std::size_t n = r.size();
  const double mr = std::accumulate(r.begin(), r.end(), 0.0) / static_cast<double>(n);
  const double mx = std::accumulate(x.begin(), x.end(), 0.0) / static_cast<double>(n);
  double sr = 0, sx = 0;
  for (std::size_t t = 0; t < n; ++t) {
    sr += (r[t] - mr) * (r[t] - mr);
    sx += (x[t] - mx) * (x[t] - mx);
  }
  std::vector<double> c(static_cast<std::size_t>(max_lag + 1), 0.0);
  if (!(sr > 0) || !(sx > 0)) return c;
  for (int k = 0; k <= max_lag && static_cast<std::size_t>(k) < n; ++k) {
    double s = 0;
    for (std::size_t t = static_cast<std::size_t>(k); t < n; ++t)
      s += (r[t] - mr) * (x[t - static_cast<std::size_t>(k)] - mx);
    c[static_cast<std::size_t>(k)] = s / std::sqrt(sr * sx);
  }
  return c;
}

// Share of the squared residual explained by the means of groups (eta squared).
double eta_squared(const std::vector<double>& r, const std::vector<int>& group, int groups) {
  std::vector<double> sum(static_cast<std::size_t>(groups), 0.0),
      cnt(static_cast<std::size_t>(groups), 0.0);
  double mean = 0, total = 0;
  for (std::size_t t = 0; t < r.size(); ++t) mean += r[t];
  mean /= static_cast<double>(r.size());
  for (std::size_t t = 0; t < r.size(); ++t) {
    if (group[t] < 0) continue;
    sum[static_cast<std::size_t>(group[t])] += r[t] - mean;
    cnt[static_cast<std::size_t>(group[t])] += 1;
    total += (r[t] - mean) * (r[t] - mean);
  }
  double between = 0;
  for (std::size_t g = 0; g < sum.size(); ++g)
    if (cnt[g] > 0) between += sum[g] * sum[g] / cnt[g];
  return total > 0 ? between / total : 0.0;
}

}  // namespace

const ResidualTest* ResidualAnalysis::test(const std::string& name) const {
  for (const auto& t : tests)
    if (t.name == name) return &t;
  return nullptr;
}

std::vector<std::size_t> op_reversals(const std::vector<double>& u, std::size_t from,
                                      std::size_t to, double hysteresis) {
  std::vector<std::size_t> rev;
  if (to <= from + 2) return rev;
  int dir = 0;
  std::size_t ext = from;  // index of the running extremum in the current direction
  for (std::size_t t = from + 1; t < to; ++t) {
    if (dir >= 0 && u[t] >= u[ext]) {
      if (dir == 0 && u[t] - u[from] > hysteresis) dir = 1;
      if (dir == 1) ext = t;
    }
    if (dir <= 0 && u[t] <= u[ext]) {
      if (dir == 0 && u[from] - u[t] > hysteresis) dir = -1;
      if (dir == -1) ext = t;
    }
    if (dir == 0) {
      if (u[t] > u[ext] || u[t] < u[ext]) ext = from;
      continue;
    }
    if (dir == 1 && u[ext] - u[t] > hysteresis) {
      rev.push_back(ext);
      dir = -1;
      ext = t;
    } else if (dir == -1 && u[t] - u[ext] > hysteresis) {
      rev.push_back(ext);
      dir = 1;
      ext = t;
    }
  }
  return rev;
}

ResidualAnalysis analyse_residual(const std::vector<double>& u, const std::vector<double>& y,
                                  const std::vector<double>& y_sim, std::size_t from,
                                  std::size_t to, const ResidualAnalysisOptions& opt) {
  if (u.size() != y.size() || y.size() != y_sim.size())
    throw std::invalid_argument("residual analysis: u, y and y_sim differ in length");
  to = std::min(to, y.size());
  if (to < from + 20)
    throw std::invalid_argument("residual analysis: the window needs at least 20 samples");
  const std::size_t n = to - from;
  ResidualAnalysis a;
  std::vector<double> r(n), uu(u.begin() + static_cast<std::ptrdiff_t>(from),
                               u.begin() + static_cast<std::ptrdiff_t>(to));
  double sse = 0;
  for (std::size_t k = 0; k < n; ++k) {
    r[k] = y[from + k] - y_sim[from + k];
    sse += r[k] * r[k];
  }
  a.rms = std::sqrt(sse / static_cast<double>(n));
  a.noise_level = noise_level(r);
  const double floor = std::max(a.noise_level, 1e-12 * (1 + a.rms));

  // OP moves smaller than its own noise are not reversals.
  std::vector<double> du(n, 0.0);
  for (std::size_t k = 1; k < n; ++k) du[k] = uu[k] - uu[k - 1];
  const auto [umin_it, umax_it] = std::minmax_element(uu.begin(), uu.end());
  const double urange = *umax_it - *umin_it;
  const double hyst = std::max(3.0 * noise_level(uu), 0.005 * urange);
  const auto rev = op_reversals(uu, 0, n, hyst);
  a.reversals = rev.size();

  // Direction of travel and time since the last reversal, per sample.
  std::vector<int> dir(n, 0);
  std::vector<std::size_t> since(n, n);
  {
    std::size_t ri = 0;
    std::size_t last = n;  // no reversal yet
    for (std::size_t k = 0; k < n; ++k) {
      while (ri < rev.size() && rev[ri] <= k) last = rev[ri++];
      since[k] = last == n ? n : k - last;
      const std::size_t back = std::min<std::size_t>(k, 5);
      const double move = uu[k] - uu[k - back];
      dir[k] = move > hyst / 2 ? 1 : (move < -hyst / 2 ? -1 : 0);
    }
  }

  // Intervals: moving RMS well above the noise level and above the average.
  {
    const std::size_t w = opt.smoothing > 0 ? opt.smoothing : std::max<std::size_t>(10, n / 100);
    std::vector<double> c(n + 1, 0.0);
    for (std::size_t k = 0; k < n; ++k) c[k + 1] = c[k] + r[k] * r[k];
    const double level = std::max(opt.interval_threshold * floor, a.rms);
    std::vector<char> bad(n, 0);
    for (std::size_t k = 0; k < n; ++k) {
      const std::size_t lo = k >= w / 2 ? k - w / 2 : 0, hi = std::min(n, lo + w);
      const double mrms = std::sqrt((c[hi] - c[lo]) / static_cast<double>(hi - lo));
      bad[k] = mrms > level;
    }
    for (std::size_t k = 0; k < n;) {
      if (!bad[k]) {
        ++k;
        continue;
      }
      std::size_t e = k;
      while (e < n && bad[e]) ++e;
      ResidualInterval iv;
      iv.begin = from + k;
      iv.end = from + e;
      iv.rms = std::sqrt((c[e] - c[k]) / static_cast<double>(e - k));
      iv.share = sse > 0 ? (c[e] - c[k]) / sse : 0.0;
      a.intervals.push_back(iv);
      k = e;
    }
    std::sort(a.intervals.begin(), a.intervals.end(),
              [](const auto& x, const auto& y2) { return x.share > y2.share; });
    if (a.intervals.size() > opt.max_intervals) a.intervals.resize(opt.max_intervals);
  }

  // Regions.
  auto add_region = [&](const std::string& kind, const std::string& label, double lo, double hi,
                        const std::vector<char>& in) {
    ResidualRegion g;
    g.kind = kind;
    g.label = label;
    g.lo = lo;
    g.hi = hi;
    double s2 = 0, s1 = 0;
    for (std::size_t k = 0; k < n; ++k)
      if (in[k]) {
        ++g.samples;
        s2 += r[k] * r[k];
        s1 += r[k];
      }
    if (g.samples == 0) return;
    g.rms = std::sqrt(s2 / static_cast<double>(g.samples));
    g.mean = s1 / static_cast<double>(g.samples);
    g.share = sse > 0 ? s2 / sse : 0.0;
    g.excess = g.share / (static_cast<double>(g.samples) / static_cast<double>(n));
    a.regions.push_back(g);
  };
  const int bins = std::max(2, opt.op_bins);
  std::vector<int> bin(n, 0);
  const double bw = urange > 0 ? urange / bins : 1.0;
  for (std::size_t k = 0; k < n; ++k)
    bin[k] = std::min(bins - 1, static_cast<int>((uu[k] - *umin_it) / bw));
  for (int b = 0; b < bins; ++b) {
    std::vector<char> in(n);
    for (std::size_t k = 0; k < n; ++k) in[k] = bin[k] == b;
    const double lo = *umin_it + b * bw, hi = lo + bw;
    add_region("op-level", strprintf("OP %.1f-%.1f", lo, hi), lo, hi, in);
  }
  for (int d : {1, -1, 0}) {
    std::vector<char> in(n);
    for (std::size_t k = 0; k < n; ++k) in[k] = dir[k] == d;
    add_region("direction", d > 0 ? "rising" : (d < 0 ? "falling" : "still"), d, d, in);
  }
  // Time since the last reversal, in bins relative to the typical half-cycle.
  std::size_t half = n;
  if (rev.size() >= 2) {
    std::vector<double> gaps;
    for (std::size_t i = 1; i < rev.size(); ++i)
      gaps.push_back(static_cast<double>(rev[i] - rev[i - 1]));
    half = static_cast<std::size_t>(std::max(4.0, median(gaps)));
  }
  const std::size_t edges[] = {0, std::max<std::size_t>(2, half / 10),
                               std::max<std::size_t>(3, half / 3), half, n + 1};
  for (int b = 0; b < 4; ++b) {
    std::vector<char> in(n);
    for (std::size_t k = 0; k < n; ++k)
      in[k] = since[k] >= edges[b] && since[k] < edges[b + 1] && since[k] < n;
    const std::string label =
        b < 3 ? strprintf("%.0f-%.0f samples after a reversal", static_cast<double>(edges[b]),
                          static_cast<double>(edges[b + 1]))
              : strprintf(">= %.0f samples after a reversal", static_cast<double>(edges[b]));
    add_region("since-reversal", label, static_cast<double>(edges[b]),
               static_cast<double>(edges[b + 1]), in);
  }

  // Residual tests.
  auto push = [&](std::string name, std::vector<std::string> effects, double stat, double score,
                  std::string detail) {
    a.tests.push_back(
        {std::move(name), std::move(effects), stat, clamp01(score), std::move(detail)});
  };
  // 1. Error locked to OP reversals (stiction, deadband).
  {
    double in = 0, nin = 0, jump = 0;
    std::vector<double> jumps;
    const std::size_t win = std::max<std::size_t>(3, half / 4);
    std::vector<char> near(n, 0);
    for (std::size_t rv : rev) {
      double jm = 0;
      for (std::size_t k = rv; k < std::min(n, rv + win); ++k) {
        near[k] = 1;
        if (k > 0) jm = std::max(jm, std::abs(r[k] - r[k - 1]));
      }
      jumps.push_back(jm / floor);
    }
    for (std::size_t k = 0; k < n; ++k)
      if (near[k]) {
        in += r[k] * r[k];
        nin += 1;
      }
    jump = jumps.empty() ? 0.0 : median(jumps);
    const double ratio = (nin > 0 && sse > 0) ? (in / nin) / (sse / static_cast<double>(n)) : 0.0;
    const double enough = rev.size() >= 4 ? 1.0 : 0.0;
    push("reversal-locked", {"stiction", "deadband"}, ratio, enough * (ratio - 1.2) / 1.5,
         rev.size() < 4
             ? strprintf("only %.0f OP reversals: too few to test", static_cast<double>(rev.size()))
             : strprintf(
                   "squared error in the %.0f samples after each of %.0f OP reversals is %.2f x "
                   "the average",
                   static_cast<double>(win), static_cast<double>(rev.size()), ratio) +
                   strprintf("; largest residual step there: %.1f x noise (slip-jump if large)",
                             jump));
  }
  // 2. Error that depends on the OP level (characteristic, preisach, saturation).
  const double eta_level = eta_squared(r, bin, bins);
  push("op-level", {"characteristic", "preisach", "saturation"}, eta_level,
       (eta_level - 0.05) / 0.3,
       strprintf("OP level explains %.0f %% of the residual variance", 100 * eta_level));
  // 3. Error that depends on the direction of travel at the same level (preisach, stiction).
  {
    std::vector<int> g(n);
    for (std::size_t k = 0; k < n; ++k) g[k] = dir[k] == 0 ? -1 : bin[k] * 2 + (dir[k] > 0);
    const double both = eta_squared(r, g, 2 * bins);
    std::vector<int> g1(n);
    for (std::size_t k = 0; k < n; ++k) g1[k] = dir[k] == 0 ? -1 : bin[k];
    const double level_only = eta_squared(r, g1, bins);
    const double gain = std::max(0.0, both - level_only);
    push("direction", {"preisach", "stiction"}, gain, (gain - 0.03) / 0.2,
         strprintf(
             "direction of travel adds %.0f %% of residual variance explained beyond the OP level",
             100 * gain));
  }
  // 4. One-sided error while OP is at an end of its range (saturation).
  {
    std::vector<double> sorted = uu;
    std::sort(sorted.begin(), sorted.end());
    const double lo_q = sorted[n / 10], hi_q = sorted[n - 1 - n / 10];
    double best = 0, mean_best = 0;
    std::string where;
    for (int side : {-1, 1}) {
      double s = 0, c = 0;
      for (std::size_t k = 0; k < n; ++k)
        if ((side < 0 && uu[k] <= lo_q) || (side > 0 && uu[k] >= hi_q)) {
          s += r[k];
          c += 1;
        }
      if (c < 5) continue;
      const double m = s / c;
      const double v = std::abs(m) / std::max(a.rms, 1e-300);
      if (v > best) {
        best = v;
        mean_best = m;
        where = side < 0 ? strprintf("OP <= %.1f", lo_q) : strprintf("OP >= %.1f", hi_q);
      }
    }
    push("one-sided-at-limit", {"saturation"}, best, (best - 0.4) / 0.8,
         where.empty() ? std::string("no samples at the ends of the OP range")
                       : "mean residual " + strprintf("%.3g", mean_best) + " while " + where +
                             strprintf(" (%.2f x the residual RMS)", best));
  }
  // 5-6. Residual correlated with past OP moves: just beyond the model's delay (actuator-lag,
  // order), or further (delay, order).
  {
    const int L = std::max(5, opt.max_lag);
    const auto c = ccf(r, du, L);
    const double band = 1.96 / std::sqrt(static_cast<double>(n));
    const int d0 = static_cast<int>(opt.model_delay);
    double short_max = 0, long_max = 0;
    int short_lag = d0, long_lag = d0;
    for (int k = 0; k <= L; ++k) {
      const double v = std::abs(c[static_cast<std::size_t>(k)]) / band;
      if (k >= d0 && k <= d0 + 3) {
        if (v > short_max) short_max = v, short_lag = k;
      } else if (k > d0 + 3) {
        if (v > long_max) long_max = v, long_lag = k;
      }
    }
    push(
        "input-correlation-short", {"actuator-lag", "order"}, short_max, (short_max - 2) / 4,
        strprintf("residual vs OP moves: peak %.1f x the 95 %% band at lag %.0f (model delay %.0f)",
                  short_max, static_cast<double>(short_lag), static_cast<double>(d0)));
    push(
        "input-correlation-long", {"delay", "order"}, long_max, (long_max - 2) / 4,
        strprintf(
            "residual vs OP moves beyond the model's reach: peak %.1f x the 95 %% band at lag %.0f",
            long_max, static_cast<double>(long_lag)));
  }
  // 7. Low-frequency residual not explained by OP (disturbance, integrator).
  {
    const std::size_t w = std::max<std::size_t>(20, n / 25);
    std::vector<double> c(n + 1, 0.0), lp(n), cu(n + 1, 0.0), lpu(n);
    for (std::size_t k = 0; k < n; ++k) {
      c[k + 1] = c[k] + r[k];
      cu[k + 1] = cu[k] + uu[k];
    }
    for (std::size_t k = 0; k < n; ++k) {
      const std::size_t lo = k >= w / 2 ? k - w / 2 : 0, hi = std::min(n, lo + w);
      lp[k] = (c[hi] - c[lo]) / static_cast<double>(hi - lo);
      lpu[k] = (cu[hi] - cu[lo]) / static_cast<double>(hi - lo);
    }
    const double mean = c[n] / static_cast<double>(n);
    double vlp = 0, vr = 0;
    for (std::size_t k = 0; k < n; ++k) {
      vlp += (lp[k] - mean) * (lp[k] - mean);
      vr += (r[k] - mean) * (r[k] - mean);
    }
    const double frac = vr > 0 ? vlp / vr : 0.0;
    const double with_op = std::abs(ccf(lp, lpu, 0)[0]);
    push("low-frequency", {"disturbance", "integrator"}, frac,
         (frac - 0.3) / 0.5 * (1.0 - 0.5 * with_op),
         strprintf(
             "%.0f %% of the residual variance is slower than %.0f samples; its correlation with "
             "slow OP is %.2f",
             100 * frac, static_cast<double>(w), with_op));
    // Ramp-like drift of the simulated output (integrator).
    double st = 0, stt = 0, sr = 0, srt = 0;
    for (std::size_t k = 0; k < n; ++k) {
      const double t = static_cast<double>(k);
      st += t;
      stt += t * t;
      sr += r[k];
      srt += r[k] * t;
    }
    const double nn = static_cast<double>(n);
    const double slope = (nn * srt - st * sr) / (nn * stt - st * st);
    const double icpt = (sr - slope * st) / nn;
    double sres = 0;
    for (std::size_t k = 0; k < n; ++k) {
      const double e = r[k] - icpt - slope * static_cast<double>(k);
      sres += e * e;
    }
    const double r2 = vr > 0 ? std::max(0.0, 1.0 - sres / vr) : 0.0;
    push("drift", {"integrator", "disturbance"}, r2, (r2 - 0.2) / 0.5,
         strprintf("a straight line in time explains %.0f %% of the residual variance", 100 * r2));
  }
  // 8. Whiteness (Ljung-Box) of the residual. Reported, pointing at no effect: a simulated
  // output's error is the noise filtered by the process, coloured whether or not a load is
  // missing (measured: Q above 200 times its 95 % point on 94 of 138 development loops without
  // one, the same as with one).
  {
    const int h = std::max(5, std::min<int>(opt.max_lag, static_cast<int>(n / 5)));
    const auto c = ccf(r, r, h);
    double q = 0;
    for (int k = 1; k <= h; ++k)
      q += c[static_cast<std::size_t>(k)] * c[static_cast<std::size_t>(k)] /
           static_cast<double>(n - static_cast<std::size_t>(k));
    q *= static_cast<double>(n) * static_cast<double>(n + 2);
    const double hh = h;
    const double crit =
        hh * std::pow(1 - 2 / (9 * hh) + 1.645 * std::sqrt(2 / (9 * hh)), 3);  // chi2 95 %
    push("whiteness", {}, q / crit, (q / crit - 1) / 20,
         strprintf("Ljung-Box Q = %.0f over %.0f lags (white below %.0f)", q, hh, crit));
  }
  return a;
}

}  // namespace valvediag
