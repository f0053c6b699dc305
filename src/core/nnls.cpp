#include "valvediag/core/nnls.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace valvediag {

const char* to_string(SolverStatus s) {
  switch (s) {
    case SolverStatus::Converged:
      return "converged";
    case SolverStatus::IterationLimit:
      return "iteration limit";
    case SolverStatus::NumericalTrouble:
      return "numerical trouble";
  }
  return "unknown";
}

NonnegativeQp::NonnegativeQp(Eigen::MatrixXd H, Eigen::VectorXd f, int n_free)
    : H_(std::move(H)), f_(std::move(f)), n_free_(n_free) {
  const auto n = f_.size();
  if (H_.rows() != n || H_.cols() != n || n_free_ < 0 || n_free_ > n) {
    throw std::invalid_argument("NonnegativeQp: H must be n x n, f of length n, 0 <= n_free <= n");
  }
  if (!H_.allFinite() || !f_.allFinite()) {
    throw std::invalid_argument("NonnegativeQp: H and f must be finite");
  }
  const double scale = n > 0 ? H_.diagonal().cwiseAbs().maxCoeff() : 1.0;
  tol_ = 1e-11 * std::max(scale, 1e-300) * std::max<double>(1.0, static_cast<double>(n));
}

double NonnegativeQp::objective(const Eigen::VectorXd& x) const {
  return 0.5 * x.dot(H_ * x) - f_.dot(x);
}

std::vector<int> NonnegativeQp::passive_set(const Eigen::VectorXd& x) const {
  std::vector<int> P;
  for (int i = n_free_; i < size(); ++i)
    if (x[i] > 0) P.push_back(i);
  return P;
}

bool NonnegativeQp::solve_on(const std::vector<int>& P, const Eigen::VectorXd& rhs,
                             Eigen::VectorXd& z) const {
  const auto m = static_cast<Eigen::Index>(P.size());
  z.setZero(size());
  if (m == 0) return true;
  Eigen::MatrixXd A(m, m);
  Eigen::VectorXd b(m);
  for (Eigen::Index r = 0; r < m; ++r) {
    b[r] = rhs[P[r]];
    for (Eigen::Index c = 0; c < m; ++c) A(r, c) = H_(P[r], P[c]);
  }
  // A tiny relative ridge keeps exactly collinear relays (identical histories) solvable; it
  // changes the optimum far below the data's noise.
  const double ridge = 1e-12 * std::max(A.diagonal().cwiseAbs().maxCoeff(), 1e-300);
  A.diagonal().array() += ridge;
  Eigen::LLT<Eigen::MatrixXd> llt(A);
  if (llt.info() != Eigen::Success) return false;
  Eigen::VectorXd sol = llt.solve(b);
  if (!sol.allFinite()) return false;
  for (Eigen::Index r = 0; r < m; ++r) z[P[r]] = sol[r];
  return true;
}

NnlsResult NonnegativeQp::solve(const std::vector<int>& warm_passive, int max_iterations) const {
  const int n = size();
  if (max_iterations < 0) max_iterations = 3 * n + 30;
  NnlsResult res;
  std::vector<char> in_p(static_cast<std::size_t>(n), 0);
  for (int i = 0; i < n_free_; ++i) in_p[static_cast<std::size_t>(i)] = 1;
  for (int i : warm_passive)
    if (i >= n_free_ && i < n) in_p[static_cast<std::size_t>(i)] = 1;

  auto set_of = [&] {
    std::vector<int> P;
    for (int i = 0; i < n; ++i)
      if (in_p[static_cast<std::size_t>(i)]) P.push_back(i);
    return P;
  };

  Eigen::VectorXd x = Eigen::VectorXd::Zero(n);
  Eigen::VectorXd z;
  int it = 0;
  bool first = true;
  while (true) {
    if (!first) {
      // Add the constrained variable with the most positive gradient (Lawson-Hanson).
      const Eigen::VectorXd w = f_ - H_ * x;
      int best = -1;
      double wmax = tol_;
      for (int i = n_free_; i < n; ++i)
        if (!in_p[static_cast<std::size_t>(i)] && w[i] > wmax) {
          wmax = w[i];
          best = i;
        }
      if (best < 0) break;  // KKT satisfied
      in_p[static_cast<std::size_t>(best)] = 1;
    }
    first = false;
    // Inner loop: keep the iterate feasible while solving on the passive set.
    while (true) {
      if (++it > max_iterations) {
        res.status = SolverStatus::IterationLimit;
        res.x = x;
        res.iterations = it;
        return res;
      }
      if (!solve_on(set_of(), f_, z)) {
        res.status = SolverStatus::NumericalTrouble;
        res.x = x;
        res.iterations = it;
        return res;
      }
      double alpha = 1.0;
      bool blocked = false;
      for (int i = n_free_; i < n; ++i) {
        if (in_p[static_cast<std::size_t>(i)] && z[i] <= 0) {
          const double denom = x[i] - z[i];
          const double a = denom > 0 ? x[i] / denom : 0.0;
          if (a < alpha) alpha = a;
          blocked = true;
        }
      }
      if (!blocked) {
        x = z;
        break;
      }
      x += alpha * (z - x);
      for (int i = n_free_; i < n; ++i)
        if (in_p[static_cast<std::size_t>(i)] && x[i] <= tol_ * 1e-3) {
          in_p[static_cast<std::size_t>(i)] = 0;
          x[i] = 0;
        }
    }
  }
  res.x = x;
  res.iterations = it;
  return res;
}

std::vector<NnlsResult> NonnegativeQp::solve_budgets(const NnlsResult& start,
                                                     std::vector<double> const& etas_in) const {
  std::vector<double> etas = etas_in;
  std::sort(etas.begin(), etas.end(), std::greater<>());
  const int n = size();
  std::vector<NnlsResult> out;
  out.reserve(etas.size());
  Eigen::VectorXd x = start.x;
  double lambda = 0.0;
  auto budget_sum = [&](const Eigen::VectorXd& v) { return v.tail(n - n_free_).sum(); };
  Eigen::VectorXd e = Eigen::VectorXd::Zero(n);
  e.tail(n - n_free_).setOnes();
  std::vector<char> in_p(static_cast<std::size_t>(n), 0);
  for (int i = 0; i < n; ++i) in_p[static_cast<std::size_t>(i)] = (i < n_free_ || x[i] > 0);
  int it = 0;
  const int max_it = 4 * n + 50;
  SolverStatus status = start.status;

  for (double eta : etas) {
    // Move lambda up until sum(x) == eta; each segment keeps the passive set fixed.
    while (budget_sum(x) > eta + 1e-12 * std::max(1.0, std::abs(eta))) {
      if (++it > max_it) {
        status = SolverStatus::IterationLimit;
        break;
      }
      std::vector<int> P;
      for (int i = 0; i < n; ++i)
        if (in_p[static_cast<std::size_t>(i)]) P.push_back(i);
      Eigen::VectorXd d;
      if (!solve_on(P, e, d)) {
        status = SolverStatus::NumericalTrouble;
        break;
      }
      // x(lambda + s) = x - s d on P.
      const double slope = e.dot(d);  // decrease of sum(x) per unit of lambda
      if (!(slope > 0)) {
        status = SolverStatus::NumericalTrouble;
        break;
      }
      double step = (budget_sum(x) - eta) / slope;
      int leave = -1, enter = -1;
      for (int i : P)
        if (i >= n_free_ && d[i] > 0) {
          const double s = x[i] / d[i];
          if (s < step) {
            step = s;
            leave = i;
            enter = -1;
          }
        }
      const Eigen::VectorXd w = f_ - lambda * e - H_ * x;  // gradient of the Lagrangian
      const Eigen::VectorXd Hd = H_ * d;
      for (int j = n_free_; j < n; ++j) {
        if (in_p[static_cast<std::size_t>(j)]) continue;
        const double rate = Hd[j] - 1.0;  // dw_j / dlambda
        if (rate > 0) {
          const double s = std::max(0.0, -w[j]) / rate;
          if (s < step) {
            step = s;
            enter = j;
            leave = -1;
          }
        }
      }
      x -= step * d;
      lambda += step;
      if (leave >= 0) {
        in_p[static_cast<std::size_t>(leave)] = 0;
        x[leave] = 0;
      }
      if (enter >= 0) in_p[static_cast<std::size_t>(enter)] = 1;
      for (int i = n_free_; i < n; ++i)
        if (x[i] < 0) x[i] = 0;  // round-off only
    }
    NnlsResult r;
    r.x = x;
    r.lambda = lambda;
    r.iterations = it;
    r.status = status;
    out.push_back(r);
  }
  return out;
}

double NonnegativeQp::kkt_violation(const Eigen::VectorXd& x, double lambda) const {
  const Eigen::VectorXd w = f_ - H_ * x;  // negative gradient of the objective
  double v = 0.0;
  const double scale = std::max({1.0, f_.cwiseAbs().maxCoeff(), H_.cwiseAbs().maxCoeff()});
  for (int i = 0; i < size(); ++i) {
    if (i < n_free_) {
      v = std::max(v, std::abs(w[i]));
    } else {
      const double wi = w[i] - lambda;
      v = std::max(v, std::max(0.0, -x[i]) * scale);
      v = std::max(v, x[i] > 0 ? std::abs(wi) : std::max(0.0, wi));
    }
  }
  return v / scale;
}

}  // namespace valvediag
