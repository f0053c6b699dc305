#include "valvediag/core/stiction_quantification.hpp"

#include <nlopt.h>

#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <map>
#include <mutex>
#include <stdexcept>
#include <unordered_map>
#include <utility>

#include "valvediag/core/autocorrelation.hpp"
#include "valvediag/core/parallel_for.hpp"
#include "valvediag/core/profile_walk.hpp"

namespace valvediag {
namespace {

const double kNaN = std::numeric_limits<double>::quiet_NaN();

// He's model, the flowchart of HeStiction in src/sim (the core does not depend on the
// simulator), evaluated for an input that moves linearly between samples: every slip the
// flowchart would make at a fine enough sampling is made, at the exact input where |u_cum|
// passes fs. Sampled as in the flowchart, a ramp of r per sample slips r / 2 late on average, so
// the staircase steps would be fs - fd plus that, and the fit would report a jump too small by
// it: the probe's sampling is ours, not the valve's.
struct He {
  double fs, fd;
  double u_prev = 0.0, x = 0.0, u_r = 0.0;
  // At u0, having last slipped up at u0 - phase (0 <= phase < fs - fd): the phase of He's
  // staircase. It is set by the valve's history, which the probe does not know: it is fitted.
  void reset(double u0, double phase) {
    u_prev = u0;
    u_r = fd + phase;
    x = u0 - u_r;
  }
  double step(double u) {
    const double du = u - u_prev;
    u_prev = u;
    const double d = du > 0 ? 1.0 : -1.0;
    const double pushed = d * u_r + std::abs(du);  // force along the move
    if (!(pushed > fs)) {
      u_r += du;  // stick
      return x;
    }
    // First slip after fs - d u_r of travel, then one every fs - fd while the input moves on.
    const double after = pushed - fs;
    const double jump = fs - fd;
    const double rest = jump > 0 ? after - jump * std::floor(after / jump) : 0.0;
    u_r = d * (fd + rest);
    x = u - u_r;
    return x;
  }
};

// The probe: an input, the identified valve's response to it, and which samples count: all
// `scored` samples in the overall fit; in a region's fit the samples within a window of OP
// travel after a reversal (turning point) that lies in the region.
struct Probe {
  std::vector<double> u, x;
  std::vector<double> uq;  // u on the grid: the level centre the Preisach model sees
  std::vector<char> scored;
  std::vector<int> reversal;       // index into reversal_u of the last turning point, -1: none
  std::vector<double> since;       // OP travel since that turning point
  std::vector<double> reversal_u;  // OP at each turning point
  double longest_sweep = 0.0;      // largest OP travel between turning points (or to the ends)
};

// Synthetic probe over levels lo..hi (no data): the major loop, then first-order reversal curves
// (FORCs) at every level, both ways, one level per sample.
Probe forc_probe(const HammersteinModel& m, int lo, int hi) {
  const PreisachGrid& g = m.grid;
  auto at = [&](int k) { return g.umin + k * g.delta(); };
  Probe p;
  PreisachModel valve(g, m.mu, 0.0);
  valve.reset({0, hi});
  int k = hi;
  int current = -1;
  bool scored = false;
  auto go_to = [&](int target) {
    const int dir = target > k ? 1 : -1;
    while (k != target) {
      k += dir;
      p.u.push_back(at(k));
      p.x.push_back(valve.step(at(k)));
      p.reversal.push_back(current);
      p.since.push_back(
          current >= 0 ? std::abs(at(k) - p.reversal_u[static_cast<std::size_t>(current)]) : 0.0);
      p.scored.push_back(scored);
    }
  };
  auto reverse_here = [&] {
    p.reversal_u.push_back(at(k));
    current = static_cast<int>(p.reversal_u.size()) - 1;
  };
  go_to(lo);  // sets the memory, not scored
  scored = true;
  go_to(hi);
  go_to(lo);
  for (int v = lo + 1; v <= hi; ++v) {
    current = -1;
    go_to(v);
    reverse_here();
    go_to(lo);
  }
  current = -1;
  go_to(hi);
  for (int v = hi - 1; v >= lo; --v) {
    current = -1;
    go_to(v);
    reverse_here();
    go_to(hi);
  }
  p.longest_sweep = (hi - lo) * g.delta();
  return p;
}

// The data as the probe: the identified model is only known on inputs like the data (a limit
// cycle identifies only 2L - 1 weight combinations, Proposition 3), so the valve is probed with
// the data's own OP. Turning points with a hysteresis of half a grid step (OP noise is not a
// reversal). The first samples, until the OP has travelled the visited range, are not scored:
// He's initial state is unknown until the valve has slipped once.
Probe data_probe(const HammersteinModel& m, const std::vector<double>& op, double width) {
  Probe p;
  for (double u : op)
    if (std::isfinite(u)) p.u.push_back(u);
  p.x = simulate_valve(m, p.u);
  const std::size_t N = p.u.size();
  const double hyst = m.grid.delta() / 2;
  std::vector<std::size_t> turns;  // sample indices of turning points
  std::size_t ext = 0;
  int dir = 0;
  for (std::size_t t = 1; t < N; ++t) {
    const double d = p.u[t] - p.u[ext];
    if (dir >= 0 && p.u[t] > p.u[ext]) {
      ext = t;
      dir = 1;
    } else if (dir <= 0 && p.u[t] < p.u[ext]) {
      ext = t;
      dir = -1;
    } else if (dir != 0 && -dir * d > hyst) {
      turns.push_back(ext);
      ext = t;
      dir = -dir;
    }
  }
  p.reversal.assign(N, -1);
  p.since.assign(N, 0.0);
  std::size_t next = 0;
  int current = -1;
  for (std::size_t t = 0; t < N; ++t) {
    if (next < turns.size() && turns[next] == t) {
      p.reversal_u.push_back(p.u[t]);
      current = static_cast<int>(next++);
    }
    p.reversal[t] = current;
    if (current >= 0)
      p.since[t] = std::abs(p.u[t] - p.reversal_u[static_cast<std::size_t>(current)]);
  }
  // Longest sweep: between consecutive turning points, and from the start / to the end.
  std::vector<std::size_t> ends{0};
  ends.insert(ends.end(), turns.begin(), turns.end());
  if (N > 0) ends.push_back(N - 1);
  for (std::size_t i = 1; i < ends.size(); ++i)
    p.longest_sweep = std::max(p.longest_sweep, std::abs(p.u[ends[i]] - p.u[ends[i - 1]]));
  p.scored.assign(N, 0);
  double travel = 0.0;
  for (std::size_t t = 1; t < N; ++t) {
    travel += std::abs(p.u[t] - p.u[t - 1]);
    p.scored[t] = travel >= width;
  }
  return p;
}

// Sums for a least-squares fit of x ~ s He + c over one set of samples.
struct Sums {
  double n = 0, sp = 0, spp = 0, sh = 0, shh = 0, sph = 0;
  void add(double P, double H) {
    n += 1;
    sp += P;
    spp += P * P;
    sh += H;
    shh += H * H;
    sph += P * H;
  }
  // A run of samples at one H: r holds their n, sums of P and of P^2.
  void add_run(const Sums& r, double H) {
    n += r.n;
    sp += r.sp;
    spp += r.spp;
    sh += r.n * H;
    shh += r.n * H * H;
    sph += r.sp * H;
  }
  double var_p() const { return n > 0 ? spp - sp * sp / n : 0.0; }
  // Residual sum of squares with s and c free (s > 0), and that s.
  double cost_free(double* s_out) const {
    if (n < 2) {
      *s_out = 0.0;
      return 0.0;
    }
    const double vh = shh - sh * sh / n, cph = sph - sp * sh / n;
    if (!(vh > 1e-12 * (1.0 + shh)) || cph <= 0) {
      *s_out = 0.0;
      return var_p();
    }
    *s_out = cph / vh;
    return std::max(0.0, var_p() - cph * cph / vh);
  }
  // With s fixed, c free.
  double cost_fixed(double s) const {
    if (n < 2) return 0.0;
    const double vh = shh - sh * sh / n, cph = sph - sp * sh / n;
    return std::max(0.0, var_p() - 2 * s * cph + s * s * vh);
  }
};

// The probe's samples merged into runs of one grid level (and one set they count in): He's
// valve does not move while its input stays put, so a run's samples enter the sums together,
// and a pass costs the level changes, not the samples.
struct Runs {
  std::vector<double> uq;
  std::vector<char> scored;
  std::vector<int> region;
  std::vector<Sums> x;  // the run's Preisach positions less their mean (H left 0)
  // Subtracted from He's position: the sums are of deviations, not of ~50 % levels, so that
  // costs that differ far below the variance are not lost to cancellation.
  double centre = 0.0;
};

Runs runs_of(const Probe& p, const std::vector<int>& region_of_sample, bool merge) {
  Runs r;
  double x_mean = 0.0;
  for (std::size_t t = 0; t < p.u.size(); ++t) {
    x_mean += p.x[t] / static_cast<double>(p.u.size());
    r.centre += p.uq[t] / static_cast<double>(p.u.size());
  }
  for (std::size_t t = 0; t < p.u.size(); ++t) {
    const int reg = region_of_sample.empty() ? -1 : region_of_sample[t];
    if (r.uq.empty() || !merge || p.uq[t] != r.uq.back() || p.scored[t] != r.scored.back() ||
        reg != r.region.back()) {
      r.uq.push_back(p.uq[t]);
      r.scored.push_back(p.scored[t]);
      r.region.push_back(reg);
      r.x.emplace_back();
    }
    r.x.back().add(p.x[t] - x_mean, 0.0);
  }
  return r;
}

// One pass of He (fs, fd) over the probe: sums over the overall set and per region.
void accumulate(const Runs& runs, double fs, double fd, double phase_fraction, int regions,
                Sums& overall, std::vector<Sums>& per_region) {
  He he{fs, fd};
  he.reset(runs.uq.front(), phase_fraction * (fs - fd));
  overall = Sums{};
  per_region.assign(static_cast<std::size_t>(regions), Sums{});
  for (std::size_t i = 0; i < runs.uq.size(); ++i) {
    const double H = he.step(runs.uq[i]) - runs.centre;
    if (runs.scored[i]) overall.add_run(runs.x[i], H);
    if (runs.region[i] >= 0)
      per_region[static_cast<std::size_t>(runs.region[i])].add_run(runs.x[i], H);
  }
}

double fit_percent(double cost, double var) {
  return var > 0 ? 100.0 * (1.0 - std::sqrt(cost / var)) : kNaN;
}

StictionFigures figures(double fs, double fd, double cost, double var) {
  return {fs, fd, fs + fd, fs - fd, fit_percent(cost, var)};
}

StictionFigures unmeasured() {
  return {kNaN, kNaN, kNaN, kNaN, kNaN};
}

std::string pct(double v, int prec = 1) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.*f", prec, v);
  return buf;
}

// "; the data fit fs a-b %, fd c-d % within 95 % (profile likelihood)", or "" without an interval.
std::string interval_clause(const StictionInterval& iv) {
  if (!iv.valid) return "";
  const std::string fs = iv.fs_open_above ? pct(iv.fs_lo) + " % or more (up to the OP span " +
                                                pct(iv.fs_hi) + " %: the data do not bound it)"
                                          : pct(iv.fs_lo) + "-" + pct(iv.fs_hi) + " %";
  return "; the data fit fs " + fs + ", fd " + pct(iv.fd_lo) + "-" + pct(iv.fd_hi) + " % within " +
         pct(100 * iv.level(), 0) + " % (profile likelihood" +
         (iv.capped ? ", at least that wide" : "") + ")";
}

// The summary of a valid quantification: "stiction: fs .. % of travel (...) over OP lo-hi %", or
// that no stiction is resolved. `span`: "" when OP is in %, else " of the OP span lo:hi"
// (in_percent_of_span), said after the figures' range in place of " %".
std::string stiction_sentence(const StictionQuantification& q, const std::string& span = "") {
  if (!q.stiction && q.refined)
    return std::string("no stiction resolved: ") +
           (q.interval.valid && q.interval.fs_lo > 0
                ? "the band He's fit finds (" + pct(q.overall.band_percent, 2) +
                      " %) is below the grid step " + pct(q.resolution_percent) + " %" + span
                : std::string("a valve without stiction fits the data as well")) +
           interval_clause(q.interval);
  if (!q.stiction)
    return "no stiction resolved: the band is below the grid step " + pct(q.resolution_percent) +
           " %" + span;
  return "stiction: fs " + pct(q.overall.fs_percent) + " %, fd " + pct(q.overall.fd_percent) +
         " % of travel (band " + pct(q.overall.band_percent) + " %, slip jump " +
         pct(q.overall.jump_percent) + " %) over OP " + pct(q.op_lo) + "-" + pct(q.op_hi) +
         (span.empty() ? " %" : span) +
         (q.jump_identified || q.refined
              ? ""
              : "; the data's sweeps are too short to split the band into fs and fd") +
         interval_clause(q.interval);
}

// He's bands (fs, fd) of one OP region.
struct Band {
  double fs, fd;
};

// He's valve inside the Hammerstein structure, fitted to the data (op, pv): for a candidate
// (fs, fd) the valve position x is simulated, and the linear part's simulated output
//   y(t) = B(q) / A(q) x(t) + c + free response of 1/A (unknown initial state)
// is linear in (b, c, initial state) for given poles A and delay nk: solved by least squares. The
// cost is the simulated-output error (eq 20), not the equation error, which measurement noise
// biases (and which a slow pole makes blind to the valve). Scored from `t0` on: after the OP has
// travelled its visited range, so He's unknown initial state (his memory before the first slip)
// is gone, as in the probe.
class HeDataFit {
 public:
  HeDataFit(const HammersteinModel& m, const std::vector<double>& op, const std::vector<double>& y,
            double width, int max_delay, bool remember, bool plain_sums)
      : u_(op), y_(y), ones_(op.size(), 1.0), remember_(remember), plain_sums_(plain_sums) {
    identity_ = m.block == LinearBlock::Identity;
    if (!identity_) {
      nb_ = std::max<int>(1, static_cast<int>(m.b.size()));
      nk_ = m.structure.nk;
    }
    const std::size_t N = u_.size();
    double travel = 0.0;
    t0_ = N;
    for (std::size_t t = 1; t < N; ++t) {
      travel += std::abs(u_[t] - u_[t - 1]);
      if (travel >= width) {
        t0_ = t;
        break;
      }
    }
    t0_ = std::max(t0_, static_cast<std::size_t>(std::max(nk_, max_delay) + nb_ + 4));
    double sy = 0, syy = 0, n = 0;
    for (std::size_t t = t0_; t < N; ++t) {
      sy += y_[t];
      syy += y_[t] * y_[t];
      n += 1;
    }
    var_y_ = n > 0 ? syy - sy * sy / n : 0.0;
    set_poles(identity_ ? std::vector<double>{} : m.a);
    // For ls_poles: sums of products of [y(t), y(t-1) .. y(t-na), 1] over the scored rows; they
    // do not depend on the valve.
    const int na = static_cast<int>(a_.size());
    if (na > 0 && t0_ < N && static_cast<std::size_t>(na) <= t0_) {
      Columns c;
      for (int i = 0; i <= na; ++i) c.add(y_, static_cast<std::size_t>(i));
      c.add(ones_, 0);
      y_lags_.resize(c.n, c.n);
      scored_dots(c, c, y_lags_);
    }
  }
  bool usable() const {
    return t0_ + 20 < u_.size() && var_y_ > 0 &&
           nb_ + 1 + static_cast<int>(a_.size()) <= static_cast<int>(kMaxColumns) - 1;
  }
  bool identity() const { return identity_; }
  double var_y() const { return var_y_; }
  // Equation-error least squares of A y = B x + c for the valve position x, with the current
  // delay and orders: the poles, or empty when A comes out unstable. y's sums come from the
  // constructor; x's enter by products.
  std::vector<double> ls_poles(const std::vector<double>& x) const {
    const int na = static_cast<int>(a_.size());
    if (na == 0 || identity_ || y_lags_.rows() != na + 2) return {};
    Columns taps, all;
    for (int i = 0; i <= na; ++i) all.add(y_, static_cast<std::size_t>(i));
    for (int j = 1; j <= nb_; ++j) {
      taps.add(x, static_cast<std::size_t>(nk_ + j));
      all.add(x, static_cast<std::size_t>(nk_ + j));
    }
    all.add(ones_, 0);
    products_.resize(taps.n, all.n);
    scored_dots(taps, all, products_);
    // The products of all columns: y's and the constant's from the constructor, the taps' here.
    const int n = all.n, one = n - 1;
    Eigen::MatrixXd P(n, n);
    for (int i = 0; i <= na; ++i) {
      for (int k = 0; k <= na; ++k) P(i, k) = y_lags_(i, k);
      P(i, one) = P(one, i) = y_lags_(i, na + 1);
    }
    P(one, one) = y_lags_(na + 1, na + 1);
    for (int j = 0; j < nb_; ++j)
      for (int k = 0; k < n; ++k) P(na + 1 + j, k) = P(k, na + 1 + j) = products_(j, k);
    return arx_poles(P, na);
  }
  // Steiglitz-McBride: the output error's poles for the valve position x, approached by the
  // equation error of y and x filtered by 1/A of the previous pass (so its noise is nearly white
  // and does not bias A), from the current poles, `passes` times. Empty when A comes out unstable.
  std::vector<double> sm_poles(const std::vector<double>& x, int passes) const {
    const int na = static_cast<int>(a_.size());
    if (na == 0 || identity_) return {};
    std::vector<double> a = a_;
    auto mean = [](const std::vector<double>& v) {
      return Eigen::Map<const Eigen::VectorXd>(v.data(), static_cast<Eigen::Index>(v.size()))
          .mean();
    };
    const double my = mean(y_), mx = mean(x);
    for (int pass = 0; pass < passes; ++pass) {
      // The first pass starts from the same poles for every x (the Preisach valve's): y through
      // them is kept.
      const bool same_y = pass == 0 && sm_y0_valid_ && sm_y0_poles_ == a;
      if (!same_y) through(y_, my, a, sm_y_);
      if (pass == 0 && !same_y) {
        sm_y0_ = sm_y_;
        sm_y0_poles_ = a;
        sm_y0_valid_ = true;
      }
      const std::vector<double>& fy = pass == 0 ? sm_y0_ : sm_y_;
      through(x, mx, a, sm_x_);
      Columns c;  // as arx_poles takes them
      for (int i = 0; i <= na; ++i) c.add(fy, static_cast<std::size_t>(i));
      for (int j = 1; j <= nb_; ++j) c.add(sm_x_, static_cast<std::size_t>(nk_ + j));
      c.add(ones_, 0);
      scored_dots(c, c, products_);
      a = arx_poles(products_, na);
      if (a.empty()) return {};
    }
    return a;
  }
  const std::vector<double>& poles() const { return a_; }
  int delay() const { return nk_; }
  // At most what the scored rows leave room for (t0_ - dj >= 0 for every tap of B).
  void set_delay(int nk) {
    nk_ = std::clamp(nk, 0, std::max(0, static_cast<int>(t0_) - nb_ - 1));
    costs_.clear();
  }
  // A's coefficients. The fixed regressors that go with them are made by the next cost().
  void set_poles(const std::vector<double>& a) {
    a_ = a;
    costs_.clear();
    fixed_ready_ = false;
  }

  // Regions for several bands: R equal parts of [lo, lo + width].
  void set_regions(double lo, double width) {
    region_lo_ = lo;
    region_width_ = width > 0 ? width : 1.0;
  }
  std::vector<double> valve(const std::vector<Band>& bands) const {
    std::vector<double> x;
    valve_into(bands, x);
    return x;
  }
  std::vector<double> valve(double fs, double fd) const { return valve({{fs, fd}}); }
  // Returns the position's fingerprint (see valve_into).
  std::uint64_t valve(double fs, double fd, std::vector<double>& x) const {
    return valve_into({{fs, fd}}, x);
  }
  double cost(double fs, double fd) const { return cost(std::vector<Band>{{fs, fd}}); }
  // Remembered per valve position while the linear part stays: neighbouring bands often slip on
  // the same samples.
  double cost(const std::vector<Band>& bands) const {
    const std::uint64_t key = valve_into(bands, x_);
    if (!remember_) return cost(x_);
    const auto hit = costs_.find(key);
    if (hit != costs_.end()) return hit->second;
    return costs_[key] = cost(x_);
  }
  // Residual sum of squares of the simulated output for the valve position x.
  double cost(const std::vector<double>& x) const { return solve(x, nullptr); }
  // The residual itself, over the scored rows.
  std::vector<double> residuals(const std::vector<double>& x) const {
    std::vector<double> r;
    solve(x, &r);
    return r;
  }

 private:
  double solve(const std::vector<double>& x, std::vector<double>* residual) const {
    filter(x);
    // Regressors: B's taps (x through 1/A, delayed), then the fixed ones, then y.
    Columns taps;
    for (int j = 0; j < nb_; ++j)
      taps.add(f_, identity_ ? 0 : static_cast<std::size_t>(nk_ + j + 1));
    Columns all = taps;
    const Columns fixed = fixed_columns();
    for (int k = 0; k < fixed.n; ++k)
      all.c[static_cast<std::size_t>(all.n++)] = fixed.c[static_cast<std::size_t>(k)];
    products_.resize(taps.n, all.n);
    if (plain_sums_) {
      scored_dots(taps, all, products_);
    } else {
      tap_gram(taps, products_);
      scored_dots(taps, fixed, fixed_products_);
      products_.rightCols(fixed.n) = fixed_products_;
    }
    const Eigen::Index nf = fixed.n - 1;
    const int p = nb_ + static_cast<int>(nf);
    Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, kMaxColumns, kMaxColumns> G(p, p);
    Eigen::Matrix<double, Eigen::Dynamic, 1, 0, kMaxColumns, 1> r(p);
    G.topRows(nb_) = products_.leftCols(p);
    G.bottomLeftCorner(nf, nb_) = products_.middleCols(nb_, nf).transpose();
    G.bottomRightCorner(nf, nf) = fixed_gram_.topLeftCorner(nf, nf);
    r.head(nb_) = products_.col(p);
    r.tail(nf) = fixed_gram_.col(nf).head(nf);
    const double yy = fixed_gram_(nf, nf);
    // Scaled, with a tiny ridge: the constant and a slow free response are nearly collinear.
    const Eigen::Matrix<double, Eigen::Dynamic, 1, 0, kMaxColumns, 1> sc =
        G.diagonal().cwiseMax(1e-300).cwiseSqrt().cwiseInverse();
    Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, kMaxColumns, kMaxColumns> Gs =
        sc.asDiagonal() * G * sc.asDiagonal();
    Gs.diagonal().array() += 1e-10;
    const Eigen::Matrix<double, Eigen::Dynamic, 1, 0, kMaxColumns, 1> rs = sc.asDiagonal() * r;
    const Eigen::Matrix<double, Eigen::Dynamic, 1, 0, kMaxColumns, 1> th = Gs.ldlt().solve(rs);
    if (residual) {
      const Eigen::Matrix<double, Eigen::Dynamic, 1, 0, kMaxColumns, 1> theta = sc.cwiseProduct(th);
      residual->resize(u_.size() - t0_);
      for (std::size_t t = t0_; t < u_.size(); ++t) {
        double e = y_[t];
        for (int k = 0; k < p; ++k) {
          const Column& c = all.c[static_cast<std::size_t>(k)];
          e -= theta(k) * c.v[t - c.lag];
        }
        (*residual)[t - t0_] = e;
      }
    }
    return std::max(0.0, yy - th.dot(rs));
  }
  // `in` less m through 1/A (coefficients a) from rest into out. The common orders keep the past
  // outputs in registers (see filter_n); the same operations in the same order as the plain loop.
  static void through(const std::vector<double>& in, double m, const std::vector<double>& a,
                      std::vector<double>& out) {
    switch (a.size()) {
      case 1:
        return through_n<1>(in, m, a, out);
      case 2:
        return through_n<2>(in, m, a, out);
      case 3:
        return through_n<3>(in, m, a, out);
      default:
        return through_n<-1>(in, m, a, out);
    }
  }
  template <int NA>
  static void through_n(const std::vector<double>& in, double m, const std::vector<double>& a,
                        std::vector<double>& out) {
    const std::size_t N = in.size();
    out.resize(N);
    if constexpr (NA < 0) {
      for (std::size_t t = 0; t < N; ++t) {
        double v = in[t] - m;
        for (std::size_t i = 1; i <= a.size() && i <= t; ++i) v -= a[i - 1] * out[t - i];
        out[t] = v;
      }
    } else {
      constexpr std::size_t na = NA;
      std::array<double, na> c{}, p{};  // p[i - 1] = out[t - i]
      for (std::size_t i = 0; i < na; ++i) c[i] = a[i];
      for (std::size_t t = 0; t < N; ++t) {
        double v = in[t] - m;
        const std::size_t k = t < na ? t : na;
        for (std::size_t i = 0; i < k; ++i) v -= c[i] * p[i];
        for (std::size_t i = na - 1; i > 0; --i) p[i] = p[i - 1];
        p[0] = v;
        out[t] = v;
      }
    }
  }
  // Equation-error least squares of y(t) on [-y(t-1) .. -y(t-na), x's taps, 1] from the products
  // P of the columns [y(t), y(t-1) .. y(t-na), x's taps, 1]: A's coefficients, or empty when A
  // comes out unstable.
  static std::vector<double> arx_poles(const Eigen::MatrixXd& P, int na) {
    const Eigen::Index p = P.rows() - 1;
    auto sign = [na](Eigen::Index k) { return k >= 1 && k <= na ? -1.0 : 1.0; };
    Eigen::MatrixXd M(p, p);
    Eigen::VectorXd r(p);
    for (Eigen::Index i = 1; i <= p; ++i) {
      for (Eigen::Index k = 1; k <= p; ++k) M(i - 1, k - 1) = sign(i) * sign(k) * P(i, k);
      r(i - 1) = sign(i) * P(0, i);
    }
    M.diagonal().array() += 1e-10 * M.diagonal().cwiseAbs().maxCoeff() + 1e-300;
    const Eigen::VectorXd th = M.ldlt().solve(r);
    std::vector<double> a(th.data(), th.data() + na);
    if (!th.allFinite() || !is_stable(a, 1e-6)) return {};
    return a;
  }
  static constexpr int kMaxColumns = 10;
  // Regressor columns as lagged series: column k holds v[t - lag] in row t.
  struct Column {
    const double* v;
    std::size_t lag;
  };
  struct Columns {
    std::array<Column, kMaxColumns> c{};
    int n = 0;
    void add(const std::vector<double>& v, std::size_t lag) {
      c[static_cast<std::size_t>(n++)] = {v.data(), lag};
    }
  };
  // The constant and the free responses through 1/A, then y.
  Columns fixed_columns() const {
    Columns c;
    c.add(step_, 0);
    for (std::size_t k = 0; k < a_.size(); ++k) c.add(impulse_, k);
    c.add(y_, 0);
    return c;
  }
  // Sums over the scored rows t0 <= t < N of the products of left's and right's columns into
  // out. A block of rows at a time, so that a column's block is read from memory once and every
  // product is a vectorised dot product in cache.
  // A product whose mirror (the same two columns the other way round) comes earlier is copied
  // from it, not summed again: a Gram matrix costs its upper triangle.
  void scored_dots(const Columns& left, const Columns& right, Eigen::MatrixXd& out) const {
    constexpr std::size_t kBlock = 512;
    out.setZero(left.n, right.n);
    auto same = [](const Column& a, const Column& b) { return a.v == b.v && a.lag == b.lag; };
    // mirror[i][j] = i' * kMaxColumns + j' of an earlier product of the same pair, or -1.
    std::array<std::array<int, kMaxColumns>, kMaxColumns> mirror;
    for (int i = 0; i < left.n; ++i)
      for (int j = 0; j < right.n; ++j) {
        mirror[i][j] = -1;
        for (int i2 = 0; i2 < i && mirror[i][j] < 0; ++i2)
          for (int j2 = 0; j2 < right.n; ++j2)
            if (same(left.c[i2], right.c[j]) && same(right.c[j2], left.c[i])) {
              mirror[i][j] = i2 * kMaxColumns + j2;
              break;
            }
      }
    for (std::size_t t = t0_; t < u_.size(); t += kBlock) {
      const auto len = static_cast<Eigen::Index>(std::min(kBlock, u_.size() - t));
      auto block = [&](const Column& c) {
        return Eigen::Map<const Eigen::VectorXd>(c.v + (t - c.lag), len);
      };
      for (int i = 0; i < left.n; ++i)
        for (int j = 0; j < right.n; ++j)
          if (mirror[i][j] < 0)
            out(i, j) += block(left.c[static_cast<std::size_t>(i)])
                             .dot(block(right.c[static_cast<std::size_t>(j)]));
    }
    for (int i = 0; i < left.n; ++i)
      for (int j = 0; j < right.n; ++j)
        if (mirror[i][j] >= 0)
          out(i, j) = out(mirror[i][j] / kMaxColumns, mirror[i][j] % kMaxColumns);
  }
  // The taps' products with each other into out's left block. The taps are one series at lags
  // l_0 < l_1 < ..., so the product of lags l_i <= l_j is the series against itself d = l_j - l_i
  // back, summed over the scored rows moved back by l_i: one dot product per d, over the rows of
  // l_0, and the few rows at the two ends where the others' differ.
  void tap_gram(const Columns& taps, Eigen::MatrixXd& out) const {
    const double* v = taps.c[0].v;
    const std::size_t l0 = taps.c[0].lag, N = u_.size();
    const auto n = static_cast<Eigen::Index>(N - t0_);
    const Eigen::Map<const Eigen::VectorXd> at_l0(v + (t0_ - l0), n);
    std::array<double, kMaxColumns> base{};
    for (int d = 0; d < taps.n; ++d)
      base[static_cast<std::size_t>(d)] = at_l0.dot(
          Eigen::Map<const Eigen::VectorXd>(v + (t0_ - l0 - static_cast<std::size_t>(d)), n));
    for (int i = 0; i < taps.n; ++i)
      for (int j = i; j < taps.n; ++j) {
        const std::size_t li = taps.c[static_cast<std::size_t>(i)].lag,
                          d = taps.c[static_cast<std::size_t>(j)].lag - li;
        double sum = base[d];
        // Rows s of the series: l_0's are t0 - l0 .. N - 1 - l0, l_i's e = li - l0 earlier.
        for (std::size_t s = t0_ - li; s < t0_ - l0; ++s) sum += v[s] * v[s - d];
        for (std::size_t s = N - li; s < N - l0; ++s) sum -= v[s] * v[s - d];
        out(i, j) = out(j, i) = sum;
      }
  }
  // x through 1/A from rest into f_ and, when the poles changed, the fixed regressors (the
  // constant and the free responses through 1/A) and their sums of products with each other and
  // y, which do not depend on the valve. The free response of initial state k is the impulse
  // response delayed by k, and the constant's response the impulse response's running sum.
  void filter(const std::vector<double>& x) const {
    const bool fixed = !fixed_ready_;
    switch (a_.size()) {  // the common orders unrolled: the recursion is the inner loop
      case 0:
        fixed ? filter_n<0, true>(x) : filter_n<0, false>(x);
        break;
      case 1:
        fixed ? filter_n<1, true>(x) : filter_n<1, false>(x);
        break;
      case 2:
        fixed ? filter_n<2, true>(x) : filter_n<2, false>(x);
        break;
      case 3:
        fixed ? filter_n<3, true>(x) : filter_n<3, false>(x);
        break;
      default:
        fixed ? filter_n<-1, true>(x) : filter_n<-1, false>(x);
    }
    if (fixed) {
      const Columns c = fixed_columns();
      fixed_gram_.resize(c.n, c.n);
      scored_dots(c, c, fixed_gram_);
      fixed_ready_ = true;
    }
  }
  // The recursions of x and of the impulse response in one loop: their latencies overlap. For the
  // unrolled orders the past outputs stay in registers: loading f[t - 1] back from memory put a
  // store-forwarding delay on the chain, the filter's critical path. Same arithmetic, same order.
  template <int NA, bool kFixed>
  void filter_n(const std::vector<double>& x) const {
    const std::size_t N = x.size();
    const std::size_t na = NA >= 0 ? static_cast<std::size_t>(NA) : a_.size();
    const double* a = a_.data();
    f_.resize(N);
    if (kFixed) {
      impulse_.resize(N);
      step_.resize(N);
    }
    double* f = f_.data();
    double* h = impulse_.data();
    double* st = step_.data();
    double sum = 0.0;
    const std::size_t head = NA >= 0 ? std::min(na, N) : N;
    for (std::size_t t = 0; t < head; ++t) {
      double v = x[t], g = t == 0 ? 1.0 : 0.0;
      const std::size_t k = t >= na ? na : t;
      for (std::size_t i = 1; i <= k; ++i) {
        v -= a[i - 1] * f[t - i];
        if (kFixed) g -= a[i - 1] * h[t - i];
      }
      f[t] = v;
      if (kFixed) {
        h[t] = g;
        st[t] = sum += g;
      }
    }
    if constexpr (NA >= 0) {
      // fp[i - 1] = f[t - i], hp[i - 1] = h[t - i].
      std::array<double, NA + 1> c{}, fp{}, hp{};
      for (std::size_t i = 0; i < na; ++i) {
        c[i] = a[i];
        fp[i] = f[head - 1 - i];
        if (kFixed) hp[i] = h[head - 1 - i];
      }
      for (std::size_t t = head; t < N; ++t) {
        double v = x[t], g = 0.0;
        for (std::size_t i = 0; i < na; ++i) {
          v -= c[i] * fp[i];
          if (kFixed) g -= c[i] * hp[i];
        }
        for (std::size_t i = na; i-- > 1;) {
          fp[i] = fp[i - 1];
          if (kFixed) hp[i] = hp[i - 1];
        }
        if (na > 0) {
          fp[0] = v;
          if (kFixed) hp[0] = g;
        }
        f[t] = v;
        if (kFixed) {
          h[t] = g;
          st[t] = sum += g;
        }
      }
    }
  }
  // He's flowchart as the simulator and a PLC-driven valve see it: the OP is held between
  // samples (zero-order hold), so the valve takes each sample's OP change as one step and slips
  // at most once per sample (the probe's He above mimics the Preisach model's input instead).
  // With several bands, the band of the region the valve is held in applies, as
  // PositionDependentStiction in src/sim has it.
  // Returns a fingerprint of the position: a hash of the start and of every slip (sample, new
  // position). Equal fingerprints mean equal positions (two of 10^4 positions collide with a
  // chance of 10^-11), so a cost is not computed twice for the same position.
  std::uint64_t valve_into(const std::vector<Band>& bands, std::vector<double>& x) const {
    const int R = static_cast<int>(bands.size());
    double u_prev = u_.front(), xv = u_prev, u_r = 0.0;
    std::uint64_t key = mix(std::bit_cast<std::uint64_t>(xv));
    x.resize(u_.size());
    for (std::size_t t = 0; t < u_.size(); ++t) {
      const Band& b = R == 1
                          ? bands.front()
                          : bands[static_cast<std::size_t>(std::clamp(
                                static_cast<int>(std::floor((xv - region_lo_) / region_width_ * R)),
                                0, R - 1))];
      const double u_cum = u_r + (u_[t] - u_prev);
      u_prev = u_[t];
      if (std::abs(u_cum) > b.fs) {
        u_r = u_cum > 0 ? b.fd : -b.fd;
        xv = u_[t] - u_r;
        key = mix(mix(key ^ t) ^ std::bit_cast<std::uint64_t>(xv));
      } else {
        u_r = u_cum;
      }
      x[t] = xv;
    }
    return key;
  }
  // splitmix64's finaliser.
  static std::uint64_t mix(std::uint64_t z) {
    z += 0x9e3779b97f4a7c15u;
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9u;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebu;
    return z ^ (z >> 31);
  }
  const std::vector<double>& u_;
  const std::vector<double>& y_;
  bool identity_ = false;
  std::vector<double> a_;
  int nb_ = 1, nk_ = 0;
  std::size_t t0_ = 0;
  const std::vector<double> ones_;  // the constant column of ls_poles
  // For the poles in a_ once fixed_ready_: 1/A's responses from rest (the fixed regressors) and
  // the products of the fixed regressors and y.
  mutable std::vector<double> impulse_, step_;
  mutable Eigen::MatrixXd fixed_gram_;
  mutable bool fixed_ready_ = false;
  Eigen::MatrixXd y_lags_;                  // products of y's lags and 1 (ls_poles)
  mutable Eigen::MatrixXd products_;        // scratch: B's taps against every column
  mutable Eigen::MatrixXd fixed_products_;  // scratch: B's taps against the fixed columns
  const bool remember_;                     // costs_ in use
  const bool plain_sums_;                   // the taps' products summed one by one (not tap_gram)
  mutable std::unordered_map<std::uint64_t, double> costs_;  // by position fingerprint
  double var_y_ = 0.0;
  double region_lo_ = 0.0, region_width_ = 1.0;
  mutable std::vector<double> x_, f_;        // scratch
  mutable std::vector<double> sm_y_, sm_x_;  // scratch of sm_poles
  // sm_poles' first pass: y through sm_y0_poles_.
  mutable std::vector<double> sm_y0_, sm_y0_poles_;
  mutable bool sm_y0_valid_ = false;
};

// The poles for a fixed valve position x: Nelder-Mead over A's coefficients (unstable A rejected),
// b, c and the initial state by least squares inside. Returns the cost; fit keeps the best poles.
double refine_poles(HeDataFit& fit, const std::vector<double>& x) {
  std::vector<double> a = fit.poles();
  double best = fit.cost(x);
  if (a.empty()) return best;
  struct Ctx {
    HeDataFit* fit;
    const std::vector<double>* x;
  } ctx{&fit, &x};
  auto f = [](unsigned n, const double* z, double*, void* data) {
    auto* c = static_cast<Ctx*>(data);
    std::vector<double> av(z, z + n);
    if (!is_stable(av, 1e-6)) return 1e300;
    c->fit->set_poles(av);
    return c->fit->cost(*c->x);
  };
  const unsigned n = static_cast<unsigned>(a.size());
  nlopt_opt o = nlopt_create(NLOPT_LN_NELDERMEAD, n);
  nlopt_set_min_objective(o, f, &ctx);
  // Steps small against the distance to the unit circle: a slow pole sits within 1e-3 of it.
  const double margin = std::max(1e-4, 1.0 - spectral_radius(a));
  std::vector<double> dx(n, 0.3 * margin);
  nlopt_set_initial_step(o, dx.data());
  nlopt_set_xtol_abs1(o, 1e-3 * margin);
  nlopt_set_maxeval(o, 150);
  std::vector<double> z = a;
  double fz = best;
  const nlopt_result res = nlopt_optimize(o, z.data(), &fz);
  nlopt_destroy(o);
  if (res > 0 && fz < best) {
    best = fz;
    a = z;
  }
  fit.set_poles(a);
  return best;
}

struct Candidate {
  double cost, fs, fd;
};
// Candidates scored with their own equation-error poles too, whichever cost is lower: at `delay`
// (< 0: not), with `fallback` where those come out unstable; `known`: such costs already
// computed, by position fingerprint.
struct OwnPoles {
  int delay;
  const std::vector<double>& fallback;
  const std::unordered_map<std::uint64_t, double>& known;
};
// The lattice (fs, fd) = (best.fs + i step, best.fd + j step) within 0 <= fd <= fs <= width; it
// starts as the box of half-width `half` around the best.
struct Lattice {
  double step, half, width;
};

// The profile-likelihood interval of (fs, fd) around `best` (StictionInterval). `fit` holds the
// best's linear part. A side of the lattice's box that holds a candidate within the threshold is
// moved out by `half`, until the lattice's limits or the point budget. The search's other
// polished valleys (`valleys`) count too: within the threshold they fit as well, however far from
// the best (on real loops the cost is nearly flat across quite different bands).
StictionInterval profile_interval(const HeDataFit& fit, Candidate best, const OwnPoles& own_poles,
                                  const std::vector<Candidate>& valleys, const Lattice& lattice,
                                  const StictionQuantificationOptions& opt) {
  const double bfs = best.fs, bfd = best.fd, h = lattice.step, half = lattice.half,
               width = lattice.width;
  StictionInterval iv;
  iv.chi2 = opt.interval_chi2;
  iv.step_percent = h;
  iv.effective_samples = effective_sample_size(fit.residuals(fit.valve(bfs, bfd)));
  iv.cost_ratio = std::exp(iv.chi2 / iv.effective_samples);
  const double eps = 1e-9;
  const int m = std::max(1, static_cast<int>(std::lround(half / h)));
  const int i_min = -static_cast<int>(std::floor((bfs + eps) / h));
  const int i_max = static_cast<int>(std::floor((width - bfs + eps) / h));
  const int j_min = -static_cast<int>(std::floor((bfd + eps) / h));
  auto fs_of = [&](int i) { return bfs + i * h; };
  auto fd_of = [&](int j) { return bfd + j * h; };
  auto valid = [&](int i, int j) {
    return i >= i_min && i <= i_max && j >= j_min && fd_of(j) <= fs_of(i) + eps;
  };
  std::map<std::pair<int, int>, double> cost;
  int ilo = std::max(-m, i_min), ihi = std::min(m, i_max), jlo = std::max(-m, j_min), jhi = m;
  for (;;) {
    std::vector<std::pair<int, int>> todo;
    for (int i = ilo; i <= ihi; ++i)
      for (int j = jlo; j <= jhi; ++j)
        if (valid(i, j) && !cost.contains({i, j})) todo.push_back({i, j});
    if (cost.size() + todo.size() > opt.interval_max_points && !cost.empty()) {
      iv.capped = true;
      break;
    }
    const unsigned workers = worker_count(opt.threads, todo.size());
    std::vector<HeDataFit> same(workers, fit);
    std::vector<HeDataFit> own(own_poles.delay >= 0 ? workers : 0, fit);
    for (HeDataFit& f : own) f.set_delay(own_poles.delay);
    std::vector<std::vector<double>> xs(workers);
    std::vector<double> c(todo.size());
    parallel_for(todo.size(), workers, [&](unsigned w, std::size_t k) {
      const double fs = fs_of(todo[k].first), fd = fd_of(todo[k].second);
      c[k] = same[w].cost(fs, fd);
      if (own.empty()) return;
      HeDataFit& f = own[w];
      const std::uint64_t key = f.valve(fs, fd, xs[w]);
      const auto known = opt.reuse_costs ? own_poles.known.find(key) : own_poles.known.end();
      if (known != own_poles.known.end()) {
        c[k] = std::min(c[k], known->second);
        return;
      }
      const std::vector<double> a = f.ls_poles(xs[w]);
      f.set_poles(a.empty() ? own_poles.fallback : a);
      c[k] = std::min(c[k], f.cost(xs[w]));
    });
    for (std::size_t k = 0; k < todo.size(); ++k) {
      cost[todo[k]] = c[k];
      best.cost = std::min(best.cost, c[k]);
    }
    const double limit = best.cost * iv.cost_ratio;
    auto inside_at = [&](bool row, int at) {
      for (const auto& [ij, v] : cost)
        if ((row ? ij.first : ij.second) == at && v <= limit) return true;
      return false;
    };
    bool grow = false;
    auto widen = [&](int& side, bool row, int step, int bound) {
      if (side == bound || !inside_at(row, side)) return;
      side = step < 0 ? std::max(side + step, bound) : std::min(side + step, bound);
      grow = true;
    };
    widen(ilo, true, -m, i_min);
    widen(ihi, true, m, i_max);
    widen(jlo, false, -m, j_min);
    // fd's side is bounded by fd <= fs at the box's largest fs.
    widen(jhi, false, m, static_cast<int>(std::floor((fs_of(ihi) - bfd + eps) / h)));
    if (!grow) break;
  }
  const double limit = best.cost * iv.cost_ratio;
  iv.fs_lo = iv.fs_hi = bfs;
  iv.fd_lo = iv.fd_hi = bfd;
  std::vector<Candidate> inside = valleys;
  for (const auto& [ij, v] : cost) inside.push_back({v, fs_of(ij.first), fd_of(ij.second)});
  for (const Candidate& c : inside) {
    if (c.cost > limit) continue;
    iv.fs_lo = std::min(iv.fs_lo, c.fs);
    iv.fs_hi = std::max(iv.fs_hi, c.fs);
    iv.fd_lo = std::min(iv.fd_lo, c.fd);
    iv.fd_hi = std::max(iv.fd_hi, c.fd);
  }
  // Between lattice points the cost is not known (on simulated loops its valleys are narrower
  // than a step): the ends are bracketed by the next points out.
  iv.fs_lo = std::max(0.0, iv.fs_lo - h);
  iv.fs_open_above = iv.fs_hi + h >= width - eps;
  iv.fs_hi = std::min(width, iv.fs_hi + h);
  iv.fd_lo = std::max(0.0, iv.fd_lo - h);
  iv.fd_hi = std::min(iv.fs_hi, iv.fd_hi + h);
  iv.points = cost.size();
  iv.valid = true;
  return iv;
}

// One region's fs range (StictionRegion::fs_lo, fs_hi): from the refined bands, that region's fs
// walks out from its value (walk_profile, a lattice step first), its fd the best of the 9 lattice
// points around the previous point's; `limit`: the largest cost inside.
std::pair<double, double> region_interval(const HeDataFit& fit, const std::vector<Band>& bands,
                                          int r, double best, double limit, double h, double width,
                                          const StictionQuantificationOptions& opt) {
  constexpr int kFd = 4;
  const Band b0 = bands[static_cast<std::size_t>(r)];
  const unsigned workers = worker_count(opt.threads, 2 * kFd + 1);
  std::vector<HeDataFit> fits(workers, fit);
  double fd = b0.fd;
  auto cost = [&](double fs, bool restart) {
    if (restart) fd = b0.fd;
    std::vector<std::vector<Band>> sets;
    for (int k = -kFd; k <= kFd; ++k) {
      const double d = std::clamp(fd + k * h, 0.0, fs);
      if (!sets.empty() && sets.back()[static_cast<std::size_t>(r)].fd == d) continue;
      sets.push_back(bands);
      sets.back()[static_cast<std::size_t>(r)] = {fs, d};
    }
    std::vector<double> costs(sets.size());
    parallel_for(sets.size(), workers,
                 [&](unsigned w, std::size_t i) { costs[i] = fits[w].cost(sets[i]); });
    const std::size_t k =
        static_cast<std::size_t>(std::min_element(costs.begin(), costs.end()) - costs.begin());
    fd = sets[k][static_cast<std::size_t>(r)].fd;
    return costs[k];
  };
  const ProfileRange range =
      walk_profile(b0.fs, best, {0.0, width, h}, cost, [limit](double c) { return c <= limit; });
  return {range.lo, range.hi};
}

}  // namespace

StictionQuantification quantify_stiction(const HammersteinModel& model,
                                         const std::vector<double>& op,
                                         const StictionQuantificationOptions& opt) {
  const PreisachGrid& g = model.grid;
  if (static_cast<int>(model.mu.size()) != g.relay_count())
    throw std::invalid_argument("stiction quantification: the weights do not match the grid");
  const int R = std::max(1, opt.regions);
  const double delta = g.delta();
  StictionQuantification q;
  q.resolution_percent = delta;
  q.overall = q.preisach = unmeasured();

  // The visited range: the data's OP extremes, or the whole grid.
  double umin = std::numeric_limits<double>::infinity(), umax = -umin;
  std::size_t finite = 0;
  for (double u : op)
    if (std::isfinite(u)) {
      umin = std::min(umin, u);
      umax = std::max(umax, u);
      ++finite;
    }
  q.data_given = finite > 0;
  if (q.data_given) {
    q.op_lo = std::max(umin, g.umin);
    q.op_hi = std::min(umax, g.umax);
  } else {
    q.op_lo = g.umin;
    q.op_hi = g.umax;
  }
  const double width = std::max(0.0, q.op_hi - q.op_lo);
  q.regions.resize(static_cast<std::size_t>(R));
  for (int r = 0; r < R; ++r) {
    auto& reg = q.regions[static_cast<std::size_t>(r)];
    reg.op_lo = q.op_lo + width * r / R;
    reg.op_hi = q.op_lo + width * (r + 1) / R;
    reg.figures = reg.preisach = unmeasured();
    reg.visited = !q.data_given;
  }
  auto region_of = [&](double u) {
    if (!(width > 0)) return 0;
    return std::clamp(static_cast<int>(std::floor((u - q.op_lo) / width * R)), 0, R - 1);
  };

  double total_weight = 0;
  for (double w : model.mu) total_weight += w;
  const int levels = g.level(q.op_hi) - g.level(q.op_lo);
  if (levels < 2 || !(total_weight > 0)) {
    q.summary = levels < 2 ? "stiction not quantified: the data visited less than two levels of "
                             "the Preisach grid"
                           : "stiction not quantified: the valve model has no weights";
    return q;
  }
  q.valid = true;

  Probe p = q.data_given ? data_probe(model, op, width)
                         : forc_probe(model, g.level(q.op_lo), g.level(q.op_hi));
  // He sees the input as the Preisach model does, on the grid: the slips of both fall on the
  // same samples, and neither the offset of the samples from the thresholds nor the phase of the
  // grid shows up as a difference between the models.
  for (double u : p.u) p.uq.push_back(g.umin + g.level(u) * delta);
  for (double ru : p.reversal_u) q.regions[static_cast<std::size_t>(region_of(ru))].probes++;
  if (q.data_given) {
    for (double u : p.u) q.regions[static_cast<std::size_t>(region_of(u))].samples++;
    for (auto& reg : q.regions) {
      reg.data_reversals = reg.probes;
      reg.visited = static_cast<double>(reg.samples) >=
                        opt.min_region_sample_fraction * static_cast<double>(p.u.size()) &&
                    reg.data_reversals >= opt.min_region_reversals;
    }
  }
  double var_all = 0;
  {
    Sums s;
    for (std::size_t t = 0; t < p.u.size(); ++t)
      if (p.scored[t]) s.add(p.x[t], 0.0);
    var_all = s.var_p();
  }

  // Grid search over fs in [0, width], fd in [0, fs] and the staircase phase (a fraction of
  // fs - fd), then two finer grids around the best.
  struct Best {
    double fs = 0, fd = 0, phase = 0, cost = std::numeric_limits<double>::infinity();
  };
  // Costs this close are equal: the cost is flat up to rounding over a valley (the slips fall on
  // the same samples), and which point of it wins must not depend on the order of the sums.
  auto tie = [&](double c) { return std::isfinite(c) ? c * 1e-9 + 1e-12 * (1.0 + var_all) : 0.0; };
  auto search = [&](auto&& cost_of) {
    Best b;
    auto scan = [&](double fs0, double fs1, double fd0, double fd1, double step,
                    const std::vector<double>& phases) {
      for (double fs = std::max(0.0, fs0); fs <= fs1 + 1e-9 * step; fs += step)
        for (double fd = std::max(0.0, fd0); fd <= std::min(fs, fd1) + 1e-9 * step; fd += step)
          for (double ph : phases) {
            ph -= std::floor(ph);
            const double c = cost_of(fs, fd, ph);
            if (c < b.cost - tie(b.cost)) b = {fs, fd, ph, c};
          }
    };
    double step = std::max(delta / 4, width / 40);
    scan(0, width, 0, width, step, {0.0, 0.25, 0.5, 0.75});
    double dph = 0.125;
    for (int refine = 0; refine < 2; ++refine) {
      const Best c = b;
      scan(c.fs - step, c.fs + step, c.fd - step, c.fd + step, step / 4,
           {c.phase - dph, c.phase, c.phase + dph});
      step /= 4;
      dph /= 4;
    }
    // The input is on the grid, so the cost is flat over an interval of band and of jump (the
    // slips fall on the same samples): report the middle of the flat part, not its low end. The
    // band is known to a grid step, no better.
    const double tol = tie(b.cost);
    auto flat_part = [&](double dband, double djump, bool top) {
      double lo = 0, hi = 0;
      const double h = delta / 16;
      for (int sign : {-1, 1})
        for (int i = 1; i <= 16; ++i) {
          const double e = sign * i * h;
          const double f_s = b.fs + e * (dband + djump) / 2, f_d = b.fd + e * (dband - djump) / 2;
          if (f_d < 0 || f_s < f_d || !(cost_of(f_s, f_d, b.phase) <= b.cost + tol)) break;
          (sign < 0 ? lo : hi) = e;
        }
      return top ? hi : (lo + hi) / 2;
    };
    const double eb = flat_part(1, 0, false);
    b.fs += eb / 2;
    b.fd += eb / 2;
    const double ej = flat_part(0, 1, false);
    b.fs += ej / 2;
    b.fd -= ej / 2;
    b.cost = cost_of(b.fs, b.fd, b.phase);
    return b;
  };
  Sums sums;
  std::vector<Sums> per_region;
  const Runs overall_runs = runs_of(p, {}, opt.reuse_costs);
  const Best best = search([&](double f_s, double f_d, double ph) {
    accumulate(overall_runs, f_s, f_d, ph, R, sums, per_region);
    double s;
    return sums.cost_free(&s);
  });
  const double fs = best.fs, fd = best.fd, cost = best.cost;
  accumulate(overall_runs, fs, fd, best.phase, R, sums, per_region);
  sums.cost_free(&q.scale);
  q.overall = figures(fs, fd, cost, var_all);
  q.stiction = q.scale > 0 && q.overall.band_percent > delta;
  q.jump_identified = q.stiction && p.longest_sweep >= 2 * fs + delta;
  if (!q.stiction) {
    // No resolved band: He's best fit is a valve that follows the OP (up to the grid step).
    q.overall.fs_percent = q.overall.fd_percent = q.overall.band_percent = q.overall.jump_percent =
        0.0;
  }

  // Per region: the samples within a window after each turning point in the region (long enough
  // for the overall band and a slip or two), with the overall scale.
  const double window =
      std::min(width, (q.stiction ? 2 * q.overall.band_percent : 0.0) + 2 * delta);
  std::vector<int> region_of_sample(p.u.size(), -1);
  for (std::size_t t = 0; t < p.u.size(); ++t)
    if (p.scored[t] && p.reversal[t] >= 0 && p.since[t] <= window)
      region_of_sample[t] = region_of(p.reversal_u[static_cast<std::size_t>(p.reversal[t])]);
  const Runs region_runs = runs_of(p, region_of_sample, opt.reuse_costs);
  for (int r = 0; r < R; ++r) {
    auto& reg = q.regions[static_cast<std::size_t>(r)];
    reg.valid = reg.visited && reg.probes > 0;
    if (reg.probes == 0) continue;
    if (!(q.scale > 0)) {
      reg.figures = {0.0, 0.0, 0.0, 0.0, kNaN};
      continue;
    }
    const Best rb = search([&](double f_s, double f_d, double ph) {
      accumulate(region_runs, f_s, f_d, ph, R, sums, per_region);
      return per_region[static_cast<std::size_t>(r)].cost_fixed(q.scale);
    });
    accumulate(region_runs, rb.fs, rb.fd, rb.phase, R, sums, per_region);
    if (per_region[static_cast<std::size_t>(r)].n < 2) {  // no sample after its reversals
      reg.valid = false;
      continue;
    }
    reg.figures = figures(rb.fs, rb.fd, rb.cost, per_region[static_cast<std::size_t>(r)].var_p());
    reg.stiction = reg.valid && reg.figures.band_percent > delta;
    if (reg.figures.band_percent <= delta)
      reg.figures.fs_percent = reg.figures.fd_percent = reg.figures.band_percent =
          reg.figures.jump_percent = 0.0;
  }

  q.summary = stiction_sentence(q);
  q.preisach = q.overall;
  for (auto& reg : q.regions) reg.preisach = reg.figures;
  return q;
}

StictionQuantification quantify_stiction(const HammersteinModel& model,
                                         const std::vector<double>& op,
                                         const std::vector<double>& pv,
                                         const StictionQuantificationOptions& opt) {
  StictionQuantification q = quantify_stiction(model, op, opt);
  q.preisach = q.overall;
  // A band below the probe's grid step is refined too: a lattice fitted by NNLS shortens bands, so
  // the probe can miss one a little over its step (a 2 % band at a step of 1.36 %).
  const bool resolved = q.stiction;
  if (!q.valid || !(q.scale > 0) || (!resolved && !opt.refine_unresolved) || !opt.refine_on_data ||
      pv.size() != op.size())
    return q;
  // The longest stretch where both are finite: the linear part needs consecutive samples.
  std::size_t best_from = 0, best_len = 0;
  for (std::size_t t = 0; t < op.size();) {
    std::size_t e = t;
    while (e < op.size() && std::isfinite(op[e]) && std::isfinite(pv[e])) ++e;
    if (e - t > best_len) {
      best_from = t;
      best_len = e - t;
    }
    t = e + 1;
  }
  const auto from = static_cast<std::ptrdiff_t>(best_from);
  const auto to = static_cast<std::ptrdiff_t>(best_from + best_len);
  const std::vector<double> u(op.begin() + from, op.begin() + to);
  const std::vector<double> y(pv.begin() + from, pv.begin() + to);
  HeDataFit fit(model, u, y, q.op_hi - q.op_lo, model.structure.nk + opt.refine_delay_range,
                opt.reuse_costs, opt.plain_sums);
  if (!fit.usable()) return q;

  const double delta = q.resolution_percent;
  const double width = q.op_hi - q.op_lo;
  const double fs0 = q.overall.fs_percent, fd0 = q.overall.fd_percent;
  // The linear part for a valve position x: delay (nk +- the range) and poles by output error.
  auto refine_linear = [&](HeDataFit& fit, const std::vector<double>& x) {
    const std::vector<double> a0 = fit.poles();
    const int nk0 = fit.delay();
    double best = std::numeric_limits<double>::infinity();
    std::vector<double> best_a = a0;
    int best_nk = nk0;
    for (int nk = std::max(0, nk0 - opt.refine_delay_range); nk <= nk0 + opt.refine_delay_range;
         ++nk) {
      fit.set_delay(nk);
      fit.set_poles(a0);
      const double c = refine_poles(fit, x);
      if (c < best) {
        best = c;
        best_a = fit.poles();
        best_nk = nk;
      }
    }
    fit.set_delay(best_nk);
    fit.set_poles(best_a);
    return best;
  };
  // The identified linear part came with the Preisach valve and from the equation error: re-fit
  // it by output error to the Preisach valve's own position first, so that the search for He's
  // figures starts from poles that do not depend on He's candidate.
  const bool arx = !fit.identity();
  if (arx) refine_linear(fit, simulate_valve(model, u));
  const std::vector<double> a_start = fit.poles();
  const int nk_start = fit.delay();

  // The cost is rugged: a candidate that moves one slip by a sample, or adds one to a sweep, costs
  // much more than the truth, so its valleys are a tenth of a % wide. A fine grid over a window of
  // a few Preisach grid steps around the Preisach figures, each point scored with a linear part of
  // its own (refine_own_linear), then the best few separate valleys are each polished (linear
  // part by output error, then a finer grid) and the best wins.
  // The step follows the band, at most 200 steps across the window (an unresolved probe's zero
  // band with a large grid step would otherwise make it 0.02 over several % of travel: 10^5
  // points). Above the step the window is 3 steps, so only unresolved bands meet the cap.
  const double W = opt.refine_window_steps * delta;
  const double h = std::max(std::clamp((fs0 + fd0) / 40, 0.02, 0.1), W / 200);
  using Point = Candidate;
  // The poles a candidate's valve position is scored with: the equation error's for that valve,
  // or the Preisach valve's. Scored with the Preisach valve's alone, the grid's ranking depends on
  // that part: on paper Example 1 with fit's default orders it put the true valley below one at
  // fd 1.0-1.5 (against 3.5) on seeds 1 and 11 of 16 and on the demo's record, and the polish
  // refined the wrong one.
  const bool own = opt.refine_own_linear && arx;
  auto poles_for = [&](const HeDataFit& fit, const std::vector<double>& x) {
    std::vector<double> a = own ? fit.ls_poles(x) : std::vector<double>{};
    return a.empty() ? a_start : a;
  };
  std::vector<Point> pts;
  for (double fs = std::max(0.0, fs0 - W); fs <= std::min(fs0 + W, width) + 1e-9; fs += h)
    for (double fd = 0.0; fd <= std::min(fs, fd0 + W) + 1e-9; fd += h) pts.push_back({0.0, fs, fd});
  const std::size_t local_points = pts.size();
  // And a coarse lattice over every band the visited range allows (0 <= fd <= fs <= width), about
  // `global_points` of them: the probe's figures are only as good as the Preisach model, which
  // measurement noise biases (fopdt, fs 5 fd 2, noise 1: the probe says fs 13.7, the window's
  // best 10.1, and the truth fits the data better than either).
  const double hg =
      opt.global_starts > 0 && opt.global_points > 0
          ? std::max(h, width / std::sqrt(2.0 * static_cast<double>(opt.global_points)))
          : 0.0;
  if (hg > 0)
    for (double fs = hg; fs <= width + 1e-9; fs += hg)
      for (double fd = 0.0; fd <= fs + 1e-9; fd += hg) pts.push_back({0.0, fs, fd});
  // The points on all cores, each worker with a fit of its own. Neighbouring points often slip
  // on the same samples (on long records, half of them): a position's cost, own poles included,
  // is computed once.
  const unsigned workers = worker_count(opt.threads, pts.size());
  std::vector<HeDataFit> fits(workers, fit);
  std::vector<std::vector<double>> xs(workers);  // positions: not allocated per point
  // The coarse lattice's bands are also scored with the Preisach valve's poles and with
  // Steiglitz-McBride's from those, the lowest cost kept: far from the probe the equation error's
  // poles can be far off (noise biases them; Steiglitz-McBride's filtering undoes most of that).
  const bool lattice_scoring = own && hg > 0;
  std::vector<HeDataFit> held(lattice_scoring ? workers : 0, fit);
  std::vector<HeDataFit> smf(held.size(), fit);
  // Steiglitz-McBride's poles for x, from the Preisach valve's (empty: none stable).
  auto sm_poles_for = [&](HeDataFit& g, const std::vector<double>& x) {
    g.set_poles(a_start);
    return g.sm_poles(x, opt.global_sm_passes);
  };
  // Each cost depends on the position alone, so it is remembered by the position's fingerprint:
  // `scored` the own poles' (the interval reuses it), `sm_scored` Steiglitz-McBride's.
  std::unordered_map<std::uint64_t, double> scored, sm_scored;
  std::mutex scored_mutex;
  auto remembered = [&](std::unordered_map<std::uint64_t, double>& costs, std::uint64_t key,
                        auto&& compute) {
    if (opt.reuse_costs) {
      const std::lock_guard<std::mutex> lock(scored_mutex);
      const auto seen = costs.find(key);
      if (seen != costs.end()) return seen->second;
    }
    const double c = compute();
    if (opt.reuse_costs) {
      const std::lock_guard<std::mutex> lock(scored_mutex);
      costs.emplace(key, c);
    }
    return c;
  };
  auto score = [&](unsigned w, Point& pt, bool lattice) {
    HeDataFit& f = fits[w];
    std::vector<double>& x = xs[w];
    const std::uint64_t key = f.valve(pt.fs, pt.fd, x);
    pt.cost = remembered(scored, key, [&] {
      if (own) f.set_poles(poles_for(f, x));
      return f.cost(x);
    });
    if (!lattice || !lattice_scoring) return;
    pt.cost = std::min(pt.cost, held[w].cost(pt.fs, pt.fd));
    if (opt.global_sm_passes > 0)  // and with Steiglitz-McBride's poles
      pt.cost = std::min(pt.cost, remembered(sm_scored, key, [&] {
                           HeDataFit& g = smf[w];
                           const std::vector<double> a = sm_poles_for(g, x);
                           if (a.empty()) return std::numeric_limits<double>::infinity();
                           g.set_poles(a);
                           return g.cost(x);
                         }));
  };
  parallel_for(pts.size(), workers,
               [&](unsigned w, std::size_t k) { score(w, pts[k], k >= local_points); });
  // The best cells of the coarse lattice again at a quarter of its step: a band that reproduces
  // the data's slips is a pit about 0.1 % wide, and a lattice point a step away from it often
  // costs three times as much, so it shows only in a cell's neighbourhood.
  if (hg > 0 && opt.global_cells > 0) {
    std::vector<Point> top(pts.begin() + static_cast<std::ptrdiff_t>(local_points), pts.end());
    const std::size_t cells = std::min(top.size(), opt.global_cells);
    std::partial_sort(top.begin(), top.begin() + static_cast<std::ptrdiff_t>(cells), top.end(),
                      [](const Point& l, const Point& r) { return l.cost < r.cost; });
    const std::size_t before = pts.size();
    for (std::size_t c = 0; c < cells; ++c)
      for (int i = -2; i <= 2; ++i)
        for (int j = -2; j <= 2; ++j) {
          const double fs = top[c].fs + i * hg / 4, fd = top[c].fd + j * hg / 4;
          if ((i != 0 || j != 0) && fd >= 0.0 && fd <= fs && fs <= width + 1e-9)
            pts.push_back({0.0, fs, fd});
        }
    parallel_for(pts.size() - before, workers,
                 [&](unsigned w, std::size_t k) { score(w, pts[before + k], true); });
  }
  // The window's best separate valleys, then the coarse lattice's best ones apart from those.
  auto by_cost = [](const Point& l, const Point& r) { return l.cost < r.cost; };
  const auto local_end = pts.begin() + static_cast<std::ptrdiff_t>(local_points);
  std::sort(pts.begin(), local_end, by_cost);
  std::sort(local_end, pts.end(), by_cost);
  std::vector<Point> starts;
  // A point joins the starts when it lies `apart` from the ones this call took and beyond the
  // polish's reach (4 h) of the earlier ones: a lattice point 2 lattice steps from the window's
  // start (1.07 % on paper Example 1 at noise 1) is a valley of its own, which the window's
  // polish cannot reach.
  const double reach = 4 * h;
  auto take = [&](auto from, auto to, std::size_t count, double apart) {
    const std::size_t earlier = starts.size(), limit = starts.size() + count;
    for (auto pt = from; pt != to && starts.size() < limit; ++pt) {
      bool separate = true;
      for (std::size_t i = 0; i < starts.size() && separate; ++i) {
        const Point& st = starts[i];
        const double d = std::max(std::abs(st.fs - pt->fs), std::abs(st.fd - pt->fd));
        separate = d > (i < earlier ? reach : apart);
      }
      if (separate) starts.push_back(*pt);
    }
  };
  take(pts.begin(), local_end, static_cast<std::size_t>(std::max(0, opt.refine_starts)), delta / 2);
  take(local_end, pts.end(), static_cast<std::size_t>(std::max(0, opt.global_starts)),
       std::max(delta / 2, 2 * hg));
  // A start's poles: of those its lattice point was scored with, the ones that fit best (the
  // polish that refines them finds a nearby minimum only: from the equation error's poles it lost
  // a valley that Steiglitz-McBride's had found on paper Example 1 at noise 1 and 2).
  auto start_poles = [&](HeDataFit& f, const std::vector<double>& x) {
    std::vector<double> best_a = poles_for(f, x);
    if (!lattice_scoring) return best_a;
    std::vector<std::vector<double>> others{a_start};
    if (opt.global_sm_passes > 0) others.push_back(sm_poles_for(f, x));
    f.set_poles(best_a);
    double best_c = f.cost(x);
    for (const auto& a : others) {
      if (a.empty()) continue;
      f.set_poles(a);
      const double c = f.cost(x);
      if (c < best_c) {
        best_c = c;
        best_a = a;
      }
    }
    return best_a;
  };
  // Each start polished by a worker with a fit of its own, from `nk` and `poles` (empty: the
  // start's own); the best in start order wins.
  struct Polished {
    std::vector<Point> points;
    std::vector<std::vector<double>> poles;  // each start's
    int delay;
  };
  auto polish = [&](const std::vector<Point>& from, int nk, const std::vector<double>& poles) {
    Polished out{from, std::vector<std::vector<double>>(from.size()), nk};
    const unsigned polishers = worker_count(opt.threads, from.size());
    std::vector<HeDataFit> pfits(polishers, fit);
    parallel_for(from.size(), polishers, [&](unsigned w, std::size_t i) {
      HeDataFit& f = pfits[w];
      Point& cur = out.points[i];
      f.set_delay(nk);
      out.poles[i] = poles.empty() ? start_poles(f, f.valve(cur.fs, cur.fd)) : poles;
      f.set_poles(out.poles[i]);
      for (int pass = 0; pass < (arx ? opt.refine_passes : 1); ++pass) {
        if (arx) refine_linear(f, f.valve(cur.fs, cur.fd));
        cur.cost = f.cost(cur.fs, cur.fd);
        const Point c0 = cur;
        const double hh = h / 4;
        for (double fs = std::max(0.0, c0.fs - 4 * h); fs <= c0.fs + 4 * h + 1e-9; fs += hh)
          for (double fd = std::max(0.0, c0.fd - 4 * h); fd <= std::min(fs, c0.fd + 4 * h) + 1e-9;
               fd += hh) {
            const double c = f.cost(fs, fd);
            if (c < cur.cost) cur = {c, fs, fd};
          }
      }
    });
    return out;
  };
  Point best{std::numeric_limits<double>::infinity(), fs0, fd0};
  std::vector<double> best_poles = a_start;
  int best_delay = nk_start;
  std::vector<Point> polished;  // every polished valley
  auto keep_best = [&](const Polished& p) {
    for (std::size_t i = 0; i < p.points.size(); ++i) {
      polished.push_back(p.points[i]);
      if (p.points[i].cost < best.cost) {
        best = p.points[i];
        best_poles = p.poles[i];
        best_delay = p.delay;
      }
    }
  };
  // And a valve without stiction, always: whether it fits as well is the engineer's first
  // question, and the lattices only reach it when the best lies near it.
  if (std::none_of(starts.begin(), starts.end(),
                   [&](const Point& st) { return st.fs <= h && st.fd <= h; }))
    starts.push_back({0.0, 0.0, 0.0});
  keep_best(polish(starts, nk_start, {}));
  // The coarse lattice again, scored with the best's linear part: where the probe and the
  // equation error's poles were both off, the first round's best has poles near the truth's.
  for (int round = 1; round < opt.global_rounds && hg > 0; ++round) {
    HeDataFit winner = fit;
    winner.set_delay(best_delay);
    winner.set_poles(best_poles);
    if (arx) refine_linear(winner, winner.valve(best.fs, best.fd));
    std::vector<Point> lattice(local_end, pts.end());
    const unsigned n = worker_count(opt.threads, lattice.size());
    std::vector<HeDataFit> wfits(n, winner);
    parallel_for(lattice.size(), n, [&](unsigned w, std::size_t k) {
      lattice[k].cost = wfits[w].cost(lattice[k].fs, lattice[k].fd);
    });
    std::sort(lattice.begin(), lattice.end(), by_cost);
    starts = polished;
    const std::size_t before = starts.size();
    take(lattice.begin(), lattice.end(), static_cast<std::size_t>(std::max(0, opt.global_starts)),
         std::max(delta / 2, 2 * hg));
    if (starts.size() == before) break;
    const double was = best.cost;
    keep_best(polish(
        std::vector<Point>(starts.begin() + static_cast<std::ptrdiff_t>(before), starts.end()),
        winner.delay(), winner.poles()));
    if (!(best.cost < was)) break;
  }
  const double bfs = best.fs, bfd = best.fd, bcost = best.cost;
  // The linear part of the winner, from where its polish started (the loop above leaves the last
  // start's).
  fit.set_poles(best_poles);
  fit.set_delay(best_delay);
  if (arx) refine_linear(fit, fit.valve(bfs, bfd));
  if (opt.interval) {
    q.interval = profile_interval(fit, {std::min(bcost, fit.cost(bfs, bfd)), bfs, bfd},
                                  {own ? nk_start : -1, a_start, scored}, polished,
                                  {h, std::max(delta / 2, 2 * h), width}, opt);
  }

  // Per region: He's bands where the valve sticks in that region (PositionDependentStiction),
  // each region's band searched in turn around the overall figures, the others held, with the
  // overall linear part. A region the data did not visit keeps the Preisach probe's figures.
  const int R = static_cast<int>(q.regions.size());
  if (opt.refine_regions && R > 1) {
    fit.set_regions(q.op_lo, width);
    std::vector<Band> bands(static_cast<std::size_t>(R), Band{bfs, bfd});
    double cost = fit.cost(bands);
    for (int sweep = 0; sweep < 2; ++sweep) {
      for (int r = 0; r < R; ++r) {
        if (!q.regions[static_cast<std::size_t>(r)].valid) continue;
        Band& b = bands[static_cast<std::size_t>(r)];
        // This region's band over a grid, the others held: the points on all cores, the first
        // best in grid order kept.
        auto local = [&](Band centre, double half, double step) {
          std::vector<std::vector<Band>> sets;
          for (double fs = std::max(0.0, centre.fs - half); fs <= centre.fs + half + 1e-9;
               fs += step)
            for (double fd = std::max(0.0, centre.fd - half);
                 fd <= std::min(fs, centre.fd + half) + 1e-9; fd += step) {
              sets.push_back(bands);
              sets.back()[static_cast<std::size_t>(r)] = {fs, fd};
            }
          const unsigned n = worker_count(opt.threads, sets.size());
          std::vector<HeDataFit> fits(n, fit);
          std::vector<double> costs(sets.size());
          parallel_for(sets.size(), n,
                       [&](unsigned w, std::size_t i) { costs[i] = fits[w].cost(sets[i]); });
          for (std::size_t i = 0; i < sets.size(); ++i)
            if (costs[i] < cost) {
              cost = costs[i];
              b = sets[i][static_cast<std::size_t>(r)];
            }
        };
        if (sweep == 0) local({bfs, bfd}, W, 2 * h);
        local(b, 2 * h, h / 2);
      }
      if (arx) {  // the linear part for the valve with its regions
        refine_linear(fit, fit.valve(bands));
        cost = fit.cost(bands);
      }
    }
    // The regions' ranges' threshold: N_eff of the residual with every region's band.
    const double limit =
        opt.interval
            ? cost * std::exp(opt.interval_chi2 /
                              std::max(effective_sample_size(fit.residuals(fit.valve(bands))), 1.0))
            : 0.0;
    for (int r = 0; r < R; ++r) {
      auto& reg = q.regions[static_cast<std::size_t>(r)];
      if (!reg.valid) continue;
      const Band& b = bands[static_cast<std::size_t>(r)];
      reg.figures = figures(b.fs, b.fd, cost, fit.var_y());
      reg.stiction = reg.figures.band_percent > 0;
      if (opt.interval) {
        const auto [lo, hi] = region_interval(fit, bands, r, cost, limit, h, width, opt);
        reg.fs_lo = lo;
        reg.fs_hi = hi;
      }
    }
  }
  q.refined = true;
  q.overall = figures(bfs, bfd, bcost, fit.var_y());
  // Below the probe's step, stiction when the refined band clears that step after all (the
  // probe's criterion, on better figures) and the data reject fs = 0. Not on the interval alone:
  // on a long record it excludes 0 for any systematic misfit (a linear valve in paper Example 1
  // fits 0.07 % "better").
  if (!resolved)
    q.stiction = q.overall.band_percent > delta && q.interval.valid && q.interval.fs_lo > 0;
  q.summary = stiction_sentence(q);
  return q;
}

StictionQuantification in_percent_of_span(StictionQuantification q, const OpRange& span) {
  const double op_lo = span.lo, op_hi = span.hi;
  if (!(std::isfinite(op_lo) && std::isfinite(op_hi) && op_lo < op_hi))
    throw std::invalid_argument("in_percent_of_span: needs op_lo < op_hi, both finite");
  const double k = 100.0 / (op_hi - op_lo);
  auto scale = [k](StictionFigures& f) {
    f.fs_percent *= k;  // NaN stays NaN
    f.fd_percent *= k;
    f.band_percent *= k;
    f.jump_percent *= k;
  };
  scale(q.overall);
  scale(q.preisach);
  for (auto& g : q.regions) {
    scale(g.figures);
    scale(g.preisach);
    g.fs_lo *= k;
    g.fs_hi *= k;
  }
  q.resolution_percent *= k;
  q.scale /= k;
  for (double* v : {&q.interval.fs_lo, &q.interval.fs_hi, &q.interval.fd_lo, &q.interval.fd_hi,
                    &q.interval.step_percent})
    *v *= k;
  if (q.valid) q.summary = stiction_sentence(q, " of the OP span " + pct(op_lo) + ":" + pct(op_hi));
  return q;
}

}  // namespace valvediag
