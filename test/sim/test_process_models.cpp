#include <doctest/doctest.h>

#include <cmath>
#include <functional>
#include <stdexcept>

#include "valvediag/sim/process_models.hpp"

using namespace valvediag;

namespace {

// Applies a valve step of `dx` at k = 0 (from rest at x0) and compares y(k Ts) with the exact
// continuous step response `unit(t)` (response to a unit step at t = 0 without dead time).
void check_step(const ProcessSpec& spec, double Ts, int samples,
                const std::function<double(double)>& unit, double tol = 1e-9) {
  DiscreteProcess p(spec, Ts);
  const double x0 = 40.0, dx = 10.0;
  p.reset(x0);
  for (int k = 0; k < samples; ++k) {
    const double t = k * Ts;
    const double want = spec.pv0 + (t >= spec.dead_time ? dx * unit(t - spec.dead_time) : 0.0);
    CAPTURE(k);
    CHECK(std::abs(p.output() - want) <= tol);
    p.advance(x0 + dx);
  }
}

}  // namespace

TEST_CASE("First order plus dead time: exact ZOH step response") {
  const double K = 3.8163, tau = 156.46;
  const auto unit = [&](double t) { return K * (1.0 - std::exp(-t / tau)); };
  SUBCASE("dead time a multiple of Ts (the paper's 2.5 s at 0.5 s)") {
    const auto spec = first_order_process(K, tau, 2.5, 50.0);
    DiscreteProcess p(spec, 0.5);
    CHECK(p.delay_samples() == 5);
    CHECK(p.fractional_delay() == 0.0);
    check_step(spec, 0.5, 2000, unit);
  }
  SUBCASE("fractional dead time 1.3 s at Ts = 0.5 s") {
    const auto spec = first_order_process(K, tau, 1.3, 50.0);
    DiscreteProcess p(spec, 0.5);
    CHECK(p.delay_samples() == 2);
    CHECK(p.fractional_delay() == doctest::Approx(0.3));
    check_step(spec, 0.5, 2000, unit);
  }
  SUBCASE("dead time shorter than one sample") {
    check_step(first_order_process(2.0, 5.0, 0.7, -3.0), 1.0, 60,
               [](double t) { return 2.0 * (1.0 - std::exp(-t / 5.0)); });
  }
  SUBCASE("no dead time") {
    check_step(first_order_process(2.0, 5.0, 0.0), 1.0, 60,
               [](double t) { return 2.0 * (1.0 - std::exp(-t / 5.0)); });
  }
  SUBCASE("rounding in theta / Ts is not mistaken for a fractional delay") {
    DiscreteProcess p(first_order_process(1.0, 1.0, 0.3), 0.1);
    CHECK(p.delay_samples() == 3);
    CHECK(p.fractional_delay() == 0.0);
  }
}

TEST_CASE("Second order plus dead time: exact step responses") {
  SUBCASE("two time constants") {
    const double K = 1.5, t1 = 50.0, t2 = 15.0;
    check_step(second_order_process(K, t1, t2, 5.7, 10.0), 1.0, 600, [&](double t) {
      return K * (1.0 - (t1 * std::exp(-t / t1) - t2 * std::exp(-t / t2)) / (t1 - t2));
    });
  }
  SUBCASE("a third lag (tau3)") {
    const double K = 1.2, t[3] = {30.0, 20.0, 12.0};
    ProcessSpec spec = second_order_process(K, t[0], t[1], 2.5, 5.0);
    spec.tau3 = t[2];
    check_step(spec, 1.0, 600, [&](double time) {
      // 1 - sum_i tau_i^2 e^{-t/tau_i} / prod_{j != i} (tau_i - tau_j)
      double s = 0.0;
      for (int i = 0; i < 3; ++i) {
        double den = 1.0;
        for (int j = 0; j < 3; ++j)
          if (j != i) den *= t[i] - t[j];
        s += t[i] * t[i] * std::exp(-time / t[i]) / den;
      }
      return K * (1.0 - s);
    });
    CHECK(describe(spec).find("tau3=12 s") != std::string::npos);
    spec.tau3 = -1.0;
    CHECK_THROWS_AS(DiscreteProcess(spec, 1.0), std::invalid_argument);
  }
  SUBCASE("underdamped wn, zeta") {
    const double K = 0.8, wn = 0.2, z = 0.3;
    const double wd = wn * std::sqrt(1 - z * z);
    check_step(second_order_process_wn(K, wn, z, 2.25, 0.0), 0.5, 1000, [&](double t) {
      return K * (1.0 - std::exp(-z * wn * t) *
                            (std::cos(wd * t) + z / std::sqrt(1 - z * z) * std::sin(wd * t)));
    });
  }
}

TEST_CASE("Integrating process: ramp of slope K per unit of valve step") {
  SUBCASE("pure integrator with fractional dead time") {
    const double K = 0.01;
    check_step(integrating_process(K, 3.4, 0.0, 50.0), 1.0, 500, [&](double t) { return K * t; });
    DiscreteProcess p(integrating_process(K, 0.0, 0.0, 0.0), 1.0);
    p.reset(50.0);
    p.advance(51.0);
    const double y1 = p.output();
    p.advance(51.0);
    CHECK(p.output() - y1 == doctest::Approx(K));  // slope K per second per % of valve
  }
  SUBCASE("with a lag") {
    const double K = 0.02, tau = 20.0;
    check_step(integrating_process(K, 2.0, tau, 0.0), 1.0, 400,
               [&](double t) { return K * (t - tau * (1.0 - std::exp(-t / tau))); });
  }
  SUBCASE("a constant valve position at the balance point keeps PV still") {
    DiscreteProcess p(integrating_process(0.05, 1.5, 5.0, 12.0), 0.5);
    p.reset(37.0);
    for (int k = 0; k < 100; ++k) p.advance(37.0);
    CHECK(p.output() == 12.0);
  }
}

TEST_CASE("Process parameters are checked") {
  CHECK_THROWS_AS(DiscreteProcess(first_order_process(1, 0, 1), 1.0), std::invalid_argument);
  CHECK_THROWS_AS(DiscreteProcess(first_order_process(1, 10, -1), 1.0), std::invalid_argument);
  CHECK_THROWS_AS(DiscreteProcess(first_order_process(1, 10, 1), 0.0), std::invalid_argument);
  CHECK_THROWS_AS(DiscreteProcess(second_order_process(1, 10, 0, 1), 1.0), std::invalid_argument);
  CHECK_THROWS_AS(DiscreteProcess(integrating_process(1, 1, -2), 1.0), std::invalid_argument);
  CHECK(process_type_from_string("integrating") == ProcessType::integrating);
  CHECK_THROWS_AS(process_type_from_string("third-order"), std::invalid_argument);
  CHECK(describe(first_order_process(3.8163, 156.46, 2.5)) ==
        "first-order: K=3.8163, tau=156.46 s, theta=2.5 s");
}
