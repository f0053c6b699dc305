// Nonnegative least squares on the Gram matrix, with free variables and an exact L1 budget.
//
//   minimize 0.5 x'Hx - f'x   s.t. x_i >= 0 for i >= n_free,   sum_{i >= n_free} x_i <= eta
//
// H = W'W, f = W'y of a least-squares problem ||y - Wx||^2 (so the data never enters here).
// Active set method of Lawson and Hanson on the Gram matrix, warm-startable from a passive set.
// The budget is handled by following the exact, piecewise-linear homotopy of the Lagrangian
// problem (f - lambda * 1 on the constrained part) from the unbudgeted solution.
#pragma once

#include <Eigen/Dense>
#include <vector>

namespace valvediag {

// How the solver ended, kept apart from whether the call itself was valid (invalid input throws).
enum class SolverStatus { Converged, IterationLimit, NumericalTrouble };
const char* to_string(SolverStatus s);

struct NnlsResult {
  Eigen::VectorXd x;
  SolverStatus status = SolverStatus::Converged;
  int iterations = 0;
  double lambda = 0.0;  // budget multiplier (0 when the budget is inactive)
};

class NonnegativeQp {
 public:
  // H must be symmetric positive semidefinite, n x n; f of length n; 0 <= n_free <= n.
  NonnegativeQp(Eigen::MatrixXd H, Eigen::VectorXd f, int n_free);

  // Solves without budget. `warm_passive`: constrained indices believed to be positive.
  NnlsResult solve(const std::vector<int>& warm_passive = {}, int max_iterations = -1) const;

  // Solutions for budgets eta_1 >= eta_2 >= ... (sorted descending on input), each exact,
  // obtained along one homotopy path starting from `unbudgeted` (the result of solve()).
  std::vector<NnlsResult> solve_budgets(const NnlsResult& unbudgeted,
                                        const std::vector<double>& etas) const;

  // Largest violation of the KKT conditions at x for budget multiplier lambda (for tests).
  double kkt_violation(const Eigen::VectorXd& x, double lambda = 0.0) const;
  // Objective 0.5 x'Hx - f'x.
  double objective(const Eigen::VectorXd& x) const;
  int size() const { return static_cast<int>(f_.size()); }
  int n_free() const { return n_free_; }
  // Passive (positive) constrained indices of x.
  std::vector<int> passive_set(const Eigen::VectorXd& x) const;

 private:
  // Solves H_PP z = rhs_P on the index set P; false when numerically singular.
  bool solve_on(const std::vector<int>& P, const Eigen::VectorXd& rhs, Eigen::VectorXd& z) const;

  Eigen::MatrixXd H_;
  Eigen::VectorXd f_;
  int n_free_;
  double tol_;
};

}  // namespace valvediag
