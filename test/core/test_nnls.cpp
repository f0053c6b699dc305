#include <doctest/doctest.h>

#include <random>

#include "valvediag/core/nnls.hpp"

using namespace valvediag;

namespace {
struct Ls {
  Eigen::MatrixXd H;
  Eigen::VectorXd f;
};
// A least-squares problem W x ~ y with n columns; `cond` stretches the singular values.
Ls random_problem(std::mt19937_64& rng, int m, int n, double cond) {
  std::normal_distribution<double> N01;
  Eigen::MatrixXd W(m, n);
  for (int i = 0; i < m; ++i)
    for (int j = 0; j < n; ++j) W(i, j) = N01(rng);
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(W, Eigen::ComputeThinU | Eigen::ComputeThinV);
  Eigen::VectorXd s(n);
  for (int j = 0; j < n; ++j) s[j] = std::pow(cond, -static_cast<double>(j) / std::max(1, n - 1));
  W = svd.matrixU() * s.asDiagonal() * svd.matrixV().transpose();
  Eigen::VectorXd y(m);
  for (int i = 0; i < m; ++i) y[i] = N01(rng);
  return {W.transpose() * W, W.transpose() * y};
}
}  // namespace

TEST_CASE("NNLS satisfies the KKT conditions on random problems") {
  std::mt19937_64 rng(42);
  for (double cond : {1.0, 1e3, 1e6}) {
    for (int trial = 0; trial < 40; ++trial) {
      const int n = 5 + trial % 30, nfree = trial % 4;
      auto p = random_problem(rng, 3 * n, n, cond);
      NonnegativeQp qp(p.H, p.f, std::min(nfree, n));
      auto r = qp.solve();
      CHECK(r.status == SolverStatus::Converged);
      CHECK(qp.kkt_violation(r.x) < 1e-8 * cond);
      for (int i = qp.n_free(); i < n; ++i) CHECK(r.x[i] >= 0.0);
    }
  }
}

TEST_CASE("NNLS matches brute force on small problems") {
  std::mt19937_64 rng(9);
  for (int trial = 0; trial < 60; ++trial) {
    const int n = 2 + trial % 5;
    auto p = random_problem(rng, 2 * n, n, 10.0);
    NonnegativeQp qp(p.H, p.f, 0);
    auto r = qp.solve();
    // Enumerate every support; keep the best feasible unconstrained solution on it.
    double best = 0.0;  // x = 0
    for (int mask = 1; mask < (1 << n); ++mask) {
      std::vector<int> idx;
      for (int i = 0; i < n; ++i)
        if (mask & (1 << i)) idx.push_back(i);
      const auto k = static_cast<Eigen::Index>(idx.size());
      Eigen::MatrixXd A(k, k);
      Eigen::VectorXd b(k);
      for (Eigen::Index a = 0; a < k; ++a) {
        b[a] = p.f[idx[static_cast<std::size_t>(a)]];
        for (Eigen::Index c = 0; c < k; ++c)
          A(a, c) = p.H(idx[static_cast<std::size_t>(a)], idx[static_cast<std::size_t>(c)]);
      }
      Eigen::VectorXd z = A.ldlt().solve(b);
      if (z.minCoeff() < 0) continue;
      Eigen::VectorXd x = Eigen::VectorXd::Zero(n);
      for (Eigen::Index a = 0; a < k; ++a) x[idx[static_cast<std::size_t>(a)]] = z[a];
      best = std::min(best, qp.objective(x));
    }
    CHECK(qp.objective(r.x) == doctest::Approx(best).epsilon(1e-9).scale(1.0));
  }
}

TEST_CASE("warm start reaches the same solution") {
  std::mt19937_64 rng(1);
  auto p = random_problem(rng, 90, 30, 100.0);
  NonnegativeQp qp(p.H, p.f, 2);
  auto cold = qp.solve();
  auto warm = qp.solve(qp.passive_set(cold.x));
  CHECK((warm.x - cold.x).norm() < 1e-9 * (1 + cold.x.norm()));
  CHECK(warm.iterations <= 2);
  // A wrong warm start (everything passive) still ends at the optimum.
  std::vector<int> all;
  for (int i = 2; i < 30; ++i) all.push_back(i);
  auto wrong = qp.solve(all);
  CHECK((wrong.x - cold.x).norm() < 1e-7 * (1 + cold.x.norm()));
}

TEST_CASE("budget: inactive leaves the solution, active meets it exactly with KKT") {
  std::mt19937_64 rng(77);
  for (int trial = 0; trial < 30; ++trial) {
    const int n = 8 + trial % 20, nfree = trial % 3;
    auto p = random_problem(rng, 3 * n, n, trial % 2 ? 1e4 : 10.0);
    NonnegativeQp qp(p.H, p.f, nfree);
    auto r = qp.solve();
    const double total = r.x.tail(n - nfree).sum();
    if (!(total > 0)) continue;
    auto path = qp.solve_budgets(r, {1.5 * total, total, 0.97 * total, 0.95 * total, 0.5 * total});
    REQUIRE(path.size() == 5);
    CHECK((path[0].x - r.x).norm() < 1e-12 * (1 + r.x.norm()));  // inactive
    CHECK(path[0].lambda == 0.0);
    const double targets[] = {1.5, 1.0, 0.97, 0.95, 0.5};
    for (int k = 2; k < 5; ++k) {
      const auto& s = path[static_cast<std::size_t>(k)];
      CHECK(s.x.tail(n - nfree).sum() == doctest::Approx(targets[k] * total).epsilon(1e-8));
      CHECK(s.x.tail(n - nfree).minCoeff() >= 0.0);
      CHECK(s.lambda > 0.0);
      CHECK(qp.kkt_violation(s.x, s.lambda) < 1e-7);
    }
    // Tighter budgets never lower the objective's minimum.
    for (int k = 1; k < 5; ++k)
      CHECK(qp.objective(path[static_cast<std::size_t>(k)].x) >=
            qp.objective(path[static_cast<std::size_t>(k - 1)].x) - 1e-9);
  }
}

TEST_CASE("budgeted solution matches a penalized NNLS with the same multiplier") {
  std::mt19937_64 rng(5);
  auto p = random_problem(rng, 60, 20, 50.0);
  NonnegativeQp qp(p.H, p.f, 1);
  auto r = qp.solve();
  const double total = r.x.tail(19).sum();
  auto s = qp.solve_budgets(r, {0.9 * total})[0];
  Eigen::VectorXd f2 = p.f;
  f2.tail(19).array() -= s.lambda;
  NonnegativeQp pen(p.H, f2, 1);
  auto q = pen.solve();
  CHECK((q.x - s.x).norm() < 1e-7 * (1 + s.x.norm()));
}

TEST_CASE("invalid problems are rejected") {
  CHECK_THROWS_AS(NonnegativeQp(Eigen::MatrixXd::Identity(2, 3), Eigen::VectorXd::Zero(2), 0),
                  std::invalid_argument);
  Eigen::MatrixXd H = Eigen::MatrixXd::Identity(2, 2);
  H(0, 0) = std::numeric_limits<double>::quiet_NaN();
  CHECK_THROWS_AS(NonnegativeQp(H, Eigen::VectorXd::Zero(2), 0), std::invalid_argument);
}
