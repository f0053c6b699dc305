// Loop-health figures on signals whose answer is known: a sine's period, a triangle's reversals
// and travel, time pinned at a limit; and the reasons a record cannot carry a model.
#include <doctest/doctest.h>

#include <cmath>
#include <random>

#include "valvediag/loop_health.hpp"

using namespace valvediag;

namespace {

LoopData make(std::size_t n, double Ts) {
  LoopData d;
  for (std::size_t k = 0; k < n; ++k) d.t.push_back(static_cast<double>(k) * Ts);
  d.op.assign(n, 50.0);
  d.pv.assign(n, 0.0);
  d.sp.assign(n, 0.0);
  return d;
}

double triangle(double t, double period, double lo, double hi) {
  const double p = std::fmod(t, period) / period;
  return lo + (hi - lo) * (p < 0.5 ? 2 * p : 2 - 2 * p);
}

}  // namespace

TEST_CASE("an oscillating control error: period found, regular") {
  for (double period : {20.0, 60.0, 150.0}) {
    CAPTURE(period);
    std::mt19937_64 rng(7);
    std::normal_distribution<double> noise(0.0, 0.2);
    LoopData d = make(4000, 1.0);
    for (std::size_t k = 0; k < d.size(); ++k) {
      d.pv[k] = std::sin(2 * M_PI * d.t[k] / period) + noise(rng);
      d.op[k] = 50 + 5 * std::cos(2 * M_PI * d.t[k] / period);
    }
    const LoopHealth h = loop_health(d);
    CHECK(h.oscillating);
    CHECK(h.period_s == doctest::Approx(period).epsilon(0.03));
    CHECK(h.regularity > 1.0);
    CHECK(h.amplitude == doctest::Approx(1.0).epsilon(0.1));  // sqrt(1 + 2 * 0.04) ~ 1.04
    CHECK(h.signal == "sp-pv");
  }
}

TEST_CASE("white noise and a random walk are not called oscillating") {
  int called = 0;
  for (std::uint64_t seed = 1; seed <= 20; ++seed) {
    std::mt19937_64 rng(seed);
    std::normal_distribution<double> noise(0.0, 1.0);
    LoopData d = make(3000, 1.0);
    double walk = 0;
    for (std::size_t k = 0; k < d.size(); ++k) {
      walk += 0.1 * noise(rng);
      d.pv[k] = (seed % 2 ? noise(rng) : walk);
      d.op[k] = 50 + noise(rng);
    }
    called += loop_health(d).oscillating ? 1 : 0;
  }
  CHECK(called <= 1);  // regularity > 1 by chance is rare, not impossible
}

TEST_CASE("a triangle OP: reversals and travel per hour, noise does not add reversals") {
  std::mt19937_64 rng(3);
  std::normal_distribution<double> noise(0.0, 0.05);
  LoopData d = make(3600, 1.0);  // one hour
  for (std::size_t k = 0; k < d.size(); ++k) d.op[k] = triangle(d.t[k], 100.0, 40, 60) + noise(rng);
  for (std::size_t k = 0; k < d.size(); ++k) d.pv[k] = d.op[k];
  const LoopHealth h = loop_health(d);
  CHECK(h.op_reversals_per_hour == doctest::Approx(72).epsilon(0.03));  // two per 100 s period
  CHECK(h.op_travel_percent_per_hour == doctest::Approx(72 * 20).epsilon(0.03));
  CHECK(h.op_noise == doctest::Approx(0.05).epsilon(0.3));
  CHECK(h.time_at_limits_percent == 0.0);
  CHECK(h.op_span_percent == doctest::Approx(20).epsilon(0.05));
}

TEST_CASE("time at the OP limits counts samples within 0.5 % of either end of the range") {
  LoopData d = make(1000, 1.0);
  for (std::size_t k = 0; k < d.size(); ++k) {
    d.op[k] = k < 300 ? 100.0 : (k < 400 ? -0.2 : 50 + (k % 7));
    d.pv[k] = static_cast<double>(k % 13);
  }
  CHECK(loop_health(d).time_at_limits_percent == doctest::Approx(40.0));
  // A valve with a 20..80 % span: OP 100 and -0.2 are beyond it, also at a limit.
  CHECK(loop_health(d, OpRange{20, 80}).time_at_limits_percent == doctest::Approx(40.0));
}

TEST_CASE("unusable records are named with what is wrong") {
  std::mt19937_64 rng(5);
  std::normal_distribution<double> noise(0.0, 0.1);
  LoopData good = make(1200, 1.0);
  for (std::size_t k = 0; k < good.size(); ++k) {
    good.op[k] = triangle(good.t[k], 120.0, 30, 70) + noise(rng);
    good.pv[k] = good.op[k] + noise(rng);
  }
  CHECK(unusable_reason(good, loop_health(good)) == "");

  LoopData shortd = good;
  shortd.t.resize(150);
  shortd.op.resize(150);
  shortd.pv.resize(150);
  shortd.sp.resize(150);
  CHECK(unusable_reason(shortd, loop_health(shortd)).find("only 150 samples") == 0);

  LoopData idle = good;
  for (auto& u : idle.op) u = 42.0 + 0.01 * noise(rng);
  CHECK(unusable_reason(idle, loop_health(idle)).find("OP does not move") == 0);

  LoopData flat = good;
  for (auto& y : flat.pv) y = 3.0;
  CHECK(unusable_reason(flat, loop_health(flat)).find("PV does not change") == 0);

  LoopData ramp = good;  // one move up: no reversal
  for (std::size_t k = 0; k < ramp.size(); ++k) ramp.op[k] = 20 + 0.03 * static_cast<double>(k);
  CHECK(unusable_reason(ramp, loop_health(ramp)).find("OP reverses 0 times") == 0);

  LoopData pinned = good;
  for (std::size_t k = 0; k < pinned.size(); ++k)
    pinned.op[k] = k % 100 < 2 ? 99.0 + (k % 2) : 100.0;
  CHECK(unusable_reason(pinned, loop_health(pinned)).find("OP sits at its limits") == 0);
}
