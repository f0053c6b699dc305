#include "valvediag/core/identification.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <mutex>
#include <stdexcept>

#include "valvediag/core/parallel_for.hpp"
#include "valvediag/core/relay_design.hpp"

namespace valvediag {

namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

// Sums of lagged outputs over the equation window, shared by every configuration.
struct OutputSums {
  Eigen::MatrixXd yy;  // sum y(t-i) y(t-j), i, j = 0..na_max
  Eigen::VectorXd y;   // sum y(t-i)
  double count = 0;
  double spread = 0;  // sum (y - mean)^2 on the window: eq 20's denominator
};

OutputSums output_sums(const std::vector<double>& y, std::size_t from, std::size_t to, int na) {
  OutputSums s;
  s.yy = Eigen::MatrixXd::Zero(na + 1, na + 1);
  s.y = Eigen::VectorXd::Zero(na + 1);
  for (std::size_t t = from; t < to; ++t) {
    for (int i = 0; i <= na; ++i) {
      const double yi = y[t - static_cast<std::size_t>(i)];
      s.y[i] += yi;
      for (int j = i; j <= na; ++j) s.yy(i, j) += yi * y[t - static_cast<std::size_t>(j)];
    }
  }
  s.yy = s.yy.selfadjointView<Eigen::Upper>();
  s.count = static_cast<double>(to - from);
  const double mean = s.y[0] / s.count;
  for (std::size_t t = from; t < to; ++t) s.spread += (y[t] - mean) * (y[t] - mean);
  return s;
}

// One configuration (na, nb, nk) on one relay design.
class ConfigSolver {
 public:
  ConfigSolver(const RelayDesign& design, const OutputSums& sums, const std::vector<double>& y,
               int na, int nb, int nk, bool identity, const FitOptions& opt)
      : D_(design), S_(sums), y_(y), na_(na), nb_(nb), nk_(nk), identity_(identity), opt_(opt) {
    lags_.resize(static_cast<std::size_t>(nb));
    for (int k = 0; k < nb; ++k) lags_[static_cast<std::size_t>(k)] = identity ? 0 : nk + k + 1;
  }

  int Kp() const { return D_.columns(); }

  const Eigen::MatrixXd& Qsym(int d, int dp) const {
    return D_.Q(std::min(d, dp), std::max(d, dp));
  }

  // Gram matrix and right-hand side of the joint (a, c, mu) problem for fixed b.
  void joint_system(const Eigen::VectorXd& b, Eigen::MatrixXd& H, Eigen::VectorXd& f) const {
    const int n = na_ + 1 + Kp();
    H.setZero(n, n);
    f.setZero(n);
    const int c = na_;
    for (int i = 0; i < na_; ++i) {
      for (int j = 0; j < na_; ++j) H(i, j) = S_.yy(i + 1, j + 1);
      H(i, c) = H(c, i) = -S_.y[i + 1];
      f[i] = -S_.yy(i + 1, 0);
    }
    H(c, c) = S_.count;
    f[c] = S_.y[0];
    auto Hmu = H.bottomRightCorner(Kp(), Kp());
    for (int k = 0; k < nb_; ++k) {
      const int dk = lags_[static_cast<std::size_t>(k)];
      const double bk = b[k];
      if (bk == 0.0) continue;
      for (int i = 0; i < na_; ++i)
        H.block(i, na_ + 1, 1, Kp()) -= bk * D_.r(dk, i + 1).transpose();
      H.block(c, na_ + 1, 1, Kp()) += bk * D_.g(dk).transpose();
      f.tail(Kp()) += bk * D_.r(dk, 0);
      Hmu += (bk * bk) * D_.Q(dk, dk);
      for (int l = k + 1; l < nb_; ++l) {
        const double bl = b[l];
        if (bl == 0.0) continue;
        const auto& q = Qsym(dk, lags_[static_cast<std::size_t>(l)]);
        Hmu += (bk * bl) * (q + q.transpose());
      }
    }
    H.bottomLeftCorner(Kp(), na_ + 1) = H.topRightCorner(na_ + 1, Kp()).transpose();
  }

  // Least squares for (a, b, c) given the valve position w[s] per state (eq 18).
  bool abc_step(const Eigen::VectorXd& w, Eigen::VectorXd& a, Eigen::VectorXd& b, double& c) const {
    const int n = na_ + nb_ + 1;
    Eigen::MatrixXd M = Eigen::MatrixXd::Zero(n, n);
    Eigen::VectorXd r = Eigen::VectorXd::Zero(n);
    const int ci = na_ + nb_;
    for (int i = 0; i < na_; ++i) {
      for (int j = 0; j < na_; ++j) M(i, j) = S_.yy(i + 1, j + 1);
      for (int k = 0; k < nb_; ++k)
        M(i, na_ + k) = M(na_ + k, i) = -w.dot(D_.h(lags_[static_cast<std::size_t>(k)], i + 1));
      M(i, ci) = M(ci, i) = -S_.y[i + 1];
      r[i] = -S_.yy(i + 1, 0);
    }
    for (int k = 0; k < nb_; ++k) {
      const int dk = lags_[static_cast<std::size_t>(k)];
      for (int l = k; l < nb_; ++l) {
        const int dl = lags_[static_cast<std::size_t>(l)];
        M(na_ + k, na_ + l) = M(na_ + l, na_ + k) = D_.cross(std::min(dk, dl), std::max(dk, dl), w);
      }
      M(na_ + k, ci) = M(ci, na_ + k) = w.dot(D_.n(dk));
      r[na_ + k] = w.dot(D_.h(dk, 0));
    }
    M(ci, ci) = S_.count;
    r[ci] = S_.y[0];
    M.diagonal().array() += 1e-12 * M.diagonal().cwiseAbs().maxCoeff();
    Eigen::LDLT<Eigen::MatrixXd> ldlt(M);
    if (ldlt.info() != Eigen::Success) return false;
    Eigen::VectorXd th = ldlt.solve(r);
    if (!th.allFinite()) return false;
    a = th.head(na_);
    b = th.segment(na_, nb_);
    c = th[ci];
    return true;
  }

  // Sum of squared simulated-output errors on the estimation window (eq 20's numerator), from
  // column weights through the state index: one gather per sample, then the ARX recursion.
  // This runs once per configuration and dominates at large N, so it is kept tight.
  double simulated_sse(const Eigen::VectorXd& a, const Eigen::VectorXd& b, double c,
                       const Eigen::VectorXd& cw) const {
    const Eigen::VectorXd w = D_.gamma() * cw;
    const auto& st = D_.state_of_sample();
    const std::size_t t0 = D_.start(), N = D_.end();
    thread_local std::vector<double> xs, ys;
    xs.resize(N);
    ys.resize(N);
    for (std::size_t t = 0; t < N; ++t) xs[t] = w[st[t]];
    for (std::size_t t = 0; t < t0; ++t) ys[t] = y_[t];
    if (na_ == 1 && nb_ == 1) return recursion<1, 1>(a, b, c, xs, ys);
    if (na_ == 1 && nb_ == 2) return recursion<1, 2>(a, b, c, xs, ys);
    if (na_ == 1 && nb_ == 3) return recursion<1, 3>(a, b, c, xs, ys);
    if (na_ == 2 && nb_ == 1) return recursion<2, 1>(a, b, c, xs, ys);
    if (na_ == 2 && nb_ == 2) return recursion<2, 2>(a, b, c, xs, ys);
    if (na_ == 2 && nb_ == 3) return recursion<2, 3>(a, b, c, xs, ys);
    if (na_ == 3 && nb_ == 1) return recursion<3, 1>(a, b, c, xs, ys);
    if (na_ == 3 && nb_ == 2) return recursion<3, 2>(a, b, c, xs, ys);
    if (na_ == 3 && nb_ == 3) return recursion<3, 3>(a, b, c, xs, ys);
    return recursion<-1, -1>(a, b, c, xs, ys);
  }

  template <int NA, int NB>
  double recursion(const Eigen::VectorXd& a, const Eigen::VectorXd& b, double c,
                   const std::vector<double>& xs, std::vector<double>& ys) const {
    const int na = NA >= 0 ? NA : na_, nb = NB >= 0 ? NB : nb_;
    const std::size_t t0 = D_.start(), N = D_.end();
    const std::size_t d0 = static_cast<std::size_t>(lags_[0]);
    double sse = 0.0;
    const double* y = y_.data();
    const double* x = xs.data();
    double* o = ys.data();
    // The input's terms first and the latest output's last: the recursion's dependent chain
    // (the last output to the next) is then one multiply and one subtract, not every term.
    for (std::size_t t = t0; t < N; ++t) {
      double v = c;
      for (int k = 0; k < nb; ++k) v += b[k] * x[t - d0 - static_cast<std::size_t>(k)];
      for (int i = na; i-- > 0;) v -= a[i] * o[t - static_cast<std::size_t>(i + 1)];
      o[t] = v;
      const double e = v - y[t];
      sse += e * e;
    }
    return std::isfinite(sse) ? sse : std::numeric_limits<double>::infinity();
  }

  struct Theta {
    Eigen::VectorXd a, b, cw;
    double c = 0.0;
    double cost = std::numeric_limits<double>::infinity();
    SolverStatus status = SolverStatus::Converged;
    std::vector<int> passive;
  };

  // Joint (a, c, mu) solve for fixed b; cost is the equation-error sum of squares.
  Theta joint(const Eigen::VectorXd& b, const std::vector<int>& warm) const {
    Eigen::MatrixXd H;
    Eigen::VectorXd f;
    joint_system(b, H, f);
    NonnegativeQp qp(std::move(H), std::move(f), na_ + 1);
    // Warm passive sets are kept as relay-column indices, so they carry across na.
    std::vector<int> wp;
    for (int k : warm)
      if (k < Kp()) wp.push_back(k + na_ + 1);
    NnlsResult r = qp.solve(wp);
    Theta th;
    th.a = r.x.head(na_);
    th.c = r.x[na_];
    th.cw = r.x.tail(Kp());
    th.b = b;
    th.cost = S_.yy(0, 0) + 2.0 * qp.objective(r.x);
    th.status = r.status;
    for (int i : qp.passive_set(r.x)) th.passive.push_back(i - na_ - 1);
    iterations_ += r.iterations;
    return th;
  }

  // The BIC choice of the L1 budget (eqs 21-22) for the final b, on the exact homotopy path.
  Theta choose_budget(const Theta& unbudgeted, double& kappa_out, double& bic_out, int& nz_out,
                      double& sse_out) const {
    Eigen::MatrixXd H;
    Eigen::VectorXd f;
    joint_system(unbudgeted.b, H, f);
    NonnegativeQp qp(std::move(H), std::move(f), na_ + 1);
    NnlsResult start;
    start.x.resize(na_ + 1 + Kp());
    start.x << unbudgeted.a, unbudgeted.c, unbudgeted.cw;
    start.status = unbudgeted.status;
    const double total = unbudgeted.cw.sum();
    std::vector<double> kappas = opt_.kappas;
    std::sort(kappas.begin(), kappas.end(), std::greater<>());
    std::vector<double> etas;
    for (double k : kappas) etas.push_back(k * total);
    const auto path = qp.solve_budgets(start, etas);
    const double N = static_cast<double>(D_.end() - D_.start());
    Theta best = unbudgeted;
    double best_bic = std::numeric_limits<double>::infinity();
    for (std::size_t i = 0; i < path.size(); ++i) {
      Theta th;
      th.a = path[i].x.head(na_);
      th.c = path[i].x[na_];
      th.cw = path[i].x.tail(Kp());
      th.b = unbudgeted.b;
      th.status = path[i].status;
      th.cost = S_.yy(0, 0) + 2.0 * qp.objective(path[i].x);
      double sse = -1.0;
      double sigma2 = std::max(th.cost, 0.0) / N;
      if (opt_.bic_on_simulated_output) {
        sse = simulated_sse(th.a, th.b, th.c, th.cw);
        sigma2 = sse / N;
      }
      int nz = 0;
      for (int k = 0; k < Kp(); ++k) nz += th.cw[k] > 0;
      const double P = na_ + nb_ + (identity_ ? 0 : nk_) + nz;
      const double bic = std::isfinite(sigma2) && sigma2 > 0
                             ? N * std::log(sigma2) + P * std::log(N)
                             : std::numeric_limits<double>::infinity();
      if (bic < best_bic || i == 0) {
        best_bic = bic;
        best = th;
        kappa_out = kappas[i];
        nz_out = nz;
        sse_out = sse;
      }
    }
    bic_out = best_bic;
    if (sse_out < 0) sse_out = simulated_sse(best.a, best.b, best.c, best.cw);
    return best;
  }

  // Joint method: alternate the (a, b, c) step with the joint solve until the cost stops falling.
  Theta fit_joint(const Eigen::VectorXd& b0, std::vector<int>& warm, int& iters,
                  std::string& stop) const {
    Theta th = joint(b0, warm);
    iters = 1;
    stop = "exact joint solve";
    if (nb_ == 1) return th;  // b = +-1 after normalization: the joint solve is the optimum
    const double tol = opt_.stop_tolerance > 0 ? opt_.stop_tolerance : 1e-9;
    stop = "iteration limit";
    for (int it = 1; it < opt_.max_iterations; ++it) {
      const Eigen::VectorXd w = D_.gamma() * th.cw;
      Eigen::VectorXd a, b;
      double c;
      if (!abc_step(w, a, b, c) || !(b.norm() > 0)) {
        stop = "b step singular";
        break;
      }
      b /= b.norm();
      Theta next = joint(b, th.passive);
      ++iters;
      const double decrease = th.cost - next.cost;
      if (next.cost <= th.cost) th = next;
      if (decrease <= tol * std::max(th.cost, 1e-300)) {
        stop = "cost decrease below tolerance";
        break;
      }
    }
    warm = th.passive;
    return th;
  }

  // The paper's alternation (eqs 17-19), with its stopping rule or ours.
  Theta fit_alternation(int& iters, std::string& stop) const {
    Eigen::VectorXd a = Eigen::VectorXd::Zero(na_), b = Eigen::VectorXd::Zero(nb_);
    b[0] = 1.0;
    double c = 0.0;
    Eigen::VectorXd cw = Eigen::VectorXd::Zero(Kp());
    const bool param_rule = opt_.stop_rule == StopRule::ParameterChange;
    const double tol = opt_.stop_tolerance > 0 ? opt_.stop_tolerance : (param_rule ? 0.01 : 1e-9);
    double prev_cost = std::numeric_limits<double>::infinity();
    Eigen::VectorXd prev_theta;
    Theta th;
    stop = "iteration limit";
    iters = 0;
    std::vector<int> warm;
    for (int it = 0; it < opt_.max_iterations; ++it) {
      ++iters;
      // Step 2: mu given (a, b, c), nonnegative with the BIC-chosen budget.
      Eigen::MatrixXd H;
      Eigen::VectorXd f;
      joint_system(b, H, f);
      const int m0 = na_ + 1;
      Eigen::MatrixXd Hmu = H.bottomRightCorner(Kp(), Kp());
      Eigen::VectorXd fmu =
          f.tail(Kp()) - H.block(m0, 0, Kp(), na_) * a - H.block(m0, na_, Kp(), 1) * c;
      NonnegativeQp qp(Hmu, fmu, 0);
      NnlsResult r = qp.solve(warm);
      iterations_ += r.iterations;
      warm = qp.passive_set(r.x);
      const double total = r.x.sum();
      std::vector<double> etas;
      for (double k : opt_.kappas) etas.push_back(k * total);
      auto path = qp.solve_budgets(r, etas);
      double best_bic = std::numeric_limits<double>::infinity();
      std::vector<double> ks = opt_.kappas;
      std::sort(ks.begin(), ks.end(), std::greater<>());
      const double N = static_cast<double>(D_.end() - D_.start());
      for (const auto& p : path) {
        int nz = 0;
        for (int k = 0; k < Kp(); ++k) nz += p.x[k] > 0;
        const double s2 = simulated_sse(a, b, c, p.x) / N;
        const double bic = (s2 > 0 && std::isfinite(s2))
                               ? N * std::log(s2) + (na_ + nb_ + nk_ + nz) * std::log(N)
                               : std::numeric_limits<double>::infinity();
        if (bic < best_bic || !std::isfinite(best_bic)) {
          best_bic = bic;
          cw = p.x;
        }
      }
      // Step 3: (a, b, c) by least squares given x.
      const Eigen::VectorXd w = D_.gamma() * cw;
      Eigen::VectorXd na_a, na_b;
      double na_c;
      if (!abc_step(w, na_a, na_b, na_c)) {
        stop = "least-squares step singular";
        th.status = SolverStatus::NumericalTrouble;
        break;
      }
      // Step 4: normalization.
      const double nrm = na_b.norm();
      if (!(nrm > 0)) {
        stop = "b collapsed to zero";
        a = na_a;
        c = na_c;
        break;
      }
      double s = 1.0;
      if (opt_.normalization == Normalization::PaperSign) {
        for (int k = 0; k < nb_; ++k)
          if (na_b[k] != 0) {
            s = na_b[k] > 0 ? 1.0 : -1.0;
            break;
          }
      }
      a = na_a;
      c = na_c;
      b = s * na_b / nrm;
      cw = s * nrm * cw;
      // Cost of the current parameters (equation error).
      Eigen::VectorXd theta(na_ + 1 + Kp());
      theta << a, c, cw;
      joint_system(b, H, f);
      const double cost = S_.yy(0, 0) - 2.0 * f.dot(theta) + theta.dot(H * theta);
      Eigen::VectorXd full(na_ + nb_ + 1 + Kp());
      full << a, b, c, cw;
      bool done = false;
      if (param_rule) {
        if (prev_theta.size() == full.size() && (full - prev_theta).norm() < tol * full.norm()) {
          stop = "parameter change below 1 % (paper's rule)";
          done = true;
        }
      } else if (std::isfinite(prev_cost) && prev_cost - cost <= tol * std::max(cost, 1e-300)) {
        stop = "cost decrease below tolerance";
        done = true;
      }
      prev_theta = full;
      prev_cost = cost;
      th.a = a;
      th.b = b;
      th.c = c;
      th.cw = cw;
      th.cost = cost;
      if (done) break;
      // mu must stay usable: with the paper's sign it can flip negative, then step 2 gives 0.
      if (opt_.normalization == Normalization::PaperSign && cw.minCoeff() < 0) {
        cw = cw.cwiseMax(0.0);
      }
    }
    return th;
  }

  mutable int iterations_ = 0;

 private:
  const RelayDesign& D_;
  const OutputSums& S_;
  const std::vector<double>& y_;
  int na_, nb_, nk_;
  bool identity_;
  const FitOptions& opt_;
  std::vector<int> lags_;
};

PreisachGrid grid_for(const std::vector<double>& u, const FitOptions& opt, int L) {
  PreisachGrid g;
  g.L = L;
  if (opt.umax > opt.umin) {
    g.umin = opt.umin;
    g.umax = opt.umax;
  } else {
    const auto [lo, hi] = std::minmax_element(u.begin(), u.end());
    g.umin = *lo;
    g.umax = *hi;
  }
  return g;
}

struct Split {
  std::size_t t0, end, N;
};

Split split_of(std::size_t N, const FitOptions& opt) {
  Split s;
  s.N = N;
  s.t0 = static_cast<std::size_t>(std::max({opt.na_max, opt.nk_max + opt.nb_max, 1}));
  if (opt.block == LinearBlock::Identity) s.t0 = 1;
  s.t0 = std::max(s.t0, opt.first_sample);
  s.end = N;
  if (opt.validation_start > 0) {
    s.end = std::min(opt.validation_start, N);
  } else if (opt.validation_fraction > 0) {
    s.end = static_cast<std::size_t>(
        std::llround(static_cast<double>(N) * (1.0 - opt.validation_fraction)));
  }
  return s;
}

RelayDesignOptions design_options(const FitOptions& opt, const Split& sp) {
  RelayDesignOptions d;
  const bool id = opt.block == LinearBlock::Identity;
  d.max_lag = id ? 0 : opt.nk_max + opt.nb_max;
  d.max_na = id ? 0 : opt.na_max;
  d.max_b_span = id ? 1 : opt.nb_max;
  d.start = sp.t0;
  d.end = sp.end;
  d.merge_identical = opt.merge_identical_relays;
  return d;
}

struct Candidate {
  ConfigurationResult info;
  HammersteinModel model;
};

// Fits (na, nb, nk) on a design and packs the model; `warm` carries the passive set along.
Candidate fit_on_design(const RelayDesign& design, const OutputSums& sums,
                        const std::vector<double>& u, const std::vector<double>& y, const Split& sp,
                        const Structure& s, const FitOptions& opt, std::vector<int>& warm,
                        const Eigen::VectorXd* b_start) {
  const bool identity = opt.block == LinearBlock::Identity;
  ConfigSolver solver(design, sums, y, identity ? 0 : s.na, identity ? 1 : s.nb, s.nk, identity,
                      opt);
  Candidate cand;
  cand.info.structure = s;
  int iters = 0;
  std::string stop;
  ConfigSolver::Theta th;
  if (identity) {
    Eigen::VectorXd b = Eigen::VectorXd::Ones(1);
    th = solver.joint(b, warm);
    iters = 1;
    stop = "exact joint solve";
  } else if (opt.method == FitMethod::Alternation) {
    th = solver.fit_alternation(iters, stop);
  } else {
    // Both gain signs for the leading b (a reverse-acting loop needs b < 0 with mu >= 0).
    std::vector<Eigen::VectorXd> starts;
    if (b_start && b_start->size() == s.nb) {
      starts.push_back(*b_start);
    } else {
      Eigen::VectorXd bp = Eigen::VectorXd::Zero(s.nb);
      bp[0] = 1.0;
      starts.push_back(bp);
      starts.push_back(-bp);
    }
    for (const auto& b0 : starts) {
      std::vector<int> w = warm;
      int it = 0;
      std::string st;
      auto t = solver.fit_joint(b0, w, it, st);
      iters += it;
      if (t.cost < th.cost) {
        th = t;
        stop = st;
        warm = w;
      }
    }
  }
  double kappa = 1.0, bic = 0.0;
  int nz = 0;
  double sse = -1.0;
  if (opt.method == FitMethod::Joint || identity) {
    th = solver.choose_budget(th, kappa, bic, nz, sse);
  } else {
    sse = solver.simulated_sse(th.a, th.b, th.c, th.cw);
    const double N = static_cast<double>(sp.end - sp.t0);
    for (int k = 0; k < th.cw.size(); ++k) nz += th.cw[k] > 0;
    bic = N * std::log(sse / N) + (s.na + s.nb + s.nk + nz) * std::log(N);
  }
  HammersteinModel& m = cand.model;
  m.structure = identity ? Structure{0, 1, 0, s.L} : s;
  m.block = opt.block;
  m.grid = design.grid();
  m.initial_history = design.history();
  m.mu = design.expand(th.cw);
  m.a.assign(th.a.data(), th.a.data() + th.a.size());
  m.b.assign(th.b.data(), th.b.data() + th.b.size());
  if (identity) m.b = {1.0};
  m.c = th.c;
  auto& info = cand.info;
  info.structure = m.structure;
  info.kappa = kappa;
  info.bic = bic;
  info.cost = th.cost;
  info.nonzero_weights = nz;
  info.iterations = iters + solver.iterations_;
  info.status = th.status;
  info.stop_reason = stop;
  info.stable = identity || is_stable(m.a);
  info.fitness_percent = info.stable && sums.spread > 0 && std::isfinite(sse)
                             ? (1.0 - std::sqrt(sse / sums.spread)) * 100.0
                             : kNaN;
  info.validation_fitness_percent = kNaN;
  if (info.stable && sp.end < sp.N) {
    const auto full = simulate_output(m, u, y, sp.t0);
    info.validation_fitness_percent = fitness_percent(y, full, sp.end, sp.N);
  }
  (void)u;
  return cand;
}

double score(const ConfigurationResult& r, const FitOptions& opt) {
  const double f = opt.select_on_validation ? r.validation_fitness_percent : r.fitness_percent;
  return std::isfinite(f) ? f : -std::numeric_limits<double>::infinity();
}

// Candidate initial memories: the input came up from umin to M, or down from umax to m,
// before the first sample (one extra dominant extremum: a staircase of the Preisach triangle).
std::vector<std::vector<int>> initial_histories(const PreisachGrid& g, double u0) {
  const int v0 = g.level(u0);
  std::vector<std::vector<int>> h;
  for (int M = v0; M <= g.L; ++M) h.push_back({0, M});
  for (int m = 0; m < v0; ++m) h.push_back({g.L, m});
  return h;
}

}  // namespace

std::string validate(const FitOptions& o) {
  if (o.na_min < 1 || o.na_max < o.na_min) return "na range must satisfy 1 <= na_min <= na_max";
  if (o.nb_min < 1 || o.nb_max < o.nb_min) return "nb range must satisfy 1 <= nb_min <= nb_max";
  if (o.nk_min < 0 || o.nk_max < o.nk_min) return "nk range must satisfy 0 <= nk_min <= nk_max";
  if (o.L_min < 1 || o.L_max < o.L_min) return "L range must satisfy 1 <= L_min <= L_max";
  if (o.L_max > 60) return "L above 60 (1,830 relays) is not supported";
  if (o.na_max > 20 || o.nb_max > 20 || o.nk_max > 200)
    return "orders too large (na, nb <= 20, nk <= 200)";
  if (o.kappas.empty()) return "kappa list must not be empty";
  for (double k : o.kappas)
    if (!(k > 0 && k <= 1)) return "kappa values must lie in (0, 1]";
  if (!(o.validation_fraction >= 0 && o.validation_fraction < 0.9))
    return "validation fraction must lie in [0, 0.9)";
  if (o.select_on_validation && o.validation_fraction <= 0 && o.validation_start == 0)
    return "selecting on validation needs a validation split";
  if (o.max_iterations < 1) return "max iterations must be at least 1";
  if ((o.umin != 0 || o.umax != 0) && !(o.umax > o.umin)) return "umax must exceed umin";
  return {};
}

std::size_t minimum_samples(const FitOptions& o) {
  // Enough equations for the largest model: a, b, nk, c and a couple of weights per level.
  const int lag = std::max(o.na_max, o.nk_max + o.nb_max);
  const double frac = 1.0 - o.validation_fraction;
  const int need = lag + 2 * (o.na_max + o.nb_max + 1 + 2 * o.L_max) + 10;
  return static_cast<std::size_t>(std::ceil(need / std::max(frac, 0.1)));
}

ConfigurationResult fit_configuration(const std::vector<double>& u, const std::vector<double>& y,
                                      const Structure& s, const FitOptions& opt,
                                      HammersteinModel* model_out) {
  const Split sp = split_of(u.size(), opt);
  const RelayDesign design(grid_for(u, opt, s.L), u, y, {0}, design_options(opt, sp));
  const OutputSums sums =
      output_sums(y, sp.t0, sp.end, opt.block == LinearBlock::Identity ? 0 : opt.na_max);
  std::vector<int> warm;
  Candidate c = fit_on_design(design, sums, u, y, sp, s, opt, warm, nullptr);
  if (model_out) *model_out = c.model;
  return c.info;
}

IdentificationResult identify(const std::vector<double>& u, const std::vector<double>& y,
                              const FitOptions& opt) {
  const auto t_start = std::chrono::steady_clock::now();
  if (auto msg = validate(opt); !msg.empty()) throw std::invalid_argument(msg);
  if (u.size() != y.size()) throw std::invalid_argument("input and output differ in length");
  if (opt.validation_start > 0 && opt.validation_start + 10 > u.size()) {
    throw std::invalid_argument("the validation part starts too close to the end of the data");
  }
  if (u.size() < minimum_samples(opt) ||
      (opt.validation_start > 0 && opt.validation_start < minimum_samples(opt))) {
    throw std::invalid_argument("too few samples: " + std::to_string(u.size()) +
                                ", the model needs at least " +
                                std::to_string(minimum_samples(opt)));
  }
  for (std::size_t t = 0; t < u.size(); ++t)
    if (!std::isfinite(u[t]) || !std::isfinite(y[t]))
      throw std::invalid_argument("non-finite sample");
  const auto [lo, hi] = std::minmax_element(u.begin(), u.end());
  if (!(*hi > *lo)) throw std::invalid_argument("the input is constant: nothing to identify");

  const Split sp = split_of(u.size(), opt);
  if (sp.end <
      sp.t0 + static_cast<std::size_t>(2 * (opt.na_max + opt.nb_max + 1 + 2 * opt.L_max) + 10))
    throw std::invalid_argument("the first estimation sample " + std::to_string(opt.first_sample) +
                                " leaves too few estimation samples");
  const bool identity = opt.block == LinearBlock::Identity;
  const RelayDesignOptions dopt = design_options(opt, sp);
  const OutputSums sums = output_sums(y, sp.t0, sp.end, identity ? 0 : opt.na_max);

  // Work per L, largest first (they cost most), shared out over the cores.
  std::vector<int> Ls;
  for (int L = opt.L_max; L >= opt.L_min; --L) Ls.push_back(L);
  const unsigned nthreads = worker_count(opt.threads, Ls.size());
  std::mutex mtx;
  IdentificationResult res;
  Candidate best;
  best.info.fitness_percent = kNaN;
  double best_score = -std::numeric_limits<double>::infinity();

  // Progress: each (L, nk, na) group weighted by L's relays, L (L + 1) / 2.
  const auto relays = [](int L) { return 0.5 * L * (L + 1); };
  double work_total = 0.0, work_done = 0.0, reported = 0.0;
  {
    const int groups = identity ? 1 : (opt.nk_max - opt.nk_min + 1) * (opt.na_max - opt.na_min + 1);
    for (int L : Ls) work_total += relays(L) * std::max(1, groups);
  }
  const auto group_done = [&](int L) {
    if (!opt.progress) return;
    const std::lock_guard<std::mutex> lock(mtx);
    work_done += relays(L);
    const double share = std::min(1.0, work_done / work_total);
    if (share >= reported + 0.01 || share >= 1.0) {
      reported = share;
      opt.progress(share);
    }
  };

  parallel_for(Ls.size(), nthreads, [&](unsigned, std::size_t idx) {
    const int L = Ls[idx];
    const RelayDesign design(grid_for(u, opt, L), u, y, {0}, dopt);
    std::vector<ConfigurationResult> local;
    Candidate local_best;
    double local_score = -std::numeric_limits<double>::infinity();
    std::vector<int> warm;
    const int nkmax = identity ? 0 : opt.nk_max, nkmin = identity ? 0 : opt.nk_min;
    const int namax = identity ? 0 : opt.na_max, namin = identity ? 0 : opt.na_min;
    const int nbmax = identity ? 1 : opt.nb_max, nbmin = identity ? 1 : opt.nb_min;
    for (int nk = nkmin; nk <= nkmax; ++nk) {
      for (int na = namin; na <= namax; ++na) {
        throw_if_cancelled(opt.cancel);
        Eigen::VectorXd prev_b;
        for (int nb = 1; nb <= nbmax; ++nb) {
          // Larger nb starts from the smaller one's b with a zero appended.
          Eigen::VectorXd b0;
          const Eigen::VectorXd* bs = nullptr;
          if (prev_b.size() > 0) {
            b0 = Eigen::VectorXd::Zero(nb);
            b0.head(prev_b.size()) = prev_b;
            bs = &b0;
          }
          Candidate c =
              fit_on_design(design, sums, u, y, sp, Structure{na, nb, nk, L}, opt, warm, bs);
          prev_b = Eigen::Map<const Eigen::VectorXd>(c.model.b.data(),
                                                     static_cast<Eigen::Index>(c.model.b.size()));
          if (nb < nbmin) continue;
          const double sc = score(c.info, opt);
          if (opt.keep_all_configurations) local.push_back(c.info);
          if (sc > local_score) {
            local_score = sc;
            local_best = std::move(c);
          }
        }
        group_done(L);
      }
    }
    std::lock_guard<std::mutex> lock(mtx);
    res.configurations.insert(res.configurations.end(), local.begin(), local.end());
    for (const auto& r : local) res.total_iterations += r.iterations;
    if (local_score > best_score) {
      best_score = local_score;
      best = std::move(local_best);
    }
  });
  std::sort(res.configurations.begin(), res.configurations.end(), [](const auto& a, const auto& b) {
    const auto& x = a.structure;
    const auto& y2 = b.structure;
    return std::tie(x.L, x.nk, x.na, x.nb) < std::tie(y2.L, y2.nk, y2.na, y2.nb);
  });

  res.first_sample = sp.t0;
  res.estimation_end = sp.end;
  if (std::isfinite(best_score) && opt.parsimony_percent > 0 && !res.configurations.empty()) {
    const ConfigurationResult* pick = nullptr;
    for (const auto& c : res.configurations) {
      if (!(score(c, opt) >= best_score - opt.parsimony_percent)) continue;
      auto key = [](const ConfigurationResult& r) {
        return std::make_tuple(r.structure.na + r.structure.nb, r.structure.L, r.structure.nk,
                               r.structure.na);
      };
      if (!pick || key(c) < key(*pick)) pick = &c;
    }
    if (pick && !(pick->structure == best.info.structure)) {
      const Structure s = pick->structure;
      const RelayDesign design(grid_for(u, opt, s.L), u, y, {0}, dopt);
      std::vector<int> warm;
      best = fit_on_design(design, sums, u, y, sp, s, opt, warm, nullptr);
      best_score = score(best.info, opt);
    }
  }
  if (!std::isfinite(best_score)) {
    res.status = IdentificationStatus::NoStableModel;
    res.fitness_percent = kNaN;
    res.validation_fitness_percent = kNaN;
    res.elapsed_s =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t_start).count();
    return res;
  }

  // Estimate the initial relay memory for the chosen structure.
  if (opt.initial_memory == InitialMemory::Estimate) {
    const double before = best.info.fitness_percent;
    const PreisachGrid g = best.model.grid;
    const auto histories = initial_histories(g, u[0]);
    std::vector<Candidate> found(histories.size());
    const Eigen::VectorXd b0 = Eigen::Map<const Eigen::VectorXd>(
        best.model.b.data(), static_cast<Eigen::Index>(best.model.b.size()));
    Structure s0 = best.info.structure;
    if (identity) s0 = Structure{0, 1, 0, s0.L};
    // Candidates are independent: share them out over the cores like the grid.
    parallel_for(histories.size(), nthreads, [&](unsigned, std::size_t k) {
      const RelayDesign design(g, u, y, histories[k], dopt);
      std::vector<int> warm;
      found[k] = fit_on_design(design, sums, u, y, sp, s0, opt, warm, identity ? nullptr : &b0);
    });
    for (auto& c : found) {
      res.total_iterations += c.info.iterations;
      if (score(c.info, opt) > best_score + 1e-9) {
        best_score = score(c.info, opt);
        best = std::move(c);
      }
    }
    res.initial_memory_gain_percent = best.info.fitness_percent - before;
  }

  res.model = best.model;
  res.best = best.info;
  res.fitness_percent = best.info.fitness_percent;
  res.validation_fitness_percent = best.info.validation_fitness_percent;
  {
    std::vector<double> ue(u.begin(), u.begin() + static_cast<std::ptrdiff_t>(sp.end));
    res.identifiability = analyse_identifiability(res.model.grid, ue, res.model.initial_history);
  }
  res.elapsed_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t_start).count();
  return res;
}

}  // namespace valvediag
