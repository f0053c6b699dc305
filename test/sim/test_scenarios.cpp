#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "valvediag/sim/scenarios.hpp"

using namespace valvediag;

namespace {

const std::string kConfigDir = std::string(VALVEDIAG_SOURCE_DIR) + "/configs/scenarios/";

// Reversals of a signal's direction, counted with a hysteresis of `band` so that noise on a
// slow ramp does not count.
int reversals(const std::vector<double>& v, std::size_t from, double band) {
  int n = 0, dir = 0;
  double hi = v[from], lo = v[from];  // extremes since the last turn
  for (std::size_t k = from + 1; k < v.size(); ++k) {
    hi = std::max(hi, v[k]);
    lo = std::min(lo, v[k]);
    if (dir >= 0 && v[k] < hi - band) {
      n += dir > 0;
      dir = -1;
      lo = v[k];
    } else if (dir <= 0 && v[k] > lo + band) {
      n += dir < 0;
      dir = 1;
      hi = v[k];
    }
  }
  return n;
}

std::size_t index_at(const LoopData& d, double t) {
  return static_cast<std::size_t>(std::lround(t / d.sample_period()));
}

ScenarioFileError parse_error(const std::string& text) {
  try {
    parse_scenario_toml(text, "bad.toml");
  } catch (const ScenarioFileError& e) {
    return e;
  }
  FAIL("no error for:\n" << text);
  return ScenarioFileError("", 0, 0, "", "");
}

const std::string kMinimal = R"(sample_period = 1.0
[controller]
kc = 1.0
ti = 20.0
[process]
type = "first-order"
gain = 2.0
tau = 10.0
)";

}  // namespace

TEST_CASE("Scenario names and lookup") {
  const auto names = scenario_names();
  for (const char* required : {"paper-ex1", "linear-clean", "deadband", "kano", "choudhury",
                               "stenman", "asymmetric-stiction", "saturation", "characteristic",
                               "actuator-lag", "integrating", "second-order"}) {
    CAPTURE(required);
    CHECK(std::find(names.begin(), names.end(), required) != names.end());
  }
  for (const auto& n : names) CHECK(scenario_by_name(n).name == n);
  try {
    scenario_by_name("sticky");
    FAIL("no exception");
  } catch (const std::invalid_argument& e) {
    const std::string m = e.what();
    CHECK(m.find("sticky") != std::string::npos);
    CHECK(m.find("paper-ex1") != std::string::npos);
    CHECK(m.find("second-order") != std::string::npos);
  }
}

TEST_CASE("Every scenario runs and stays physical") {
  for (const auto& name : scenario_names()) {
    CAPTURE(name);
    const Scenario s = scenario_by_name(name);
    CHECK(!s.description.empty());
    const LoopData d = run_scenario(s, 1, 0);
    REQUIRE(d.size() == s.default_samples);
    CHECK(d.sample_period() == doctest::Approx(s.loop.Ts));
    CHECK(d.source == "scenario " + name + ", seed 1");
    for (std::size_t k = 0; k < d.size(); ++k) {
      REQUIRE(std::isfinite(d.pv[k]));
      REQUIRE(std::isfinite(d.mv[k]));
      REQUIRE(d.op[k] >= s.loop.controller.op_min);
      REQUIRE(d.op[k] <= s.loop.controller.op_max);
    }
    // Every scenario has set-point changes, and the loop follows them: PV moves.
    const auto [lo, hi] = std::minmax_element(d.pv.begin(), d.pv.end());
    CHECK(*hi - *lo > 3.0);
  }
}

TEST_CASE("paper-ex1: He valve gives a stick-slip limit cycle, a linear valve settles") {
  Scenario sticky = scenario_by_name("paper-ex1");
  Scenario linear = sticky;
  linear.loop.valve.clear();
  const double noise = sticky.loop.measurement_noise_std;
  REQUIRE(noise > 0.0);
  // Longer than the default so that the end is far from the last set-point change (1200 s).
  const std::size_t n = 10000;  // 5000 s
  const LoopData s = run_scenario(sticky, 7, n);
  const LoopData l = run_scenario(linear, 7, n);
  const std::size_t tail = index_at(s, 3500.0);

  // Sticky valve: the valve keeps slipping up and down to the end and OP keeps reversing.
  int up = 0, down = 0;
  for (std::size_t k = tail; k < n; ++k) {
    up += s.mv[k] - s.mv[k - 1] > 1.0;
    down += s.mv[k] - s.mv[k - 1] < -1.0;
  }
  CHECK(up >= 1);
  CHECK(down >= 1);
  CHECK(reversals(s.op, tail, 1.0) >= 2);
  const auto [plo, phi] =
      std::minmax_element(s.pv.begin() + static_cast<std::ptrdiff_t>(tail), s.pv.end());
  CHECK(*phi - *plo > 20.0 * noise);

  // Linear valve: PV at the set point within noise, OP still.
  double e2 = 0, e = 0;
  for (std::size_t k = tail; k < n; ++k) {
    e += l.pv[k] - l.sp[k];
    e2 += (l.pv[k] - l.sp[k]) * (l.pv[k] - l.sp[k]);
  }
  const double cnt = static_cast<double>(n - tail);
  CHECK(std::abs(e / cnt) < 0.05);
  CHECK(std::sqrt(e2 / cnt) < 1.5 * noise);
  const auto [olo, ohi] =
      std::minmax_element(l.op.begin() + static_cast<std::ptrdiff_t>(tail), l.op.end());
  CHECK(*ohi - *olo < 1.0);

  // The default record: OP travels over a 10-30 % range, as the paper's Figure 8 suggests.
  const LoopData d = run_scenario(sticky, 7, 0);
  const auto [dlo, dhi] = std::minmax_element(d.op.begin(), d.op.end());
  CHECK(*dhi - *dlo > 10.0);
  CHECK(*dhi - *dlo < 30.0);
}

TEST_CASE("configs/scenarios/paper-ex1.toml is the built-in paper-ex1") {
  const Scenario file = load_scenario_file(kConfigDir + "paper-ex1.toml");
  const Scenario builtin = scenario_by_name("paper-ex1");
  CHECK(file.name == builtin.name);
  CHECK(file.description == builtin.description);
  CHECK(file.default_samples == builtin.default_samples);
  const LoopData a = run_scenario(file, 2024, 0);
  const LoopData b = run_scenario(builtin, 2024, 0);
  CHECK(a.t == b.t);
  CHECK(a.sp == b.sp);
  CHECK(a.op == b.op);
  CHECK(a.pv == b.pv);
  CHECK(a.mv == b.mv);
}

TEST_CASE("scenario_to_toml reads back to the same simulation for every scenario") {
  for (const auto& name : scenario_names()) {
    CAPTURE(name);
    const Scenario s = scenario_by_name(name);
    const std::string text = scenario_to_toml(s);
    const Scenario back = parse_scenario_toml(text, name + ".toml");
    CHECK(back.name == s.name);
    CHECK(back.description == s.description);
    CHECK(back.loop.valve.size() == s.loop.valve.size());
    const LoopData a = run_scenario(s, 5, 1500);
    const LoopData b = run_scenario(back, 5, 1500);
    CHECK(a.pv == b.pv);
    CHECK(a.mv == b.mv);
  }
}

TEST_CASE("Scenario file errors name the file, the line and the key") {
  SUBCASE("minimal file is fine and takes the defaults") {
    const Scenario s = parse_scenario_toml(kMinimal, "configs/scenarios/mini.toml");
    CHECK(s.name == "mini");
    CHECK(s.default_samples == 3000);
    CHECK(s.loop.controller.op0 == 50.0);
    CHECK(s.loop.valve.empty());
  }
  SUBCASE("unknown key (a typo)") {
    const auto e = parse_error(kMinimal +
                               "\n[[valve]]\neffect = \"stiction\"\nmodel = \"he\"\n"
                               "fs = 8.4\nfdd = 3.5\n");
    CHECK(e.line() == 14);
    CHECK(e.key() == "valve[1].fdd");
    const std::string m = e.what();
    CHECK(m.find("bad.toml:14:") == 0);
    CHECK(m.find("fd") != std::string::npos);  // lists the keys that are allowed
  }
  SUBCASE("wrong type") {
    std::string text = kMinimal;
    text.replace(text.find("kc = 1.0"), 8, "kc = \"fast\"");
    const auto e = parse_error(text);
    CHECK(e.line() == 3);
    CHECK(e.key() == "controller.kc");
    CHECK(std::string(e.what()).find("expected a number") != std::string::npos);
  }
  SUBCASE("missing key: reported at the table") {
    std::string text = kMinimal;
    text.replace(text.find("gain = 2.0\n"), 11, "");
    const auto e = parse_error(text);
    CHECK(e.line() == 5);
    CHECK(e.key() == "process.gain");
    CHECK(std::string(e.what()).find("add `gain = <number>`") != std::string::npos);
  }
  SUBCASE("value the model rejects") {
    const auto e = parse_error(kMinimal +
                               "\n[[valve]]\neffect = \"deadband\"\nd = 1\n"
                               "\n[[valve]]\neffect = \"stiction\"\nmodel = \"he\"\n"
                               "fs = 1.0\nfd = 3.5\n");
    CHECK(e.line() == 14);
    CHECK(e.key() == "valve[2]");
    CHECK(std::string(e.what()).find("fs >= fd") != std::string::npos);
  }
  SUBCASE("unknown effect and unknown model name the choices") {
    auto e = parse_error(kMinimal + "[[valve]]\neffect = \"sticktion\"\n");
    CHECK(e.key() == "valve[1].effect");
    CHECK(std::string(e.what()).find("deadband") != std::string::npos);
    e = parse_error(kMinimal + "[[valve]]\neffect = \"stiction\"\nmodel = \"karnopp\"\n");
    CHECK(e.key() == "valve[1].model");
    CHECK(e.line() == 11);
    CHECK(std::string(e.what()).find("kano") != std::string::npos);
  }
  SUBCASE("set points out of order") {
    const auto e = parse_error(kMinimal +
                               "[[setpoint]]\ntime = 10\nvalue = 1\n[[setpoint]]\ntime = 5\n"
                               "value = 2\n");
    CHECK(e.key() == "setpoint[2].time");
    CHECK(e.line() == 13);
  }
  SUBCASE("TOML syntax error") {
    const auto e = parse_error(kMinimal + "[noise]\nmeasurement_std = = 0.1\n");
    CHECK(e.line() == 10);
    CHECK(e.key().empty());
    CHECK(std::string(e.what()).find("bad.toml:10:") == 0);
  }
  SUBCASE("missing file") {
    CHECK_THROWS_AS(load_scenario_file(kConfigDir + "no-such-scenario.toml"), ScenarioFileError);
  }
}

TEST_CASE("The simulator records where each effect acted") {
  SUBCASE("saturation: exactly where the limits clamp the valve") {
    const ScenarioRun r = run_scenario_traced(scenario_by_name("saturation"), 1, 0);
    const EffectActivity* a = r.find("saturation");
    REQUIRE(a != nullptr);
    CHECK(a->samples > 50);
    std::size_t clamped = 0;
    for (std::size_t k = 0; k < r.data.size(); ++k) {
      const bool at_limit = r.data.op[k] > 70.0 || r.data.op[k] < 5.0;
      clamped += at_limit;
      CHECK(a->overlaps(k, k + 1) == at_limit);
    }
    CHECK(clamped == a->samples);
    CHECK(r.find("disturbance") != nullptr);
    CHECK(r.find("stiction") == nullptr);
  }
  SUBCASE("stiction: every sample where OP moves and the valve stays put is inside") {
    const ScenarioRun r = run_scenario_traced(scenario_by_name("paper-ex1"), 1, 0);
    const EffectActivity* a = r.find("stiction");
    REQUIRE(a != nullptr);
    REQUIRE(!a->intervals.empty());
    CHECK(a->samples > r.data.size() / 4);
    std::size_t stuck = 0;
    for (std::size_t k = 1; k < r.data.size(); ++k) {
      if (r.data.op[k] == r.data.op[k - 1] || r.data.mv[k] != r.data.mv[k - 1]) continue;
      ++stuck;
      CHECK(a->overlaps(k, k + 1));
    }
    CHECK(stuck > 0);
    CHECK(stuck <= a->samples);         // short gaps between stuck stretches are bridged
    CHECK(r.find("delay") != nullptr);  // 2.5 s dead time = 5 samples
  }
  SUBCASE("process effects: delay, order, integrator, and a linear valve records nothing") {
    const ScenarioRun d = run_scenario_traced(scenario_by_name("dead-time"), 1, 0);
    REQUIRE(d.find("delay") != nullptr);
    CHECK(d.find("delay")->samples > 0);
    CHECK(d.activity.size() == 2);  // delay and the filtered load noise
    const ScenarioRun o = run_scenario_traced(scenario_by_name("third-order"), 1, 0);
    REQUIRE(o.find("order") != nullptr);
    CHECK(o.find("order")->samples > 0);
    const ScenarioRun l = run_scenario_traced(scenario_by_name("level"), 1, 0);
    REQUIRE(l.find("integrator") != nullptr);
    CHECK(l.find("integrator")->samples > 0);
    const ScenarioRun a = run_scenario_traced(scenario_by_name("slow-actuator"), 1, 0);
    REQUIRE(a.find("actuator-lag") != nullptr);
    CHECK(a.find("actuator-lag")->samples > 0);
    // The traced run is the plain run.
    CHECK(a.data.pv == run_scenario(scenario_by_name("slow-actuator"), 1, 0).pv);
  }
}
