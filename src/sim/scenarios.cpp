#include "valvediag/sim/scenarios.hpp"

#include <functional>
#include <utility>

namespace valvediag {
namespace {

using Builder = std::function<Scenario()>;

// The paper's Example 1 loop (section 6): PI C(s) = 0.25 (1 + 1/(50 s)), G(s) = 3.8163
// e^{-2.5 s} / (156.46 s + 1), Ts = 0.5 s. The operating point (OP 50 %, PV 50) and the set-point
// steps are ours: the paper only shows them in its Figure 8.
Scenario paper_ex1_linear() {
  Scenario s;
  s.name = "paper-ex1-linear";
  s.description =
      "paper Example 1 loop (PI 0.25/50 s, 3.8163 e^-2.5s/(156.46 s + 1), Ts 0.5 s) with a "
      "linear valve: settles after each set-point step";
  s.default_samples = 3000;
  LoopConfig& c = s.loop;
  c.Ts = 0.5;
  c.controller = {0.25, 50.0, 0.0, 100.0, 50.0};
  c.process = first_order_process(3.8163, 156.46, 2.5, 50.0);
  c.measurement_noise_std = 0.1;
  // A few set-point changes that start the stick-slip cycle and move it over the OP range.
  c.setpoint = {{0.0, 50.0}, {50.0, 57.0}, {450.0, 45.0}, {900.0, 55.0}, {1200.0, 52.0}};
  return s;
}

Scenario paper_ex1() {
  Scenario s = paper_ex1_linear();
  s.name = "paper-ex1";
  s.description =
      "paper Example 1: the same PI loop with He stiction fs = 8.4, fd = 3.5243; stick-slip "
      "limit cycle (identification target na = nb = 1, nk = 5, L = 16)";
  s.loop.valve = {HeStiction(8.4, 3.5243)};
  return s;
}

// The paper's loop with He's valve written as its Preisach equivalent (Proposition 1) on a fine
// grid: exercises the `preisach` block in closed loop.
Scenario preisach_he() {
  Scenario s = paper_ex1_linear();
  s.name = "preisach";
  s.description =
      "paper Example 1 loop with a Preisach valve carrying he_stiction_weights(fs 8.4, fd "
      "3.5243) on L = 40 over 0..100 %";
  const PreisachGrid grid{0.0, 100.0, 40};
  const PreisachWeights w = he_stiction_weights(grid, 8.4, 3.5243);
  s.loop.valve = {PreisachValve(grid, w.mu, w.offset)};
  return s;
}

// A temperature-like self-regulating loop, IMC-tuned (lambda = 20 s): the reference for the
// valve effects below, which reuse its process and controller.
Scenario base_loop(const std::string& name, const std::string& description) {
  Scenario s;
  s.name = name;
  s.description = description;
  s.default_samples = 3000;
  LoopConfig& c = s.loop;
  c.Ts = 1.0;
  c.controller = {1.4, 40.0, 0.0, 100.0, 50.0};
  c.process = first_order_process(1.2, 40.0, 4.0, 50.0);
  c.measurement_noise_std = 0.1;
  c.disturbances.noises = {{0.4, 60.0, DisturbanceEntry::output}};
  c.setpoint = {{0.0, 50.0}, {500.0, 56.0}, {1100.0, 47.0}, {1800.0, 53.0}, {2400.0, 50.0}};
  return s;
}

Scenario linear_clean() {
  Scenario s = base_loop(
      "linear-clean",
      "no valve problem: first-order loop (K 1.2, tau 40 s, theta 4 s) with filtered load "
      "noise, a 5 % load step at the valve at t = 1500 s and measurement noise");
  s.loop.disturbances.steps = {{1500.0, 5.0, DisturbanceEntry::input}};
  return s;
}

Scenario deadband() {
  Scenario s = base_loop("deadband",
                         "4 % backlash in the valve linkage: lag after every OP reversal, no jump");
  s.loop.valve = {Deadband(4.0)};
  return s;
}

Scenario kano() {
  Scenario s = base_loop("kano", "Kano stiction S = 5 %, J = 2 %: stick-slip limit cycle");
  s.loop.valve = {KanoStiction(5.0, 2.0)};
  return s;
}

Scenario choudhury() {
  Scenario s = base_loop("choudhury",
                         "Choudhury stiction S = 5 %, J = 2 %: stick-slip limit cycle; noise-free "
                         "loop with a 3 % load step at the valve at t = 1500 s");
  s.loop.valve = {ChoudhuryStiction(5.0, 2.0)};
  // Choudhury's model re-sticks at every reversal of OP, so OP noise larger than the integral
  // action's drift per sample keeps the valve frozen while OP wanders tens of %: the model was
  // made for smooth controller outputs, so this loop has none.
  s.loop.measurement_noise_std = 0.0;
  s.loop.disturbances.noises.clear();
  s.loop.disturbances.steps = {{1500.0, 3.0, DisturbanceEntry::input}};
  return s;
}

Scenario stenman() {
  Scenario s = base_loop("stenman", "Stenman stiction d = 3 %: the valve jumps to OP after 3 %");
  s.loop.valve = {StenmanStiction(3.0)};
  return s;
}

Scenario asymmetric_stiction() {
  Scenario s = base_loop(
      "asymmetric-stiction",
      "position-dependent stiction, severe near the closed end (fs 8 %, fd 3 % below 20 %) and "
      "mild above 40 % (fs 1.5 %, fd 0.5 %), like the paper's Example 2 valve");
  LoopConfig& c = s.loop;
  c.controller.op0 = 15.0;
  c.process = first_order_process(1.2, 40.0, 4.0, 18.0);
  c.valve = {PositionDependentStiction({{20.0, 8.0, 3.0}, {40.0, 1.5, 0.5}})};
  c.setpoint = {{0.0, 18.0},    {400.0, 30.0},  {900.0, 45.0},
                {1400.0, 62.0}, {1900.0, 45.0}, {2400.0, 24.0}};
  return s;
}

Scenario saturation() {
  Scenario s = base_loop(
      "saturation",
      "valve travel limited to 5..70 %: the 80 set point cannot be reached, PV stops following OP");
  LoopConfig& c = s.loop;
  c.valve = {Saturation(5.0, 70.0)};
  c.setpoint = {{0.0, 50.0}, {500.0, 60.0}, {1000.0, 80.0}, {1700.0, 55.0}, {2400.0, 45.0}};
  return s;
}

Scenario characteristic() {
  Scenario s = base_loop(
      "characteristic",
      "equal-percentage valve (R = 50) on a linear-tuned loop: the loop gain grows fivefold from "
      "OP 50 % to OP 90 %");
  LoopConfig& c = s.loop;
  c.valve = {Characteristic(Characteristic::Kind::equal_percentage, 50.0)};
  c.controller = {1.2, 40.0, 0.0, 100.0, 60.0};
  c.process = first_order_process(1.2, 40.0, 4.0, 30.0);
  c.setpoint = {{0.0, 30.0}, {500.0, 42.0}, {1100.0, 60.0}, {1800.0, 40.0}, {2400.0, 25.0}};
  return s;
}

Scenario actuator_lag() {
  Scenario s =
      base_loop("actuator-lag", "slow actuator (tau = 15 s) in a loop tuned for an ideal valve");
  s.loop.valve = {ActuatorLag(15.0, s.loop.Ts)};
  return s;
}

Scenario integrating() {
  Scenario s;
  s.name = "integrating";
  s.description =
      "level loop K = 0.01 %/s per % valve, theta = 3 s, SIMC-tuned PI; outflow drift and a "
      "5 % inflow step at the valve";
  s.default_samples = 3000;
  LoopConfig& c = s.loop;
  c.Ts = 1.0;
  c.controller = {1.6, 250.0, 0.0, 100.0, 50.0};
  c.process = integrating_process(0.01, 3.0, 0.0, 50.0);
  c.measurement_noise_std = 0.1;
  c.disturbances.steps = {{1300.0, -5.0, DisturbanceEntry::input}};
  c.disturbances.drifts = {{200.0, 0.002, 2200.0, DisturbanceEntry::input}};
  c.setpoint = {{0.0, 50.0}, {400.0, 60.0}, {2000.0, 45.0}};
  return s;
}

Scenario second_order() {
  Scenario s;
  s.name = "second-order";
  s.description =
      "second-order loop K = 1.5, tau 50 s and 15 s, theta 5 s, SIMC-tuned PI, linear valve";
  s.default_samples = 3000;
  LoopConfig& c = s.loop;
  c.Ts = 1.0;
  c.controller = {1.5, 57.5, 0.0, 100.0, 50.0};
  c.process = second_order_process(1.5, 50.0, 15.0, 5.0, 50.0);
  c.measurement_noise_std = 0.1;
  c.disturbances.noises = {{0.4, 80.0, DisturbanceEntry::output}};
  c.setpoint = {{0.0, 50.0}, {500.0, 56.0}, {1100.0, 46.0}, {1800.0, 52.0}, {2400.0, 50.0}};
  return s;
}

// The process effects hidden from a `linear` start (whose base grid is na, nb <= 2, nk <= 10):
// each a plain loop with a linear valve, filtered load noise and measurement noise, set-point
// steps every few minutes (a step test), and one process feature that grid cannot carry.
Scenario process_loop(const std::string& name, const std::string& description) {
  Scenario s = base_loop(name, description);
  s.loop.measurement_noise_std = 0.05;
  s.loop.disturbances.noises = {{0.08, 60.0, DisturbanceEntry::output}};
  s.loop.setpoint = {{0.0, 50.0},    {150.0, 55.0},  {400.0, 47.0},  {600.0, 52.0},  {850.0, 44.0},
                     {1100.0, 50.0}, {1300.0, 56.0}, {1550.0, 49.0}, {1800.0, 53.0}, {2000.0, 46.0},
                     {2250.0, 51.0}, {2500.0, 55.0}, {2750.0, 48.0}};
  return s;
}

Scenario dead_time() {
  Scenario s = process_loop(
      "dead-time",
      "dead-time dominant loop (transport line): first-order process (K 1.2, tau 4 s) with a 26 s "
      "dead time and a PI tuned too tight for it (kc 0.3, ti 8 s): it rings after set-point steps");
  s.loop.controller = {0.3, 8.0, 0.0, 100.0, 50.0};
  s.loop.process = first_order_process(1.2, 4.0, 26.0, 50.0);
  return s;
}

Scenario third_order() {
  Scenario s =
      process_loop("third-order",
                   "three lags in series (K 1.2; 30, 20 and 16 s; theta 2 s), PI: more lags than a "
                   "second-order model carries");
  s.loop.controller = {0.9, 50.0, 0.0, 100.0, 50.0};
  s.loop.process = second_order_process(1.2, 30.0, 20.0, 2.0, 50.0);
  s.loop.process.tau3 = 16.0;
  return s;
}

Scenario slow_actuator() {
  Scenario s = process_loop(
      "slow-actuator",
      "slow actuator (tau 20 s) on a second-order process (K 1.2; 40 and 10 s; theta 2 s): the "
      "actuator lag is a third lag the second-order fit cannot carry");
  s.loop.controller = {0.9, 50.0, 0.0, 100.0, 50.0};
  s.loop.process = second_order_process(1.2, 40.0, 10.0, 2.0, 50.0);
  s.loop.valve = {ActuatorLag(20.0, s.loop.Ts)};
  return s;
}

Scenario load_changes() {
  Scenario s = base_loop(
      "load-changes",
      "unmeasured load changes: first-order loop with slow filtered load noise at the valve (std "
      "4 %, tau 300 s), two load steps and a drift, linear valve");
  s.loop.disturbances.noises = {{4.0, 300.0, DisturbanceEntry::input},
                                {0.2, 60.0, DisturbanceEntry::output}};
  s.loop.disturbances.steps = {{800.0, 6.0, DisturbanceEntry::input},
                               {1900.0, -8.0, DisturbanceEntry::input}};
  s.loop.disturbances.drifts = {{1200.0, 0.004, 1700.0, DisturbanceEntry::output}};
  return s;
}

Scenario level() {
  Scenario s;
  s.name = "level";
  s.description =
      "surge-tank level loop K = 0.01 %/s per % valve, theta = 3 s, averaging PI (kc 0.8, ti "
      "600 s) that lets the level swing; level waves and sensor noise on the measurement";
  s.default_samples = 3000;
  LoopConfig& c = s.loop;
  c.Ts = 1.0;
  c.controller = {0.8, 600.0, 0.0, 100.0, 50.0};
  c.process = integrating_process(0.01, 3.0, 0.0, 50.0);
  c.measurement_noise_std = 0.1;
  c.disturbances.noises = {{0.3, 30.0, DisturbanceEntry::output}};
  c.setpoint = {{0.0, 50.0}, {400.0, 60.0}, {1100.0, 45.0}, {1800.0, 55.0}, {2400.0, 48.0}};
  return s;
}

const std::vector<std::pair<std::string, Builder>>& registry() {
  static const std::vector<std::pair<std::string, Builder>> r = {
      {"paper-ex1", paper_ex1},
      {"paper-ex1-linear", paper_ex1_linear},
      {"linear-clean", linear_clean},
      {"deadband", deadband},
      {"kano", kano},
      {"choudhury", choudhury},
      {"stenman", stenman},
      {"asymmetric-stiction", asymmetric_stiction},
      {"preisach", preisach_he},
      {"saturation", saturation},
      {"characteristic", characteristic},
      {"actuator-lag", actuator_lag},
      {"integrating", integrating},
      {"second-order", second_order},
      {"dead-time", dead_time},
      {"third-order", third_order},
      {"slow-actuator", slow_actuator},
      {"load-changes", load_changes},
      {"level", level},
  };
  return r;
}

}  // namespace

std::vector<std::string> scenario_names() {
  std::vector<std::string> names;
  for (const auto& [name, build] : registry()) names.push_back(name);
  return names;
}

Scenario scenario_by_name(const std::string& name) {
  for (const auto& [n, build] : registry()) {
    if (n == name) return build();
  }
  std::string known;
  for (const auto& [n, build] : registry()) known += (known.empty() ? "" : ", ") + n;
  throw std::invalid_argument("unknown scenario '" + name + "' (known: " + known + ")");
}

LoopData run_scenario(const Scenario& scenario, std::uint64_t seed, std::size_t samples) {
  if (samples == 0) samples = scenario.default_samples;
  LoopSimulator sim(scenario.loop, seed);
  return sim.run(samples, "scenario " + scenario.name + ", seed " + std::to_string(seed));
}

}  // namespace valvediag

namespace valvediag {

const EffectActivity* ScenarioRun::find(const std::string& effect) const {
  for (const auto& a : activity)
    if (a.effect == effect) return &a;
  return nullptr;
}

ScenarioRun run_scenario_traced(const Scenario& scenario, std::uint64_t seed, std::size_t samples) {
  if (samples == 0) samples = scenario.default_samples;
  LoopSimulator sim(scenario.loop, seed);
  ScenarioRun r;
  r.data = sim.run(samples, "scenario " + scenario.name + ", seed " + std::to_string(seed));
  r.activity = sim.activity();
  r.valve_pv = sim.valve_pv();
  return r;
}

}  // namespace valvediag
