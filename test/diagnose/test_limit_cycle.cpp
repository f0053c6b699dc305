// The limit-cycle test (Horch's phase test with the OP-driven model's share): properties on
// synthetic cycles, the simulated stick-slip loops, a linear loop tuned too tightly, and an
// oscillation that comes from outside the loop.
#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

#include "../common/sanitized.hpp"
#include "valvediag/diagnose/diagnosis.hpp"
#include "valvediag/diagnose/limit_cycle.hpp"
#include "valvediag/diagnose/verdict.hpp"
#include "valvediag/io/mat_reader.hpp"
#include "valvediag/sim/scenarios.hpp"
#include "valvediag/sim/valve_effects.hpp"

using namespace valvediag;

namespace {

constexpr double kPi = 3.14159265358979323846;
// Trial fits that support a valve with memory and no clearly better rival.
const TrialEvidence kMemory{50.0, 10.0, 5.0, "order"};

struct Signals {
  std::vector<double> u, y;
};

// OP = 50 + A sin(w t), PV = 10 + B sin(w t + phase) + noise; the period drifts slowly by
// `drift` (relative) over the record, as a real cycle does.
Signals cycle(double phase_deg, std::size_t N = 3000, double period = 40.0, double drift = 0.0,
              double noise = 0.05, unsigned seed = 1) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> w(0.0, noise);
  Signals s;
  double theta = 0.0;
  for (std::size_t k = 0; k < N; ++k) {
    const double p = period * (1.0 + drift * static_cast<double>(k) / static_cast<double>(N));
    theta += 2.0 * kPi / p;
    s.u.push_back(50.0 + 2.0 * std::sin(theta) + w(rng));
    s.y.push_back(10.0 + 1.0 * std::sin(theta + phase_deg * kPi / 180.0) + w(rng));
  }
  return s;
}

}  // namespace

TEST_CASE("the phase of PV against OP is measured at the cycle, odd near +-90 deg") {
  for (double phase : {-150.0, -100.0, -90.0, -60.0, 0.0, 30.0, 80.0, 120.0, 180.0}) {
    for (double drift : {0.0, 0.05}) {
      CAPTURE(phase);
      CAPTURE(drift);
      const Signals s = cycle(phase, 3000, 40.0, drift);
      const LimitCycle c = limit_cycle_test(s.u, s.y, s.y, 1.0, false, kMemory);
      REQUIRE(c.oscillating);
      CHECK(c.period_s == doctest::Approx(40.0 * (1 + drift / 2)).epsilon(0.06));
      const double err = std::remainder(c.phase_deg - phase, 360.0);
      CHECK(std::abs(err) < 6.0);
      const bool odd = std::abs(std::sin(phase * kPi / 180.0)) > std::sqrt(0.5);
      CHECK(c.odd == odd);
      // The model here is PV itself: it carries the whole cycle.
      CHECK(c.model_share > 0.95);
      CHECK(c.stick_slip == odd);
      // Choudhury's apparent stiction: the ellipse's width along OP, 2 A |sin phase|.
      CHECK(c.apparent_band ==
            doctest::Approx(2 * 2.0 * std::abs(std::sin(phase * kPi / 180.0))).epsilon(0.08));
    }
  }
}

TEST_CASE("the test does not decide without a cycle, for an integrating process, or without OP") {
  SUBCASE("white noise") {
    std::mt19937_64 rng(3);
    std::normal_distribution<double> w(0.0, 1.0);
    std::vector<double> u(2000), y(2000);
    for (auto& v : u) v = 50 + w(rng);
    for (auto& v : y) v = w(rng);
    const LimitCycle c = limit_cycle_test(u, y, y, 1.0, false, kMemory);
    CHECK_FALSE(c.oscillating);
    CHECK_FALSE(c.stick_slip);
  }
  SUBCASE("integrating process: an integrator adds its own 90 deg") {
    const Signals s = cycle(90.0);
    const LimitCycle c = limit_cycle_test(s.u, s.y, s.y, 1.0, true, kMemory);
    CHECK(c.oscillating);
    CHECK(c.odd);
    CHECK_FALSE(c.stick_slip);
    CHECK(c.summary.find("integrates") != std::string::npos);
  }
  SUBCASE("the model driven by OP carries none of PV's cycle") {
    const Signals s = cycle(90.0);
    const std::vector<double> flat(s.y.size(), 10.0);
    const LimitCycle c = limit_cycle_test(s.u, s.y, flat, 1.0, false, kMemory);
    CHECK(c.odd);
    CHECK(c.model_share < 0.1);
    CHECK_FALSE(c.stick_slip);
    CHECK(c.summary.find("outside the loop") != std::string::npos);
  }
  SUBCASE("no model output: the share is unknown and the test does not decide") {
    const Signals s = cycle(90.0);
    const LimitCycle c = limit_cycle_test(s.u, s.y, {}, 1.0, false, kMemory);
    CHECK(std::isnan(c.model_share));
    CHECK_FALSE(c.stick_slip);
    CHECK(c.summary.find("no model driven by OP") != std::string::npos);
  }
  SUBCASE("no valve model with memory gains: an outside cycle looks the same") {
    const Signals s = cycle(90.0);
    for (double gain : {0.5, std::nan("")}) {
      const LimitCycle c = limit_cycle_test(s.u, s.y, s.y, 1.0, false, {50.0, gain, 0.0, "order"});
      CHECK(c.odd);
      CHECK_FALSE(c.stick_slip);
    }
    // A memoryless rival that removes a fifth of the error the memory trial leaves.
    const LimitCycle c = limit_cycle_test(s.u, s.y, s.y, 1.0, false, {50.0, 10.0, 18.0, "order"});
    CHECK(c.rival == "order");
    CHECK_FALSE(c.stick_slip);
    CHECK(limit_cycle_test(s.u, s.y, s.y, 1.0, false, {50.0, 10.0, 17.0, "order"}).stick_slip);
  }
  SUBCASE("OP flat: the phase is noise") {
    Signals s = cycle(90.0);
    std::mt19937_64 rng(5);
    std::normal_distribution<double> w(0.0, 0.5);
    for (auto& v : s.u) v = 50 + w(rng);
    const LimitCycle c = limit_cycle_test(s.u, s.y, s.y, 1.0, false, kMemory);
    CHECK_FALSE(c.stick_slip);
  }
}

// A first-order process with dead time under a PI, simulated here so that the load can be a
// sine (an upstream loop's cycle) or the tuning can be pushed to the edge of stability.
struct MiniLoop {
  double K = 1.2, tau = 40.0, theta = 4.0, kc = 0.8, ti = 40.0, Ts = 1.0;
  double load_amp = 0.0, load_period = 600.0, noise = 0.02, load_noise = 0.0;
  double fs = 0.0, fd = 0.0;  // He stiction of the valve (0: linear)
  double sp_offset = 0.0;     // set point off the start, in valve % (K times this in PV)
  std::vector<double> u, y;
  void run(std::size_t N, unsigned seed) {
    std::mt19937_64 rng(seed);
    std::normal_distribution<double> w(0.0, 1.0);
    const double a = std::exp(-Ts / tau);
    const auto d = static_cast<std::size_t>(theta / Ts);
    std::vector<double> x(N + d + 1, 50.0);
    double yp = K * 50.0, op = 50.0, e_prev = 0.0, ln = 0.0;
    const double sp = K * (50.0 + sp_offset);
    HeStiction valve(fs, fd);
    valve.reset(50.0, 50.0, 0.0);
    u.clear();
    y.clear();
    for (std::size_t k = 0; k < N; ++k) {
      ln = 0.99 * ln + load_noise * std::sqrt(1 - 0.99 * 0.99) * w(rng);
      yp = a * yp + (1 - a) * K * (x[k] + ln);
      const double load = load_amp * std::sin(2 * kPi * static_cast<double>(k) * Ts / load_period);
      const double ym = yp + load + noise * w(rng);
      const double e = sp - ym;
      op = std::clamp(op + kc * (e - e_prev) + kc * Ts / ti * e, 0.0, 100.0);
      e_prev = e;
      x[k + d] = fs > 0 ? valve.step(op) : op;
      u.push_back(op);
      y.push_back(ym);
    }
  }
};

TEST_CASE("a sticky valve that makes its loop cycle is found, with its band") {
  // A flow-like loop and a slower one; the set point lies off the point where the valve lands
  // after a slip (else the first slip would settle the loop).
  struct Case {
    double tau, theta, kc, ti;
  };
  for (const Case& k : {Case{10, 2, 0.3, 20}, Case{40, 4, 0.5, 60}})
    for (unsigned seed : {1u, 2u}) {
      CAPTURE(k.tau);
      CAPTURE(seed);
      MiniLoop m;
      m.tau = k.tau;
      m.theta = k.theta;
      m.kc = k.kc;
      m.ti = k.ti;
      m.fs = 3.0;
      m.fd = 1.0;
      m.sp_offset = 2.7;
      m.run(3000, seed);
      const Diagnosis dg = diagnose(m.u, m.y, m.Ts, parse_model_spec("linear"));
      std::printf("He fs 3 fd 1, tau %2.0f  %s\n", k.tau, dg.limit_cycle.summary.c_str());
      CHECK(dg.limit_cycle.oscillating);
      CHECK(dg.limit_cycle.stick_slip);
      CHECK(verdict(dg) == "stiction");
      // The apparent band (the OP-PV ellipse's width) is of the size of fs.
      CHECK(dg.limit_cycle.apparent_band == doctest::Approx(3.0).epsilon(0.2));
    }
}

TEST_CASE("an outside cycle and the linear scenarios are not stick-slip" *
          valvediag::test::release_only()) {
  SUBCASE("a slow outside oscillation that the controller compensates") {
    MiniLoop m;
    m.load_amp = 2.0;
    m.load_period = 900.0;
    m.load_noise = 1.0;
    m.run(6000, 3);
    const Diagnosis dg = diagnose(m.u, m.y, m.Ts, parse_model_spec("linear"));
    std::printf("%-22s %s\n", "outside oscillation", dg.limit_cycle.summary.c_str());
    CHECK(dg.limit_cycle.oscillating);
    CHECK_FALSE(dg.limit_cycle.stick_slip);
    CHECK(verdict(dg) != "stiction");
  }
  SUBCASE("linear-clean and paper-ex1-linear are never stick-slip") {
    for (const char* name : {"linear-clean", "paper-ex1-linear"}) {
      CAPTURE(name);
      const LoopData d = run_scenario(scenario_by_name(name), 1, 3000);
      const Diagnosis dg = diagnose(d.op, d.pv, d.sample_period(), parse_model_spec("linear"));
      CHECK_FALSE(dg.limit_cycle.stick_slip);
    }
  }
}

// The Tennessee Eastman reactor cooling-water loop (shared/data): with the valve-sticking fault
// IDV(14) it cycles with a period of about 270 s; in normal operation it does not cycle. The
// trial fits alone cannot tell (36 s samples, the valve slips within a sample): the limit cycle
// can.
TEST_CASE("Tennessee Eastman: the valve-sticking fault is stiction, normal operation is not" *
          valvediag::test::release_only()) {
  for (const char* run : {"m1d14", "m1d00"}) {
    CAPTURE(run);
    MatOptions o;
    o.op = "51";
    o.pv = "21";
    o.sample_period = 36.0;
    const LoopData d = read_mat_loop(
        std::string(VALVEDIAG_DATA_DIR) + "/tennessee-eastman/" + run + ".mat", run, o);
    const Diagnosis dg = diagnose_auto(d.op, d.pv, d.sample_period(), parse_model_spec("linear"));
    std::printf("%-6s %-16s %s\n", run, verdict(dg).c_str(), dg.limit_cycle.summary.c_str());
    if (std::string(run) == "m1d14") {
      CHECK(dg.limit_cycle.oscillating);
      CHECK(dg.limit_cycle.period_s == doctest::Approx(269).epsilon(0.05));
      CHECK(std::abs(std::sin(dg.limit_cycle.phase_deg * kPi / 180)) > 0.9);
      CHECK(dg.limit_cycle.stick_slip);
      CHECK(verdict(dg) == "stiction");
      // TE's valve jumps once OP is 2 % of travel away from it: the apparent band is of that size.
      CHECK(dg.limit_cycle.apparent_band > 1.5);
      CHECK(dg.limit_cycle.apparent_band < 4.0);
    } else {
      CHECK_FALSE(dg.limit_cycle.stick_slip);
      CHECK(verdict(dg) == "no-valve-problem");
    }
  }
}
