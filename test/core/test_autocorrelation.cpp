// The autocorrelation and the effective sample size against their closed forms.
#include <doctest/doctest.h>

#include <cmath>
#include <random>
#include <vector>

#include "valvediag/core/autocorrelation.hpp"

using namespace valvediag;

namespace {
// AR(1) noise e[t] = phi e[t-1] + w[t]: autocorrelation phi^k, integrated time (1+phi)/(1-phi).
std::vector<double> ar1(double phi, std::size_t n, unsigned seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> w(0.0, 1.0);
  std::vector<double> e(n);
  double v = 0.0;
  for (std::size_t t = 0; t < n; ++t) e[t] = v = phi * v + w(rng);
  return e;
}
}  // namespace

TEST_CASE("autocorrelation: one at lag 0, phi^k for AR(1) noise, empty for a constant") {
  const auto e = ar1(0.8, 20000, 1);
  const auto r = autocorrelation(e);
  REQUIRE(r.size() == e.size());
  CHECK(r[0] == doctest::Approx(1.0));
  for (int k = 1; k <= 5; ++k) {
    CAPTURE(k);
    CHECK(r[static_cast<std::size_t>(k)] == doctest::Approx(std::pow(0.8, k)).epsilon(0.1));
  }
  CHECK(autocorrelation(std::vector<double>(50, 3.0)).empty());
  CHECK(autocorrelation({}).empty());
}

TEST_CASE("effective sample size: N for white noise, N (1-phi)/(1+phi) for AR(1) noise") {
  for (unsigned seed = 1; seed <= 5; ++seed) {
    CAPTURE(seed);
    const std::size_t n = 5000;
    CHECK(effective_sample_size(ar1(0.0, n, seed)) == doctest::Approx(n).epsilon(0.15));
    for (const double phi : {0.5, 0.9, 0.98}) {
      CAPTURE(phi);
      const double expected = static_cast<double>(n) * (1 - phi) / (1 + phi);
      CHECK(effective_sample_size(ar1(phi, n, seed)) == doctest::Approx(expected).epsilon(0.35));
    }
  }
  CHECK(effective_sample_size(std::vector<double>(40, 1.0)) == 40.0);  // no spread: no correlation
}

TEST_CASE("residual_correlation: 99 % bands that hold for white and for coloured series") {
  constexpr std::size_t N = 20000, M = 50;
  // White residual, white input: about 1 % of the lags outside each band.
  int out_auto = 0, out_cross = 0, lags_auto = 0, lags_cross = 0;
  // Both AR(1) with phi 0.9 and independent: the cross band must widen by
  // sqrt((1 + phi^2) / (1 - phi^2)) = 3.09; the white-noise band would leave a third outside.
  int out_coloured = 0, out_naive = 0;
  for (unsigned s = 0; s < 20; ++s) {
    const auto w = ar1(0.0, N, 100 + s), v = ar1(0.0, N, 200 + s);
    const ResidualCorrelation r = residual_correlation(w, v, M);
    REQUIRE(r.autocorrelation.size() == M + 1);
    REQUIRE(r.cross_correlation.size() == 2 * M + 1);
    CHECK(r.autocorrelation_band == doctest::Approx(2.5758 / std::sqrt(double(N))));
    CHECK(r.cross_correlation_band == doctest::Approx(r.autocorrelation_band).epsilon(0.05));
    for (std::size_t k = 1; k <= M; ++k, ++lags_auto)
      out_auto += std::abs(r.autocorrelation[k]) > r.autocorrelation_band;
    for (double c : r.cross_correlation) out_cross += std::abs(c) > r.cross_correlation_band;
    lags_cross += static_cast<int>(r.cross_correlation.size());

    const auto e = ar1(0.9, N, 300 + s), u = ar1(0.9, N, 400 + s);
    const ResidualCorrelation c = residual_correlation(e, u, M);
    CHECK(c.cross_correlation_band / c.autocorrelation_band ==
          doctest::Approx(std::sqrt(1.81 / 0.19)).epsilon(0.12));
    for (double x : c.cross_correlation) {
      out_coloured += std::abs(x) > c.cross_correlation_band;
      out_naive += std::abs(x) > c.autocorrelation_band;
    }
  }
  CHECK(out_auto <= 0.025 * lags_auto);
  CHECK(out_cross <= 0.025 * lags_cross);
  CHECK(out_coloured <= 0.04 * lags_cross);
  CHECK(out_naive >= 0.2 * lags_cross);
}

TEST_CASE(
    "residual_correlation: input the model misses shows at its lag, slow error in the "
    "autocorrelation") {
  constexpr std::size_t N = 5000, M = 25;
  const auto u = ar1(0.0, N, 7), w = ar1(0.0, N, 8);
  std::vector<double> e(N);
  for (std::size_t t = 0; t < N; ++t) e[t] = w[t] + (t >= 3 ? 0.5 * u[t - 3] : 0.0);
  const ResidualCorrelation r = residual_correlation(e, u, M);
  // Corr(e(t), u(t - 3)) = 0.5 / sqrt(1.25) = 0.447; the other lags stay near 0.
  CHECK(r.cross_correlation[M + 3] == doctest::Approx(0.447).epsilon(0.05));
  CHECK(std::abs(r.cross_correlation[M - 3]) < r.cross_correlation_band);
  const ResidualCorrelation a = residual_correlation(ar1(0.95, N, 9), u, M);
  CHECK(a.autocorrelation[1] == doctest::Approx(0.95).epsilon(0.02));
  CHECK(a.autocorrelation[1] > 10 * a.autocorrelation_band);
  // Too short for the lags asked: empty, not out of bounds.
  CHECK(residual_correlation(std::vector<double>(40, 1.0), u, M).autocorrelation.empty());
}
