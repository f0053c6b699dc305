#include <doctest/doctest.h>

#include <cmath>
#include <numeric>
#include <stdexcept>
#include <vector>

#include "valvediag/sim/loop_simulator.hpp"

using namespace valvediag;

namespace {

double mean(const std::vector<double>& v, std::size_t from, std::size_t to) {
  return std::accumulate(v.begin() + static_cast<std::ptrdiff_t>(from),
                         v.begin() + static_cast<std::ptrdiff_t>(to), 0.0) /
         static_cast<double>(to - from);
}

// Sample standard deviation and lag-1 autocorrelation of v[from, to).
void moments(const std::vector<double>& v, std::size_t from, std::size_t to, double& sd,
             double& r1) {
  const double m = mean(v, from, to);
  double c0 = 0, c1 = 0;
  for (std::size_t k = from; k < to; ++k) {
    c0 += (v[k] - m) * (v[k] - m);
    if (k + 1 < to) c1 += (v[k] - m) * (v[k + 1] - m);
  }
  sd = std::sqrt(c0 / static_cast<double>(to - from - 1));
  r1 = c1 / c0;
}

// An open loop (kc = 0: OP frozen at op0) to look at disturbances and noise alone.
LoopConfig open_loop() {
  LoopConfig c;
  c.Ts = 1.0;
  c.controller = {0.0, 10.0, 0.0, 100.0, 50.0};
  c.process = first_order_process(2.0, 10.0, 3.0, 20.0);
  return c;
}

}  // namespace

TEST_CASE("PI controller: velocity form by hand, clamping is anti-windup") {
  PiController pi({2.0, 10.0, 0.0, 100.0, 50.0}, 1.0);
  // First error 2: no proportional kick, integral 2 * 1/10 * 2 = 0.4.
  CHECK(pi.step(10.0, 8.0) == doctest::Approx(50.4));
  // e = 1: 2 ((1 - 2) + 0.1 * 1) = -1.8.
  CHECK(pi.step(10.0, 9.0) == doctest::Approx(48.6));
  // A long large error: OP sits at the limit (the integral would have grown by 200 %) ...
  for (int k = 0; k < 100; ++k) pi.step(10.0, 0.0);
  CHECK(pi.output() == 100.0);
  // ... and leaves it as soon as the error shrinks, with no wound-up integral to unwind:
  // 2 ((1 - 10) + 0.1 * 1) = -17.8.
  CHECK(pi.step(10.0, 9.0) == doctest::Approx(82.2));
  CHECK_THROWS_AS(PiController({1.0, 0.0, 0, 100, 50}, 1.0), std::invalid_argument);
  CHECK_THROWS_AS(PiController({1.0, 10.0, 0, 100, 150}, 1.0), std::invalid_argument);
}

TEST_CASE("PI loop with a linear valve settles to the set point") {
  LoopConfig c;
  c.Ts = 0.5;
  c.controller = {0.25, 50.0, 0.0, 100.0, 50.0};
  c.process = first_order_process(3.8163, 156.46, 2.5, 50.0);
  c.setpoint = {{0.0, 50.0}, {20.0, 56.0}};
  SUBCASE("noise-free: zero steady-state error") {
    const LoopData d = simulate_loop(c, 1, 8000);
    CHECK(d.pv.back() == doctest::Approx(56.0).epsilon(1e-6));
    CHECK(d.mv.back() == doctest::Approx(50.0 + 6.0 / 3.8163).epsilon(1e-6));
    CHECK(d.op.back() == d.mv.back());  // linear valve
  }
  SUBCASE("with measurement noise: the error averages out") {
    c.measurement_noise_std = 0.2;
    const LoopData d = simulate_loop(c, 5, 8000);
    const double e = mean(d.pv, 6000, 8000) - 56.0;
    CHECK(std::abs(e) < 0.05);  // 3 sigma of the mean of correlated noise is about 0.03
  }
  SUBCASE("a load step at the valve is rejected") {
    c.disturbances.steps = {{1500.0, -5.0, DisturbanceEntry::input}};
    const LoopData d = simulate_loop(c, 1, 12000);
    CHECK(d.pv.back() == doctest::Approx(56.0).epsilon(1e-6));
    CHECK(d.op.back() == doctest::Approx(50.0 + 6.0 / 3.8163 + 5.0).epsilon(1e-6));
  }
}

TEST_CASE("LoopData layout: t = k Ts, sp schedule, mv filled") {
  LoopConfig c = open_loop();
  c.Ts = 0.5;
  c.setpoint = {{0.0, 20.0}, {1.5, 22.0}, {3.0, 19.0}};
  LoopSimulator sim(c, 3);
  const LoopData d = sim.run(10, "unit");
  REQUIRE(d.size() == 10);
  CHECK(d.source == "unit");
  CHECK(d.has_sp());
  CHECK(d.has_mv());
  CHECK(d.sample_period() == 0.5);
  CHECK(d.t[7] == 3.5);
  const std::vector<double> sp{20, 20, 20, 22, 22, 22, 19, 19, 19, 19};
  for (std::size_t k = 0; k < sp.size(); ++k) CHECK(d.sp[k] == sp[k]);
  // A later run continues the same loop.
  CHECK(sim.run(2).t.front() == 5.0);
}

TEST_CASE("Disturbances at the output and at the valve") {
  SUBCASE("output step shows in PV at its time, input step through the process") {
    LoopConfig c = open_loop();
    c.disturbances.steps = {{10.0, 3.0, DisturbanceEntry::output},
                            {20.0, 1.0, DisturbanceEntry::input}};
    const LoopData d = simulate_loop(c, 1, 60);
    CHECK(d.pv[9] == 20.0);
    CHECK(d.pv[10] == doctest::Approx(23.0));
    CHECK(d.mv[30] == 50.0);  // the recorded valve position does not include the load
    // Input step of 1 at t = 20, dead time 3: 2 (1 - e^{-(t-23)/10}).
    CHECK(d.pv[23] == doctest::Approx(23.0));
    CHECK(d.pv[33] == doctest::Approx(23.0 + 2.0 * (1.0 - std::exp(-1.0))));
  }
  SUBCASE("drift ramps and holds") {
    LoopConfig c = open_loop();
    c.disturbances.drifts = {{10.0, 0.5, 20.0, DisturbanceEntry::output}};
    const LoopData d = simulate_loop(c, 1, 40);
    CHECK(d.pv[10] == doctest::Approx(20.0));
    CHECK(d.pv[14] == doctest::Approx(22.0));
    CHECK(d.pv[30] == doctest::Approx(25.0));
  }
  SUBCASE("filtered noise: stationary std and correlation e^{-Ts/tau}") {
    LoopConfig c = open_loop();
    c.disturbances.noises = {{0.7, 10.0, DisturbanceEntry::output}};
    const LoopData d = simulate_loop(c, 11, 40000);
    double sd = 0, r1 = 0;
    moments(d.pv, 0, d.size(), sd, r1);
    CHECK(sd == doctest::Approx(0.7).epsilon(0.06));
    CHECK(r1 == doctest::Approx(std::exp(-0.1)).epsilon(0.02));
  }
  SUBCASE("measurement noise: white with the given std") {
    LoopConfig c = open_loop();
    c.measurement_noise_std = 0.3;
    const LoopData d = simulate_loop(c, 12, 20000);
    double sd = 0, r1 = 0;
    moments(d.pv, 0, d.size(), sd, r1);
    CHECK(sd == doctest::Approx(0.3).epsilon(0.03));
    CHECK(std::abs(r1) < 0.03);
  }
}

// The valve's own PV (the true model's output, the benchmark's reference): the process driven by
// the valve position alone, without loads or measurement noise.
TEST_CASE("valve_pv: PV as the valve alone moves it") {
  LoopConfig c = open_loop();
  c.controller.kc = 0.8;  // closed: the valve moves against the loads
  c.setpoint = {{0.0, 20.0}, {40.0, 24.0}};
  SUBCASE("without loads or noise it is PV") {
    LoopSimulator sim(c, 3);
    const LoopData d = sim.run(200);
    REQUIRE(sim.valve_pv().size() == d.size());
    for (std::size_t k = 0; k < d.size(); ++k) CHECK(sim.valve_pv()[k] == doctest::Approx(d.pv[k]));
  }
  SUBCASE("loads and noise are left out, the valve's moves kept") {
    c.disturbances.steps = {{60.0, 2.0, DisturbanceEntry::input},
                            {90.0, -1.0, DisturbanceEntry::output}};
    c.disturbances.noises = {{0.3, 8.0, DisturbanceEntry::input}};
    c.measurement_noise_std = 0.2;
    LoopSimulator sim(c, 4);
    const LoopData d = sim.run(200);
    REQUIRE(sim.valve_pv().size() == d.size());
    // The same process driven by the recorded valve position from its rest there.
    DiscreteProcess p(c.process, c.Ts);
    p.reset(c.controller.op0);
    double worst = 0.0, load = 0.0;
    for (std::size_t k = 0; k < d.size(); ++k) {
      worst = std::max(worst, std::abs(sim.valve_pv()[k] - p.output()));
      load = std::max(load, std::abs(d.pv[k] - sim.valve_pv()[k]));
      p.advance(d.mv[k]);
    }
    CHECK(worst < 1e-9);
    CHECK(load > 1.0);  // PV does carry the loads
  }
  SUBCASE("without the trace nothing grows, and the samples are the same") {
    LoopSimulator traced(c, 5), bare(c, 5);
    bare.keep_trace(false);
    const LoopData a = traced.run(300), b = bare.run(300);
    CHECK(a.pv == b.pv);
    CHECK(a.op == b.op);
    CHECK(traced.valve_pv().size() == 300);
    CHECK(bare.valve_pv().empty());
  }
}

TEST_CASE("Seeded runs are reproducible, different seeds differ") {
  LoopConfig c = open_loop();
  c.controller.kc = 0.5;
  c.measurement_noise_std = 0.1;
  c.disturbances.noises = {{0.5, 30.0, DisturbanceEntry::output}};
  c.valve = {HeStiction(3.0, 1.0)};
  c.setpoint = {{0.0, 20.0}, {100.0, 25.0}};
  const LoopData a = simulate_loop(c, 42, 2000);
  const LoopData b = simulate_loop(c, 42, 2000);
  const LoopData other = simulate_loop(c, 43, 2000);
  CHECK(a.pv == b.pv);
  CHECK(a.op == b.op);
  CHECK(a.mv == b.mv);
  CHECK(a.pv != other.pv);
  LoopSimulator sim(c, 42);
  sim.run(700);
  sim.reset(42);
  CHECK(sim.run(2000).pv == a.pv);
}

TEST_CASE("Each noise source has its own random stream") {
  // Switching the measurement noise off leaves the load-noise sequence unchanged: with the
  // controller frozen (kc = 0) the PV difference is exactly the measurement noise, which is
  // white with the given std.
  LoopConfig c = open_loop();
  c.disturbances.noises = {{0.5, 30.0, DisturbanceEntry::output}};
  const LoopData quiet = simulate_loop(c, 9, 5000);
  c.measurement_noise_std = 0.2;
  const LoopData noisy = simulate_loop(c, 9, 5000);
  std::vector<double> diff(quiet.size());
  for (std::size_t k = 0; k < diff.size(); ++k) diff[k] = noisy.pv[k] - quiet.pv[k];
  double sd = 0, r1 = 0;
  moments(diff, 0, diff.size(), sd, r1);
  CHECK(sd == doctest::Approx(0.2).epsilon(0.05));
  CHECK(std::abs(r1) < 0.05);
}

TEST_CASE("Loop configuration is validated") {
  LoopConfig c = open_loop();
  c.valve = {ActuatorLag(5.0, 0.5)};  // built for another Ts
  CHECK_THROWS_AS(validate(c), std::invalid_argument);
  c.valve = {ActuatorLag(5.0, 1.0)};
  CHECK_NOTHROW(validate(c));
  c.setpoint = {{10.0, 1.0}, {5.0, 2.0}};
  CHECK_THROWS_AS(validate(c), std::invalid_argument);
  c.setpoint.clear();
  c.disturbances.noises = {{1.0, 0.0, DisturbanceEntry::output}};
  CHECK_THROWS_AS(LoopSimulator(c, 1), std::invalid_argument);
  c.disturbances.noises.clear();
  c.measurement_noise_std = -1.0;
  CHECK_THROWS_AS(validate(c), std::invalid_argument);
}
