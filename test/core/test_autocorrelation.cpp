// The autocorrelation and the effective sample size against their closed forms.
#include <doctest/doctest.h>

#include <cmath>
#include <random>
#include <vector>

#include "valvediag/autocorrelation.hpp"

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
