#include "valvediag/autocorrelation.hpp"

#include <algorithm>
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

}  // namespace valvediag
