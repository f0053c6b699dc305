// The valve-travel test: friction read from OP -> MV (valve_travel.hpp).
#include "valvediag/diagnose/valve_travel.hpp"

#include <nlopt.h>

#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>

#include "valvediag/core/hammerstein.hpp"
#include "valvediag/core/parallel_for.hpp"
#include "valvediag/core/simd.hpp"
#include "valvediag/util/text_stats.hpp"

namespace valvediag {
namespace {

// White-noise sigma from the sample-to-sample changes (a moving valve adds to it: an upper bound).
// Not limit_cycle.hpp's noise_sigma (second differences): this test's thresholds were measured with
// this one.
double step_noise_sigma(const std::vector<double>& x) {
  std::vector<double> d;
  d.reserve(x.size());
  for (std::size_t i = 1; i < x.size(); ++i) d.push_back(std::abs(x[i] - x[i - 1]));
  return quantile(d, 0.5) / 0.6745 / std::sqrt(2.0);
}

// A positioner model: He's valve (band 0: none), a first-order lag, the calibration map. In He's
// terms fs = band (1 + jump) / 2, fd = band (1 - jump) / 2: the band (fs + fd, the OP
// travel after a reversal before the valve moves) sets when the valve moves and the cost is sharp
// in it; the jump's share of the band (fs - fd) / (fs + fd) only sets how far.
struct Candidate {
  double band = 0.0, jump = 0.0, tau = 0.0;
  int motion = 0;  // He's state at the start (-1, 0, +1)
  double fs() const { return std::max(band, 0.0) * (1.0 + std::clamp(jump, 0.0, 1.0)) / 2.0; }
  double fd() const { return std::max(band, 0.0) * (1.0 - std::clamp(jump, 0.0, 1.0)) / 2.0; }
};

struct Evaluated {
  double sse = HUGE_VAL, gain = 0.0;  // gain: the map's mean slope over the OP range
  std::vector<double> mv_hat;
};

// Travel limits MV rests on (a stop, a limit in the positioner): the models clip there, and the
// samples held at a limit do not pull the calibration.
struct Limits {
  double lo = -HUGE_VAL, hi = HUGE_VAL, tol = 0.0;
  bool at(double m) const { return m <= lo + tol || m >= hi - tol; }
};

// He's flowchart (HeStiction, valve_effects.cpp) with each sample's output blended at the slip:
// OP moves linearly between samples, so a slip happens a fraction th into its interval, and the
// sample holds th of the old position and 1 - th of the new (the average over the interval).
// Why: with the bare flowchart a slip lands on one sample or the next as the band changes by a
// hair, and over many slips the cost in the band is a field of needles no search can climb;
// blended, a slip's weight moves with its crossing time and the cost is continuous. The state
// stays He's, so a fast-moving valve (a slip every sample) is He's exactly.
class BlendedHe {
 public:
  BlendedHe(double fs, double fd, double motion, double u0)
      : fs_(fs), fd_(std::min(fd, fs)), u_(u0), ur_(motion * fd_), x_(u0 - ur_) {}
  double position() const { return x_; }
  double step(double u) {
    const double d = u - u_, cum = ur_ + d;
    u_ = u;
    if (std::abs(cum) <= fs_) {
      ur_ = cum;  // stick
      return x_;
    }
    const double s = cum > 0 ? 1.0 : -1.0;
    const double th = std::clamp((fs_ - s * ur_) / std::abs(d), 0.0, 1.0);
    const double x_old = x_;
    ur_ = s * fd_;
    x_ = u - ur_;
    return th * x_old + (1.0 - th) * x_;
  }

 private:
  double fs_, fd_, u_, ur_, x_;
};

// The positioner's calibration from the valve's travel to the transmitted position: a cubic in
// the travel scaled to the OP range (positioners characterise, transmitters are not perfectly
// linear), solved by least squares on the estimation samples off the limits.
class Positioner {
 public:
  Positioner(const std::vector<double>& op, const std::vector<double>& mv, double Ts,
             std::size_t n_est, Limits limits, int degree)
      : op_(op), mv_(mv), Ts_(Ts), n_est_(n_est), lim_(limits), degree_(degree) {
    const auto [lo, hi] = std::minmax_element(op.begin(), op.end());
    centre_ = 0.5 * (*lo + *hi);
    half_ = std::max(0.5 * (*hi - *lo), 1e-9);
    // The calibration's samples do not depend on the candidate: found once.
    for (std::size_t k = 0; k < n_est_; ++k)
      if (!lim_.at(mv_[k])) off_limits_.push_back(k);
  }

  Evaluated evaluate(const Candidate& c, bool keep = false) const {
    if (kHaveAvx) return evaluate_avx(c, keep);
    return evaluate_body<Pairs>(c, keep);
  }

 private:
  VALVEDIAG_AVX Evaluated evaluate_avx(const Candidate& c, bool keep) const {
    return evaluate_body<Quad>(c, keep);
  }

  // Compiled twice (simd.hpp): with AVX where the processor has it, the same bits either way.
  template <class V>
  [[gnu::always_inline]] inline Evaluated evaluate_body(const Candidate& c, bool keep) const {
    // Without `keep` only the estimation samples are read: the rest are not simulated.
    const std::size_t n = keep ? op_.size() : n_est_;
    std::vector<double> z(n);
    BlendedHe he(c.fs(), c.fd(), static_cast<double>(c.motion), op_[0]);
    const double a = c.tau > 0.0 ? std::exp(-Ts_ / c.tau) : 0.0;
    double state = he.position();
    for (std::size_t k = 0; k < n; ++k) {
      const double x = k == 0 ? he.position() : he.step(op_[k]);
      state = a * state + (1.0 - a) * x;
      z[k] = (state - centre_) / half_;
    }
    const int m = degree_ + 1;
    Eigen::Matrix4d A = Eigen::Matrix4d::Zero();
    Eigen::Vector4d b = Eigen::Vector4d::Zero();
    const std::size_t used = off_limits_.size();
    // The sums of p_i p_j (j <= i) and p_i mv over the samples, each in sample order: all of
    // row i at once in one four-lane vector, the sums in registers. The entries above the
    // diagonal are summed too and dropped.
    std::array<V, 4> rows{};  // row i: A(i, 0 .. 3)
    V bq{};
    for (const std::size_t k : off_limits_) {
      V p;
      set4(p, 1.0, z[k], z[k] * z[k], z[k] * z[k] * z[k]);
      for (int i = 0; i < 4; ++i) rows[i] += p[i] * p;
      bq += p * mv_[k];
    }
    for (int i = 0; i < m; ++i) {
      b(i) = bq[i];
      for (int j = 0; j <= i; ++j) A(i, j) = A(j, i) = rows[i][j];
    }
    Evaluated e;
    if (used < static_cast<std::size_t>(2 * m)) return e;
    // Minimum-norm solution: a valve model that never moves makes the powers collinear.
    const Eigen::VectorXd coef =
        A.topLeftCorner(m, m).completeOrthogonalDecomposition().solve(b.head(m));
    double cf[4] = {};
    for (int i = 0; i < m; ++i) cf[i] = coef(i);
    auto map = [&](double s) {
      double v = 0.0;
      for (int i = m - 1; i >= 0; --i) v = v * s + cf[i];
      return v;
    };
    e.gain = (map(1.0) - map(-1.0)) / (2.0 * half_);
    auto at = [&](std::size_t k) { return std::clamp(map(z[k]), lim_.lo, lim_.hi); };
    double sse = 0.0;  // a local: e's member would be stored on every sample
    for (std::size_t k = 0; k < n_est_; ++k) {
      const double r = mv_[k] - at(k);
      sse += r * r;
    }
    e.sse = sse;
    if (keep) {
      e.mv_hat.resize(n);
      for (std::size_t k = 0; k < n; ++k) e.mv_hat[k] = at(k);
    }
    return e;
  }

  const std::vector<double>& op_;
  const std::vector<double>& mv_;
  double Ts_;
  std::size_t n_est_;
  Limits lim_;
  int degree_;
  double centre_ = 0.0, half_ = 1.0;
  std::vector<std::size_t> off_limits_;  // estimation samples off the travel limits
};

// A travel limit is a plateau at MV's extreme (at least 2 % of the samples within noise of its
// level, the median of the samples near the extreme) that OP pushes beyond: on the plateau OP,
// mapped to MV by a straight line, lies past the level by more than the noise band in the median.
// A sticky valve also rests at its extremes, but OP turns back there: the median lies inside.
Limits travel_limits(const std::vector<double>& op, const std::vector<double>& mv, double noise,
                     double width) {
  const double tol = std::max(3.0 * noise, 1e-6 * width);
  const auto [mn, mx] = std::minmax_element(mv.begin(), mv.end());
  auto level = [&](bool top) {
    std::vector<double> near;
    for (double m : mv)
      if (top ? m >= *mx - 2.0 * tol : m <= *mn + 2.0 * tol) near.push_back(m);
    return quantile(near, 0.5);
  };
  // MV = g OP + c over the whole record.
  const auto N = static_cast<double>(op.size());
  double so = 0, sm = 0, soo = 0, som = 0;
  for (std::size_t k = 0; k < op.size(); ++k) {
    so += op[k];
    sm += mv[k];
    soo += op[k] * op[k];
    som += op[k] * mv[k];
  }
  const double var = soo - so * so / N;
  const double g = var > 0 ? (som - so * sm / N) / var : 0.0, c = (sm - g * so) / N;
  auto pushed = [&](double lvl, bool top) {
    std::vector<double> beyond;
    for (std::size_t k = 0; k < mv.size(); ++k)
      if (top ? mv[k] >= lvl - tol : mv[k] <= lvl + tol)
        beyond.push_back(top ? g * op[k] + c - lvl : lvl - g * op[k] - c);
    return static_cast<double>(beyond.size()) >= 0.02 * N && quantile(beyond, 0.5) > 3.0 * tol;
  };
  Limits l;
  l.tol = tol;
  const double lo = level(false), hi = level(true);
  if (pushed(lo, false)) l.lo = lo;
  if (pushed(hi, true)) l.hi = hi;
  if (l.lo + tol >= l.hi - tol) return {};  // MV barely moves: no room for limits
  return l;
}

struct Polish {
  const Positioner* p;
  Candidate base;
  std::array<double, 3> lo{}, hi{};
  unsigned dims = 0;  // 1: tau only; 3: band, jump, tau
  Candidate at(const double* z) const {
    Candidate c = base;
    if (dims == 1) {
      c.tau = lo[2] + z[0] * (hi[2] - lo[2]);
    } else {
      c.band = lo[0] + z[0] * (hi[0] - lo[0]);
      c.jump = lo[1] + z[1] * (hi[1] - lo[1]);
      c.tau = lo[2] + z[2] * (hi[2] - lo[2]);
    }
    return c;
  }
};

double polish_cost(unsigned, const double* z, double*, void* data) {
  const auto* s = static_cast<const Polish*>(data);
  return s->p->evaluate(s->at(z)).sse;
}

// Nelder-Mead from `c` in the unit box of `s`; the best point seen.
Candidate polish(Polish s, const Candidate& c) {
  std::vector<double> z;
  auto unit = [](double v, double lo, double hi) {
    return hi > lo ? std::clamp((v - lo) / (hi - lo), 0.0, 1.0) : 0.0;
  };
  if (s.dims == 1) {
    z = {unit(c.tau, s.lo[2], s.hi[2])};
  } else {
    z = {unit(c.band, s.lo[0], s.hi[0]), unit(c.jump, s.lo[1], s.hi[1]),
         unit(c.tau, s.lo[2], s.hi[2])};
  }
  s.base = c;
  nlopt_opt o = nlopt_create(NLOPT_LN_NELDERMEAD, s.dims);
  if (!o) return c;
  const std::vector<double> lb(s.dims, 0.0), ub(s.dims, 1.0), step(s.dims, 0.05);
  nlopt_set_lower_bounds(o, lb.data());
  nlopt_set_upper_bounds(o, ub.data());
  nlopt_set_initial_step(o, step.data());
  nlopt_set_min_objective(o, polish_cost, &s);
  nlopt_set_maxeval(o, 150 * static_cast<int>(s.dims));
  nlopt_set_xtol_abs1(o, 1e-4);
  double f = 0.0;
  const double start = s.p->evaluate(c).sse;
  const nlopt_result r = nlopt_optimize(o, z.data(), &f);
  nlopt_destroy(o);
  // NLopt keeps the best point in z; a failure leaves the grid's point.
  return r > 0 && f <= start ? s.at(z.data()) : c;
}

// Scans inside the box [lo, hi] (band, jump, tau), finer than the grid: band and lag jointly
// (a lag shifts when a slip shows, so the band's valley moves with it), then the jump. Nelder-Mead
// alone stops on the terraces a slip one sample earlier or later makes.
// `du`: OP's typical change per sample, which sets the band's step (a slip moves by a sample when
// the band changes by about that much).
Candidate scan(const Positioner& pos, Candidate c, const std::array<double, 3>& lo,
               const std::array<double, 3>& hi, double du) {
  double best = pos.evaluate(c).sse;
  auto try_at = [&](Candidate t) {
    const double e = pos.evaluate(t).sse;
    if (e < best) best = e, c = t;
  };
  const int kBand = static_cast<int>(
      std::clamp(std::ceil((hi[0] - lo[0]) / std::max(0.3 * du, 1e-12)), 24.0, 240.0));
  constexpr int kTau = 8, kJump = 40;
  for (int pass = 0; pass < 3; ++pass) {
    const Candidate from = c;
    for (int i = 0; i <= kBand; ++i)
      for (int t = 0; t <= kTau; ++t) {
        Candidate x = from;
        x.band = lo[0] + (hi[0] - lo[0]) * i / kBand;
        x.tau = lo[2] + (hi[2] - lo[2]) * t / kTau;
        try_at(x);
      }
    const Candidate mid = c;
    for (int j = 0; j <= kJump; ++j) {
      Candidate x = mid;
      x.jump = static_cast<double>(j) / kJump;  // the whole range: a lag blurs the jump
      try_at(x);
    }
  }
  return c;
}

double geometric(double lo, double hi, int i, int n) {
  return lo * std::pow(hi / lo, static_cast<double>(i) / (n - 1));
}

}  // namespace

ValveTravel check_valve_travel(const std::vector<double>& op, const std::vector<double>& mv,
                               double Ts, const ValveTravelOptions& opt) {
  ValveTravel v;
  if (mv.empty()) {
    v.summary = "the valve position (MV) is not recorded";
    return v;
  }
  if (mv.size() != op.size()) {
    v.summary = strprintf("MV has %.0f samples and OP %.0f: they are not one record",
                          static_cast<double>(mv.size()), static_cast<double>(op.size()));
    return v;
  }
  for (std::size_t k = 0; k < mv.size(); ++k)
    if (!std::isfinite(mv[k]) || !std::isfinite(op[k])) {
      v.summary = strprintf(
          "MV or OP is not a number at sample %.0f: the valve-travel test needs an "
          "unbroken record",
          static_cast<double>(k));
      return v;
    }
  if (op.size() < opt.min_samples || !(Ts > 0.0)) {
    v.summary = strprintf("only %.0f samples of MV; at least %.0f are needed",
                          static_cast<double>(op.size()), static_cast<double>(opt.min_samples));
    return v;
  }
  const double width = std::max(opt.op_range.hi - opt.op_range.lo, 1e-12);
  const double to_pct = 100.0 / width;
  const auto [op_min, op_max] = std::minmax_element(op.begin(), op.end());
  const auto [mv_min, mv_max] = std::minmax_element(mv.begin(), mv.end());
  const double op_span = *op_max - *op_min, mv_span = *mv_max - *mv_min;
  const double op_sweep = quantile(op, 0.95) - quantile(op, 0.05);  // OP's 5..95 % spread
  v.mv_noise = step_noise_sigma(mv);
  v.tested = true;

  // A valve that stays put while OP sweeps far beyond MV's noise: stuck, or a dead transmitter.
  if (mv_span <= std::max(6.0 * v.mv_noise, 0.002 * width) &&
      op_sweep >= std::max(opt.stuck_op_noise * v.mv_noise, 0.02 * width)) {
    v.decided = true;
    v.verdict = "stiction";
    v.summary = strprintf(
        "the valve position stays within %.2f %% of travel while OP sweeps %.1f %%: "
        "the valve is stuck (or its position transmitter is dead; check it before "
        "the valve)",
        mv_span * to_pct, op_sweep * to_pct);
    return v;
  }
  if (op_span <= 0.0) {
    v.tested = false;
    v.summary = "OP does not move: the valve-travel test needs OP to move the valve";
    return v;
  }

  const std::size_t n = op.size();
  const std::size_t n_est = std::min(
      n, std::max<std::size_t>(opt.min_samples / 2,
                               static_cast<std::size_t>(std::floor((1.0 - opt.validation_fraction) *
                                                                   static_cast<double>(n)))));
  const Positioner pos(op, mv, Ts, n_est, travel_limits(op, mv, v.mv_noise, width), opt.map_degree);
  const double tau_hi = std::max(opt.max_lag_s, Ts);
  const double tau_lo = std::min(0.5 * Ts, tau_hi);
  auto fitness = [&](const Evaluated& e, std::size_t from, std::size_t to) {
    return from < to ? fitness_percent(mv, e.mv_hat, from, to) : ValveTravel::kNaN;
  };

  // Follow: lag only.
  Candidate follow;
  {
    double best = HUGE_VAL;
    constexpr int kTau = 16;
    for (int i = -1; i < kTau; ++i) {
      const Candidate c{0.0, 0.0, i < 0 ? 0.0 : geometric(tau_lo, tau_hi, i, kTau), 0};
      const double s = pos.evaluate(c).sse;
      if (s < best) best = s, follow = c;
    }
    Polish p{&pos, follow, {0, 0, 0}, {0, 0, tau_hi}, 1};
    follow = polish(p, follow);
  }
  // Friction: He's band and jump, the lag, the valve's state at the start. A grid (bands
  // geometric and fine, from a resolution step to the OP span), then Nelder-Mead inside the grid
  // cell of each of the best points: the cost has valleys a slip-sample wide in the band.
  Candidate friction;
  {
    const double band_hi = std::max(op_span, 1e-9);
    std::vector<double> steps;
    for (std::size_t k = 1; k < n; ++k)
      if (op[k] != op[k - 1]) steps.push_back(std::abs(op[k] - op[k - 1]));
    const double du = steps.empty() ? op_span : quantile(steps, 0.5);
    const double band_lo = std::min(std::max(1e-3 * width, v.mv_noise), 0.5 * band_hi);
    constexpr double kBandStep = 1.03;
    const int n_band =
        1 + static_cast<int>(std::ceil(std::log(band_hi / band_lo) / std::log(kBandStep)));
    constexpr int kJump = 11, kTau = 7;
    const double q_band = std::pow(band_hi / band_lo, 1.0 / std::max(n_band - 1, 1));
    const double q_tau = std::pow(tau_hi / tau_lo, 1.0 / (kTau - 1));
    struct Scored {
      double sse;
      Candidate c;
    };
    std::vector<Scored> grid;
    // From rest; the start state (which only shapes the record's first sweep) is chosen per start.
    grid.reserve(static_cast<std::size_t>(n_band * kJump * (kTau + 1)));
    for (int i = 0; i < n_band; ++i)
      for (int j = 0; j < kJump; ++j)
        for (int t = -1; t < kTau; ++t)
          grid.push_back({HUGE_VAL,
                          {geometric(band_lo, band_hi, i, n_band), j / (kJump - 1.0),
                           t < 0 ? 0.0 : geometric(tau_lo, tau_hi, t, kTau), 0}});
    // The grid and the starts on the cores: each evaluation is independent, and the results are
    // taken in grid and start order as before.
    parallel_for(grid.size(), worker_count(opt.threads, grid.size()),
                 [&](unsigned, std::size_t k) { grid[k].sse = pos.evaluate(grid[k].c).sse; });
    constexpr std::size_t kStarts = 10;
    std::partial_sort(grid.begin(), grid.begin() + kStarts, grid.end(),
                      [](const Scored& a, const Scored& b) { return a.sse < b.sse; });
    std::vector<Scored> ends(kStarts);
    parallel_for(kStarts, worker_count(opt.threads, kStarts), [&](unsigned, std::size_t s) {
      Candidate g = grid[s].c;
      double start = grid[s].sse;
      for (int m : {-1, 1}) {
        Candidate t = g;
        t.motion = m;
        const double e = pos.evaluate(t).sse;
        if (e < start) start = e, g = t;
      }
      Polish p{&pos,
               g,
               {g.band / q_band, 0.0, g.tau > tau_lo * 1.0001 ? g.tau / q_tau : 0.0},
               {std::min(g.band * q_band, band_hi), 1.0,
                g.tau > 0 ? std::min(g.tau * q_tau, tau_hi) : tau_lo * q_tau},
               3};
      const Candidate c = polish(p, scan(pos, g, p.lo, p.hi, du));
      ends[s] = {pos.evaluate(c).sse, c};
    });
    double best = HUGE_VAL;
    for (const Scored& e : ends)
      if (e.sse < best) best = e.sse, friction = e.c;
  }
  const Evaluated ef = pos.evaluate(follow, true), er = pos.evaluate(friction, true);
  v.follow_fitness_percent = fitness(ef, 0, n_est);
  v.follow_validation_fitness_percent = fitness(ef, n_est, n);
  v.friction_fitness_percent = fitness(er, 0, n_est);
  v.friction_validation_fitness_percent = fitness(er, n_est, n);
  const double fs = friction.fs(), fd = friction.fd();
  v.fs_percent = fs * to_pct;
  v.fd_percent = fd * to_pct;
  v.jump_percent = (fs - fd) * to_pct;

  // The share of the error the follow model leaves that friction removes, on each part: points
  // of fitness would depend on how far OP travelled, the share does not.
  auto rms = [&](const Evaluated& e, std::size_t from, std::size_t to) {
    double q = 0.0;
    for (std::size_t k = from; k < to; ++k) q += (mv[k] - e.mv_hat[k]) * (mv[k] - e.mv_hat[k]);
    return std::sqrt(q / static_cast<double>(std::max<std::size_t>(to - from, 1)));
  };
  // An MV that equals OP to rounding leaves friction nothing to explain: none of it, not a ratio
  // of rounding errors (measured: -6e13 %).
  const double nothing_left = 1e-6 * 100.0 / to_pct;
  auto share = [&](std::size_t from, std::size_t to) {
    if (from >= to) return ValveTravel::kNaN;
    const double f = rms(ef, from, to);
    return f > nothing_left ? 1.0 - rms(er, from, to) / f : 0.0;
  };
  v.error_share = share(0, n_est);
  v.validation_error_share = share(n_est, n);
  const double share_est = v.error_share;
  const double share_val =
      std::isnan(v.validation_error_share) ? share_est : v.validation_error_share;
  const double band = fs + fd;  // OP travel after a reversal before the valve moves
  const bool above_resolution = band * to_pct >= opt.min_band_percent;
  v.lag_s = follow.tau;  // the follow model's, unless friction is found
  v.gain = ef.gain;
  const bool explains_est = share_est >= opt.min_error_share;
  const bool explains_val = share_val >= opt.min_error_share;
  const bool explains = explains_est && explains_val;
  // Friction that explains one part and not the other is no evidence either way (a held-out part
  // with few reversals, or a fit to noise): the closed-loop models decide. "Follows OP" needs
  // friction to fail on both parts, or a band under the resolution.
  // A share below zero is a friction that tracks the valve worse than following OP does: none,
  // not a ratio of thousands of per cent.
  const auto none = [](double s) { return 100 * s < 0.5; };
  const auto share_text = [&none](double s) {
    return none(s) ? std::string("none") : strprintf("%.0f %%", 100 * s);
  };
  if (explains_est != explains_val && above_resolution) {
    v.summary =
        strprintf(
            "the valve-travel test is inconclusive: friction (He's fs %.2f, fd %.2f) explains ",
            v.fs_percent, v.fd_percent) +
        share_text(share_est) + " / " + share_text(share_val) +
        strprintf(
            " of the error a valve that follows OP leaves (estimation / held out), above "
            "%.0f %% on one part only; the process models decide",
            100 * opt.min_error_share);
    return v;
  }
  v.decided = true;
  // Explaining a fifth of the error on both parts already sets the friction apart from MV's noise;
  // a band under the positioner's resolution is no maintenance case.
  if (explains && above_resolution) {
    const bool backlash = fs - fd < opt.deadband_jump_fraction * band;
    v.verdict = backlash ? "deadband" : "stiction";
    v.lag_s = friction.tau;
    v.gain = er.gain;
    v.summary =
        strprintf(
            "the measured valve position has friction: after a reversal OP travels %.2f %% of "
            "travel before the valve moves, then it jumps %.2f %% (He's fs %.2f, fd %.2f); it "
            "explains ",
            band * to_pct, v.jump_percent, v.fs_percent, v.fd_percent) +
        strprintf(
            "%.0f / %.0f %% of the error a valve that follows OP leaves (estimation / held out)",
            100 * share_est, 100 * share_val);
    if (backlash) v.summary += " (no jump: backlash)";
    return v;
  }
  v.verdict = "no-valve-problem";
  std::string why;
  if (!explains)
    why = none(share_est) && none(share_val)
              ? std::string("friction explains none of the error left")
              : "friction explains only " + share_text(share_est) + " / " + share_text(share_val) +
                    " of the error left (estimation / held out)";
  else
    why = strprintf("its band, %.2f %% of travel, is under %.2f %%", band * to_pct,
                    opt.min_band_percent);
  v.summary = strprintf(
                  "the measured valve position follows OP (%.1f / %.1f %% fitness, lag %.1f s, "
                  "gain %.3f): ",
                  v.follow_fitness_percent, v.follow_validation_fitness_percent, v.lag_s, v.gain) +
              why;
  return v;
}

}  // namespace valvediag
