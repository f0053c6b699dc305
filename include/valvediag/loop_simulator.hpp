// Discrete-time closed loop at sample period Ts:
//   set point r -> PI controller -> OP u -> valve chain -> valve position x -> process -> y
// with load disturbances (at the process output or input) and white measurement noise; the
// controller sees the noisy measured PV. All randomness comes from std::mt19937_64 engines
// seeded from one seed (one engine per noise source, so switching one source on or off leaves
// the others' sequences unchanged) through std::normal_distribution: a seed reproduces a run
// exactly with the same standard library.
#pragma once

#include <cstddef>
#include <cstdint>
#include <limits>
#include <random>
#include <vector>

#include "valvediag/loop_data.hpp"
#include "valvediag/process_models.hpp"
#include "valvediag/valve_effects.hpp"

namespace valvediag {

struct PiSettings {
  double kc = 1.0;        // gain, % of OP per PV unit (negative for a reverse-acting loop)
  double ti = 100.0;      // integral time, s
  double op_min = 0.0;    // OP clamp, %
  double op_max = 100.0;  // OP clamp, %
  double op0 = 50.0;      // OP the loop starts at rest with, %
};

// C(s) = Kc (1 + 1/(Ti s)) in velocity (incremental) form, backward Euler for the integral:
//   u(k) = clamp(u(k-1) + Kc (e(k) - e(k-1)) + Kc Ts/Ti e(k), op_min, op_max),  e = r - y_m.
// Storing the clamped u is the anti-windup: the integral cannot run on beyond the limits.
class PiController {
 public:
  PiController(const PiSettings& settings, double Ts);  // throws std::invalid_argument
  void reset(double op0);  // at rest at op0; the first error then causes no proportional kick
  double step(double sp, double pv);
  double output() const { return u_; }
  const PiSettings& settings() const { return settings_; }

 private:
  PiSettings settings_;
  double Ts_;
  double u_ = 0.0, e_prev_ = 0.0;
  bool first_ = true;
};

// Where a disturbance enters: added to the PV, or to the valve position before the process
// (a load change the process dynamics filter).
enum class DisturbanceEntry { output, input };

struct StepDisturbance {
  double time = 0.0;  // s
  double size = 0.0;
  DisturbanceEntry entry = DisturbanceEntry::output;
};
// Ramp of `slope` per second from `start`, held at its value after `stop`.
struct DriftDisturbance {
  double start = 0.0;
  double slope = 0.0;
  double stop = std::numeric_limits<double>::infinity();
  DisturbanceEntry entry = DisturbanceEntry::output;
};
// First-order filtered white Gaussian noise with stationary standard deviation `std` and time
// constant `tau` (exact discretization e(k+1) = a e(k) + std sqrt(1 - a^2) w(k), a = e^{-Ts/tau}),
// started from its stationary distribution.
struct NoiseDisturbance {
  double std = 0.0;
  double tau = 1.0;  // s
  DisturbanceEntry entry = DisturbanceEntry::output;
};
struct Disturbances {
  std::vector<StepDisturbance> steps;
  std::vector<DriftDisturbance> drifts;
  std::vector<NoiseDisturbance> noises;
};
std::string to_string(DisturbanceEntry entry);  // "output", "input"

// Set point `value` from `time` on (until the next step). Before the first step: process pv0.
struct SetpointStep {
  double time = 0.0;
  double value = 0.0;
};

struct LoopConfig {
  double Ts = 1.0;  // s
  PiSettings controller;
  std::vector<ValveEffect> valve;  // applied in order; empty = linear valve (x = u)
  ProcessSpec process;
  Disturbances disturbances;
  double measurement_noise_std = 0.0;  // white, PV units
  std::vector<SetpointStep> setpoint;  // non-decreasing times
};
// Checks the whole configuration (Ts, controller, set point order, noise, actuator-lag blocks
// built for this Ts, process parameters); throws std::invalid_argument naming the problem.
void validate(const LoopConfig& config);

// One sample of the loop: t, set point, OP, measured PV and the true valve position.
struct LoopSample {
  double t, sp, op, pv, mv;
};

class LoopSimulator {
 public:
  LoopSimulator(LoopConfig config, std::uint64_t seed);  // validates; starts at rest
  void reset(std::uint64_t seed);                        // back to t = 0 with a new seed
  LoopSample step();
  // The next `samples` samples as LoopData (sp and mv filled); `source` names the run.
  LoopData run(std::size_t samples, const std::string& source = "simulation");
  const LoopConfig& config() const { return config_; }

 private:
  double setpoint_at(double t) const;
  double deterministic_disturbance(double t, DisturbanceEntry entry) const;

  LoopConfig config_;
  PiController pi_;
  ValveChain valve_;
  DiscreteProcess process_;
  std::vector<double> noise_state_;
  std::vector<std::mt19937_64> noise_engines_;
  std::mt19937_64 measurement_engine_;
  std::normal_distribution<double> normal_{0.0, 1.0};
  std::vector<std::normal_distribution<double>> noise_normals_;
  std::size_t k_ = 0;
};

// Convenience: a fresh simulator run for `samples` samples.
LoopData simulate_loop(const LoopConfig& config, std::uint64_t seed, std::size_t samples);

}  // namespace valvediag
