#include <doctest/doctest.h>

#include <cmath>
#include <random>
#include <stdexcept>

#include "valvediag/diagnose/residual_analysis.hpp"

using namespace valvediag;

namespace {

// A triangle OP between 40 and 60 with a period of `period` samples, plus small noise.
std::vector<double> triangle(std::size_t n, std::size_t period, std::mt19937_64& rng) {
  std::normal_distribution<double> e(0, 0.02);
  std::vector<double> u(n);
  for (std::size_t t = 0; t < n; ++t) {
    const double ph = static_cast<double>(t % period) / static_cast<double>(period);
    u[t] = 40 + 20 * (ph < 0.5 ? 2 * ph : 2 - 2 * ph) + e(rng);
  }
  return u;
}

struct Case {
  std::vector<double> u, y, ys;
};

// y_sim = 0, y = residual: the analysis only looks at y - y_sim.
Case with_residual(const std::vector<double>& u, const std::vector<double>& r) {
  return {u, r, std::vector<double>(r.size(), 0.0)};
}

double score(const ResidualAnalysis& a, const char* name) {
  const auto* t = a.test(name);
  REQUIRE(t != nullptr);
  return t->score;
}

}  // namespace

TEST_CASE("white residual: no test fires, the noise level is found") {
  std::mt19937_64 rng(1);
  const auto u = triangle(4000, 200, rng);
  std::normal_distribution<double> e(0, 0.5);
  std::vector<double> r(u.size());
  for (auto& v : r) v = e(rng);
  const auto c = with_residual(u, r);
  const auto a = analyse_residual(c.u, c.y, c.ys, 0, u.size());
  CHECK(a.noise_level == doctest::Approx(0.5).epsilon(0.1));
  CHECK(a.rms == doctest::Approx(0.5).epsilon(0.05));
  CHECK(a.reversals >= 35);
  CHECK(a.reversals <= 41);
  for (const auto& t : a.tests) {
    CAPTURE(t.name);
    CAPTURE(t.detail);
    CHECK(t.score < 0.25);
  }
  CHECK(a.intervals.size() <= 2);
}

TEST_CASE("residual spikes after reversals point to stiction/deadband") {
  std::mt19937_64 rng(2);
  const auto u = triangle(4000, 200, rng);
  std::normal_distribution<double> e(0, 0.2);
  std::vector<double> r(u.size());
  for (std::size_t t = 0; t < r.size(); ++t) {
    const std::size_t ph = t % 100;  // reversals every 100 samples
    r[t] = e(rng) + (ph < 20 ? 3.0 * std::exp(-static_cast<double>(ph) / 8.0) : 0.0);
  }
  const auto c = with_residual(u, r);
  const auto a = analyse_residual(c.u, c.y, c.ys, 0, u.size());
  CHECK(score(a, "reversal-locked") > 0.8);
  // The region right after reversals carries far more than its share of the error.
  bool found = false;
  for (const auto& g : a.regions)
    if (g.kind == "since-reversal" && g.lo == 0.0) {
      CHECK(g.excess > 2.0);
      found = true;
    }
  CHECK(found);
}

TEST_CASE("error that grows with OP level points to characteristic/preisach/saturation") {
  std::mt19937_64 rng(3);
  const auto u = triangle(4000, 400, rng);
  std::normal_distribution<double> e(0, 0.2);
  std::vector<double> r(u.size());
  for (std::size_t t = 0; t < r.size(); ++t)
    r[t] = 0.05 * (u[t] - 50) * (u[t] - 50) / 10 - 0.17 + e(rng);
  const auto c = with_residual(u, r);
  const auto a = analyse_residual(c.u, c.y, c.ys, 0, u.size());
  CHECK(score(a, "op-level") > 0.8);
  CHECK(score(a, "direction") < 0.2);  // symmetric in direction
}

TEST_CASE("error that depends on the direction of travel points to preisach/stiction") {
  std::mt19937_64 rng(4);
  const auto u = triangle(4000, 400, rng);
  std::normal_distribution<double> e(0, 0.2);
  std::vector<double> r(u.size());
  for (std::size_t t = 0; t < r.size(); ++t) {
    const bool rising = (t % 400) < 200;
    r[t] = (rising ? 1.0 : -1.0) * (u[t] > 50 ? 1.0 : 0.2) + e(rng);
  }
  const auto c = with_residual(u, r);
  const auto a = analyse_residual(c.u, c.y, c.ys, 0, u.size());
  CHECK(score(a, "direction") > 0.8);
}

TEST_CASE("one-sided error at the top of the OP range points to saturation") {
  std::mt19937_64 rng(5);
  const auto u = triangle(4000, 400, rng);
  std::normal_distribution<double> e(0, 0.2);
  std::vector<double> r(u.size());
  for (std::size_t t = 0; t < r.size(); ++t) r[t] = e(rng) + (u[t] > 57 ? -2.0 * (u[t] - 57) : 0.0);
  const auto c = with_residual(u, r);
  const auto a = analyse_residual(c.u, c.y, c.ys, 0, u.size());
  CHECK(score(a, "one-sided-at-limit") > 0.8);
  CHECK(a.test("one-sided-at-limit")->detail.find("OP >=") != std::string::npos);
}

TEST_CASE("residual following OP moves at a long lag points to delay") {
  std::mt19937_64 rng(6);
  std::normal_distribution<double> e(0, 1.0), w(0, 0.1);
  std::vector<double> u(4000), r(4000, 0.0);
  u[0] = 50;
  for (std::size_t t = 1; t < u.size(); ++t) u[t] = u[t - 1] + e(rng) - 0.01 * (u[t - 1] - 50);
  for (std::size_t t = 12; t < r.size(); ++t) r[t] = 0.5 * (u[t - 10] - u[t - 11]) + w(rng);
  const auto c = with_residual(u, r);
  ResidualAnalysisOptions o;
  o.model_delay = 3;
  const auto a = analyse_residual(c.u, c.y, c.ys, 0, u.size(), o);
  CHECK(score(a, "input-correlation-long") > 0.9);
  CHECK(a.test("input-correlation-long")->detail.find("lag 10") != std::string::npos);
  CHECK(score(a, "input-correlation-short") < 0.3);
}

TEST_CASE("slow drift of the residual points to disturbance/integrator; whiteness fails") {
  std::mt19937_64 rng(7);
  const auto u = triangle(4000, 200, rng);
  std::normal_distribution<double> e(0, 0.2), walk(0, 0.08);
  std::vector<double> r(u.size());
  double d = 0;
  for (std::size_t t = 0; t < r.size(); ++t) {
    d += walk(rng);
    r[t] = d + e(rng);
  }
  const auto c = with_residual(u, r);
  const auto a = analyse_residual(c.u, c.y, c.ys, 0, u.size());
  CHECK(score(a, "low-frequency") > 0.7);
  CHECK(score(a, "whiteness") > 0.7);
}

TEST_CASE("a burst of error is reported as the worst interval") {
  std::mt19937_64 rng(8);
  const auto u = triangle(3000, 300, rng);
  std::normal_distribution<double> e(0, 0.2);
  std::vector<double> r(u.size());
  for (std::size_t t = 0; t < r.size(); ++t) r[t] = e(rng) + (t >= 1200 && t < 1350 ? 2.5 : 0.0);
  const auto c = with_residual(u, r);
  const auto a = analyse_residual(c.u, c.y, c.ys, 100, u.size());
  REQUIRE(!a.intervals.empty());
  const auto& iv = a.intervals.front();
  CHECK(iv.begin >= 1180);
  CHECK(iv.begin <= 1215);
  CHECK(iv.end >= 1335);
  CHECK(iv.end <= 1370);
  CHECK(iv.share > 0.8);
}

TEST_CASE("reversals ignore OP noise and bad windows are refused") {
  std::vector<double> u{0, 1, 2, 3, 2.95, 3.02, 2, 1, 0, 1, 2};
  const auto rev = op_reversals(u, 0, u.size(), 0.5);
  REQUIRE(rev.size() == 2);
  CHECK(rev[0] == 5);
  CHECK(rev[1] == 8);
  std::vector<double> s(10, 0.0);
  CHECK_THROWS_AS(analyse_residual(s, s, s, 0, 10), std::invalid_argument);
  std::vector<double> s2(30, 0.0), s3(29, 0.0);
  CHECK_THROWS_AS(analyse_residual(s2, s2, s3, 0, 30), std::invalid_argument);
}
