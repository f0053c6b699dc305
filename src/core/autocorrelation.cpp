#include "valvediag/core/autocorrelation.hpp"

#include <algorithm>
#include <cmath>
#include <complex>
#include <numeric>
#include <unsupported/Eigen/FFT>

namespace valvediag {

std::vector<double> autocorrelation(const std::vector<double>& x) {
  const std::size_t N = x.size();
  if (N == 0) return {};
  const double mean = std::accumulate(x.begin(), x.end(), 0.0) / static_cast<double>(N);
  std::size_t n = 1;
  while (n < 2 * N) n <<= 1;
  std::vector<double> padded(n, 0.0);
  for (std::size_t k = 0; k < N; ++k) padded[k] = x[k] - mean;
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

double effective_sample_size(const std::vector<double>& residual) {
  const double N = static_cast<double>(residual.size());
  const std::vector<double> r = autocorrelation(residual);
  if (r.empty()) return N;
  double tau = 1.0;
  // Lags past N/2 rest on too few pairs to count.
  for (std::size_t k = 1; k < r.size() / 2 && r[k] > 0; ++k) tau += 2.0 * r[k];
  return std::max(1.0, N / tau);
}

double effective_sample_size(const std::vector<double>& y, const std::vector<double>& y_sim,
                             std::size_t t0, std::size_t t1) {
  std::vector<double> e;
  e.reserve(t1 > t0 ? t1 - t0 : 0);
  for (std::size_t t = t0; t < t1; ++t) e.push_back(y[t] - y_sim[t]);
  return effective_sample_size(e);
}

ResidualCorrelation residual_correlation(const std::vector<double>& e, const std::vector<double>& u,
                                         std::size_t max_lag) {
  ResidualCorrelation r;
  const std::size_t N = e.size();
  r.samples = N;
  r.max_lag = max_lag;
  if (u.size() != N || N < 2 * max_lag + 2) return r;
  const std::vector<double> ae = autocorrelation(e), au = autocorrelation(u);
  if (ae.empty()) return r;  // a constant residual: nothing to test
  const double n = static_cast<double>(N);
  constexpr double z99 = 2.5758;  // the standard normal's two-sided 99 % quantile
  r.autocorrelation.assign(ae.begin(), ae.begin() + static_cast<std::ptrdiff_t>(max_lag) + 1);
  r.autocorrelation_band = z99 / std::sqrt(n);
  if (au.empty()) return r;  // a constant input: no cross-correlation
  const auto mean = [N](const std::vector<double>& x) {
    double m = 0.0;
    for (std::size_t t = 0; t < N; ++t) m += x[t];
    return m / static_cast<double>(N);
  };
  const double me = mean(e), mu = mean(u);
  double se = 0.0, su = 0.0;
  for (std::size_t t = 0; t < N; ++t) {
    se += (e[t] - me) * (e[t] - me);
    su += (u[t] - mu) * (u[t] - mu);
  }
  const double norm = std::sqrt(se * su);
  const auto M = static_cast<std::ptrdiff_t>(max_lag);
  r.cross_correlation.resize(2 * max_lag + 1);
  for (std::ptrdiff_t k = -M; k <= M; ++k) {
    double c = 0.0;
    const std::ptrdiff_t from = std::max<std::ptrdiff_t>(0, k);
    const std::ptrdiff_t to = std::min<std::ptrdiff_t>(static_cast<std::ptrdiff_t>(N),
                                                       static_cast<std::ptrdiff_t>(N) + k);
    for (std::ptrdiff_t t = from; t < to; ++t)
      c += (e[static_cast<std::size_t>(t)] - me) * (u[static_cast<std::size_t>(t - k)] - mu);
    r.cross_correlation[static_cast<std::size_t>(k + M)] = c / norm;
  }
  double p = 1.0;
  for (std::size_t k = 1; k <= max_lag; ++k) p += 2.0 * ae[k] * au[k];
  r.cross_correlation_band = z99 * std::sqrt(std::max(p, 1.0 / n) / n);
  return r;
}

}  // namespace valvediag
