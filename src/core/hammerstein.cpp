#include "valvediag/core/hammerstein.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>

namespace valvediag {

std::vector<double> simulate_valve(const HammersteinModel& m, const std::vector<double>& u) {
  PreisachModel p(m.grid, m.mu, 0.0);
  return p.simulate(u, m.initial_history);
}

std::vector<double> simulate_arx(const HammersteinModel& m, const std::vector<double>& x,
                                 const std::vector<double>& y, std::size_t t0) {
  const std::size_t N = x.size();
  std::vector<double> ys(N, 0.0);
  if (m.block == LinearBlock::Identity) {
    for (std::size_t t = 0; t < N; ++t) ys[t] = x[t] + m.c;
    return ys;
  }
  const int na = static_cast<int>(m.a.size());
  const int nb = static_cast<int>(m.b.size());
  const int nk = m.structure.nk;
  for (std::size_t t = 0; t < std::min(t0, N); ++t) ys[t] = y[t];
  for (std::size_t t = t0; t < N; ++t) {
    double v = m.c;
    for (int i = 1; i <= na; ++i)
      if (t >= static_cast<std::size_t>(i))
        v -= m.a[static_cast<std::size_t>(i - 1)] * ys[t - static_cast<std::size_t>(i)];
    for (int k = 1; k <= nb; ++k) {
      const std::size_t d = static_cast<std::size_t>(nk + k);
      if (t >= d) v += m.b[static_cast<std::size_t>(k - 1)] * x[t - d];
    }
    ys[t] = v;
  }
  return ys;
}

std::vector<double> simulate_output(const HammersteinModel& m, const std::vector<double>& u,
                                    const std::vector<double>& y, std::size_t t0) {
  return simulate_arx(m, simulate_valve(m, u), y, t0);
}

double fitness_percent(const std::vector<double>& y, const std::vector<double>& ys,
                       std::size_t from, std::size_t to) {
  to = std::min({to, y.size(), ys.size()});
  if (from >= to) return std::numeric_limits<double>::quiet_NaN();
  double mean = 0.0;
  for (std::size_t t = from; t < to; ++t) mean += y[t];
  mean /= static_cast<double>(to - from);
  double num = 0.0, den = 0.0;
  for (std::size_t t = from; t < to; ++t) {
    num += (ys[t] - y[t]) * (ys[t] - y[t]);
    den += (y[t] - mean) * (y[t] - mean);
  }
  if (!(den > 0) || !std::isfinite(num)) return std::numeric_limits<double>::quiet_NaN();
  return (1.0 - std::sqrt(num / den)) * 100.0;
}

std::optional<std::vector<std::complex<double>>> poles_of(const std::vector<double>& a) {
  const auto na = static_cast<Eigen::Index>(a.size());
  if (na == 0) return std::vector<std::complex<double>>{};
  // Companion matrix of z^na + a1 z^(na-1) + ... + a_na.
  Eigen::MatrixXd C = Eigen::MatrixXd::Zero(na, na);
  for (Eigen::Index i = 0; i < na; ++i) C(0, i) = -a[static_cast<std::size_t>(i)];
  for (Eigen::Index i = 1; i < na; ++i) C(i, i - 1) = 1.0;
  Eigen::EigenSolver<Eigen::MatrixXd> es(C, false);
  if (es.info() != Eigen::Success) return std::nullopt;
  const Eigen::VectorXcd& ev = es.eigenvalues();
  return std::vector<std::complex<double>>(ev.data(), ev.data() + ev.size());
}

double spectral_radius(const std::vector<double>& a) {
  if (a.empty()) return 0.0;
  const auto p = poles_of(a);
  if (!p) return std::numeric_limits<double>::infinity();
  double r = 0.0;
  for (const auto& z : *p) r = std::max(r, std::abs(z));
  return r;
}

bool is_stable(const std::vector<double>& a, double margin) {
  for (double v : a)
    if (!std::isfinite(v)) return false;
  return spectral_radius(a) < 1.0 - margin;
}

}  // namespace valvediag
