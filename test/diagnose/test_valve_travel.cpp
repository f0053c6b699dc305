// The valve-travel test (OP -> measured valve position): He's figures recovered from noisy,
// quantised positions, every named scenario's valve told right, a seeded sweep over friction,
// lag, calibration and noise, and the records it must refuse.
#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "../common/sanitized.hpp"
#include "../common/text.hpp"
#include "valvediag/diagnose/valve_travel.hpp"
#include "valvediag/diagnose/verdict.hpp"
#include "valvediag/sim/scenarios.hpp"
#include "valvediag/sim/valve_effects.hpp"

using namespace valvediag;

namespace {

// A position transmitter: white noise and a resolution step, as a positioner reports travel.
std::vector<double> transmitted(std::vector<double> x, double noise, double step, unsigned seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> w(0.0, noise);
  for (double& v : x) {
    v += noise > 0 ? w(rng) : 0.0;
    if (step > 0) v = step * std::round(v / step);
  }
  return x;
}

using valvediag::test::has;

}  // namespace

TEST_CASE("every named scenario's valve is told from its measured position" *
          valvediag::test::accuracy()) {
  struct Case {
    const char* scenario;
    const char* verdict;
  };
  const Case cases[] = {
      {"paper-ex1", "stiction"},
      {"kano", "any"},
      {"stenman", "stiction"},
      {"choudhury", "any"},
      {"preisach", "any"},
      {"deadband", "deadband"},
      {"asymmetric-stiction", "any"},
      {"paper-ex1-linear", "no-valve-problem"},
      {"linear-clean", "no-valve-problem"},
      {"second-order", "no-valve-problem"},
      {"load-changes", "no-valve-problem"},
      {"actuator-lag", "no-valve-problem"},
      {"saturation", "no-valve-problem"},
      {"characteristic", "no-valve-problem"},
      {"integrating", "no-valve-problem"},
      {"level", "no-valve-problem"},
      {"slow-actuator", "no-valve-problem"},
  };
  // Under the sanitizers every fourth scenario, one seed: the same code on other valves.
  for (std::size_t i = 0; i < std::size(cases); ++i)
    for (unsigned seed = 1; seed <= 2u; ++seed) {
      const Case& c = cases[i];
      const LoopData d = run_scenario(scenario_by_name(c.scenario), seed, 3000);
      REQUIRE(d.has_mv());
      const auto mv = transmitted(d.mv, 0.1, 0.05, seed + 10);
      const ValveTravel v = check_valve_travel(d.op, mv, d.sample_period());
      INFO(std::string(c.scenario) << " seed " << seed << ": " << v.summary);
      CHECK(v.tested);
      CHECK(v.decided);
      // Kano's and Choudhury's valves re-stick whenever OP stops or turns (noisy OP: all the time),
      // the Preisach one moves on its grid's steps: He's jump is only roughly theirs, so the split
      // stiction / backlash is asserted for He's valves and backlash only.
      if (std::string(c.verdict) == "any")
        CHECK((v.verdict == "stiction" || v.verdict == "deadband"));
      else
        CHECK(v.verdict == c.verdict);
      // A healthy valve: the follow model explains the transmitted position.
      if (v.verdict == "no-valve-problem") CHECK(v.follow_fitness_percent > 90.0);
    }
}

TEST_CASE("He's figures and the actuator lag are read back from noisy positions" *
          valvediag::test::release_only()) {
  SUBCASE("paper Example 1: fs 8.4, fd 3.52") {
    const LoopData d = run_scenario(scenario_by_name("paper-ex1"), 1, 3000);
    const ValveTravel v = check_valve_travel(d.op, transmitted(d.mv, 0.2, 0.1, 3), 0.5);
    CHECK(v.verdict == "stiction");
    CHECK(v.fs_percent == doctest::Approx(8.4).epsilon(0.05));
    CHECK(v.fd_percent == doctest::Approx(3.52).epsilon(0.1));
    CHECK(v.jump_percent == doctest::Approx(8.4 - 3.52).epsilon(0.1));
    CHECK(has(v.summary, "has friction"));
  }
  SUBCASE("backlash 4 %: fs = fd = 2, no jump") {
    const LoopData d = run_scenario(scenario_by_name("deadband"), 1, 3000);
    const ValveTravel v = check_valve_travel(d.op, transmitted(d.mv, 0.1, 0.05, 4), 1.0);
    CHECK(v.verdict == "deadband");
    CHECK(v.fs_percent + v.fd_percent == doctest::Approx(4.0).epsilon(0.05));
    CHECK(std::abs(v.jump_percent) < 0.3);
    CHECK(has(v.summary, "backlash"));
  }
  SUBCASE("slow actuator, tau 15 s: follows OP with that lag") {
    const LoopData d = run_scenario(scenario_by_name("actuator-lag"), 1, 3000);
    const ValveTravel v = check_valve_travel(d.op, transmitted(d.mv, 0.1, 0.05, 5), 1.0);
    CHECK(v.verdict == "no-valve-problem");
    CHECK(v.lag_s == doctest::Approx(15.0).epsilon(0.15));
    CHECK(v.gain == doctest::Approx(1.0).epsilon(0.05));
    CHECK(has(v.summary, "follows OP"));
  }
  SUBCASE("travel limited to 5..70 %: a stop is not friction") {
    const LoopData d = run_scenario(scenario_by_name("saturation"), 2, 3000);
    REQUIRE(*std::max_element(d.mv.begin(), d.mv.end()) <= 70.0 + 1e-9);
    const ValveTravel v = check_valve_travel(d.op, transmitted(d.mv, 0.1, 0.05, 6), 1.0);
    CHECK(v.verdict == "no-valve-problem");
  }
}

// Seeded sweep: OP a random walk with steps (a controller's output), the valve He's with random
// fs, fd, an actuator lag, a transmitter with calibration gain and offset, noise and resolution.
TEST_CASE("seeded sweep: friction sized within 20 % or 0.5 % of travel, clean valves kept" *
          valvediag::test::accuracy()) {
  std::mt19937_64 rng(2026);
  std::uniform_real_distribution<double> U(0.0, 1.0);
  std::normal_distribution<double> N(0.0, 1.0);
  int sized = 0, sticky = 0, clean_kept = 0, clean = 0;
  std::printf("\n  fs    fd    tau  noise | fs^    fd^   verdict\n");
  for (int c = 0; c < 40; ++c) {
    const bool friction = c % 4 != 3;  // every fourth valve is healthy
    const double fs = friction ? 1.0 + 7.0 * U(rng) : 0.0;
    const double fd = fs * U(rng);
    const double tau = 8.0 * U(rng), noise = 0.3 * U(rng), gain = 0.95 + 0.1 * U(rng);
    const double offset = 2.0 * (U(rng) - 0.5), Ts = 1.0;
    const std::size_t n = 2000;
    std::vector<double> op(n), x(n);
    double u = 50.0, drift = 0.0;
    for (std::size_t k = 0; k < n; ++k) {
      drift = 0.98 * drift + 0.3 * N(rng);
      u = std::clamp(u + drift * 0.2 + 0.15 * N(rng) + (U(rng) < 0.004 ? 8.0 * N(rng) : 0.0), 10.0,
                     90.0);
      op[k] = u;
    }
    HeStiction he(fs, fd, 0.0);
    he.reset(op[0]);
    const double a = tau > 0 ? std::exp(-Ts / tau) : 0.0;
    double z = he.output();
    for (std::size_t k = 0; k < n; ++k) {
      z = a * z + (1 - a) * (k == 0 ? he.output() : he.step(op[k]));
      x[k] = gain * z + offset;
    }
    const ValveTravel v = check_valve_travel(op, transmitted(x, noise, 0.05, 100 + c), Ts);
    std::printf("%5.2f %5.2f %5.1f %5.2f | %5.2f %5.2f %s\n", fs, fd, tau, noise, v.fs_percent,
                v.fd_percent, v.verdict.c_str());
    if (friction) {
      ++sticky;
      const bool fs_ok = std::abs(v.fs_percent - fs) <= std::max(0.2 * fs, 0.5);
      const bool fd_ok = std::abs(v.fd_percent - fd) <= std::max(0.2 * fd, 0.5);
      sized += (v.verdict == "stiction" || v.verdict == "deadband") && fs_ok && fd_ok;
    } else {
      ++clean;
      clean_kept += v.verdict == "no-valve-problem";
    }
  }
  std::printf("friction found and sized: %d of %d; healthy valves kept: %d of %d\n", sized, sticky,
              clean_kept, clean);
  CHECK(sized >= 0.9 * sticky);
  CHECK(clean_kept == clean);
}

TEST_CASE("records the valve-travel test refuses or reads as stuck") {
  const LoopData d = run_scenario(scenario_by_name("kano"), 1, 1000);
  SUBCASE("a gap in MV is named by its sample") {
    auto mv = d.mv;
    mv[417] = std::numeric_limits<double>::quiet_NaN();
    const ValveTravel v = check_valve_travel(d.op, mv, 1.0);
    CHECK_FALSE(v.tested);
    CHECK_FALSE(v.decided);
    CHECK(has(v.summary, "sample 417"));
  }
  SUBCASE("MV and OP of different lengths") {
    auto mv = d.mv;
    mv.pop_back();
    const ValveTravel v = check_valve_travel(d.op, mv, 1.0);
    CHECK_FALSE(v.decided);
    CHECK(has(v.summary, "not one record"));
  }
  SUBCASE("too short") {
    const std::vector<double> op(d.op.begin(), d.op.begin() + 50),
        mv(d.mv.begin(), d.mv.begin() + 50);
    CHECK_FALSE(check_valve_travel(op, mv, 1.0).tested);
  }
  SUBCASE("a valve that does not move while OP sweeps is stuck") {
    const ValveTravel v =
        check_valve_travel(d.op, transmitted(std::vector<double>(1000, 42.0), 0.02, 0.0, 7), 1.0);
    CHECK(v.decided);
    CHECK(v.verdict == "stiction");
    CHECK(has(v.summary, "stuck"));
    CHECK(has(v.summary, "transmitter"));
  }
}

TEST_CASE("an MV that equals OP leaves friction nothing to explain, not a ratio of roundings") {
  // As the simulator writes a linear valve's MV: OP itself. The follow model's error is rounding;
  // the share friction removes of it is none (it read -6e13 %).
  const LoopData d = run_scenario(scenario_by_name("kano"), 1, 1000);
  const ValveTravel v = check_valve_travel(d.op, d.op, 1.0);
  INFO(v.summary);
  CHECK(v.decided);
  CHECK(v.verdict == "no-valve-problem");
  CHECK(v.error_share == doctest::Approx(0.0));
  CHECK(v.validation_error_share == doctest::Approx(0.0));
  CHECK(has(v.summary, "friction explains none of the error left"));
}

TEST_CASE("friction that explains one part of the record only leaves the verdict to the models") {
  // Kano's valve, seed 3, as `simulate` writes it: friction removes three quarters of the error on
  // the estimation part and a sixth held out. That is no evidence the valve follows OP (which
  // overruled the models' right `deadband` in the simulated sweep); the test is inconclusive.
  const LoopData d = run_scenario(scenario_by_name("kano"), 3, 0);
  const ValveTravel v = check_valve_travel(d.op, d.mv, d.sample_period());
  INFO(v.summary);
  CHECK(v.tested);
  CHECK(v.error_share >= 0.2);
  CHECK(v.validation_error_share < 0.2);
  CHECK_FALSE(v.decided);
  CHECK(v.verdict.empty());
  CHECK(has(v.summary, "inconclusive"));
  // A part friction explains worse than following OP reads "none", not a negative share.
  CHECK_FALSE(has(v.summary, " -"));
  CHECK(has(v.summary, "models decide"));
}

TEST_CASE("the verdict: a measured position outweighs the closed-loop models") {
  Diagnosis d;
  DiagnosisStep s;
  s.fit.spec = parse_model_spec("stiction");  // the closed-loop models found memory
  d.steps.push_back(s);
  CHECK(verdict(d) == "stiction");
  d.valve_travel.decided = true;
  d.valve_travel.verdict = "no-valve-problem";  // ... but the valve follows OP
  CHECK(verdict(d) == "no-valve-problem");
  d.steps.front().fit.spec = parse_model_spec("saturation");
  CHECK(verdict(d) == "other-nonlinearity");  // a static curve is not seen in the travel
  d.steps.front().fit.spec = parse_model_spec("linear");
  d.valve_travel.verdict = "deadband";
  CHECK(verdict(d) == "deadband");
  d.valve_travel.decided = false;  // tested but inconclusive: the models decide
  CHECK(verdict(d) == "no-valve-problem");
}

TEST_CASE("a part friction explains worse than following OP reads none, not a negative share") {
  // paper-ex1 over 1500 samples (as `simulate --scenario paper-ex1 --seed 1` writes it): MV
  // moves twice in the estimation part and once held out. The friction fitted to the two (He's
  // fs 8.40, fd 3.40, the simulator's 8.4 and 3.5) misses where the held-out step falls, and
  // its share of the error a following valve leaves there came out -2367 %.
  const LoopData d = run_scenario(scenario_by_name("paper-ex1"), 1, 1500);
  const ValveTravel v = check_valve_travel(d.op, d.mv, d.sample_period());
  INFO(v.summary);
  REQUIRE(v.validation_error_share < 0.0);
  CHECK(has(v.summary, "none"));
  CHECK_FALSE(has(v.summary, " -"));
}
