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
#include <string>
#include <utility>
#include <vector>

#include "valvediag/io/loop_data.hpp"
#include "valvediag/sim/process_models.hpp"
#include "valvediag/sim/valve_effects.hpp"

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

// Where one effect of the simulated loop acted: the ground truth a diagnosis is checked against.
//   valve blocks: stiction (every model), deadband, preisach: stuck, OP moving while the valve
//     stays put; saturation: the block clamps; characteristic: the local slope of the map differs
//     from its mean slope over the run by more than 20 %; actuator-lag: the valve lags OP by more
//     than `move` (below);
//   delay: the process still sees a valve position that differs by more than `move` from the
//     current one (the dead time hides a move);
//   order: within the extra lags' settling time (tau2 + tau3) after a valve move larger than
//     `move` (a second-order process, or one with a third lag);
//   integrator: the process input (valve position plus input load) is off the balance it started
//     at by more than `move` (PV ramps);
//   disturbance: the loads' effect on PV (output loads plus input loads through the process) is
//     larger than twice the measurement noise (0.1 PV units when noise-free).
struct EffectActivity {
  std::string effect;  // effect name (effects.md): "stiction", "saturation", "delay", ...
  std::string detail;  // what "acted" means for it, one line
  std::vector<std::pair<std::size_t, std::size_t>> intervals;  // samples [begin, end), in order
  std::size_t samples = 0;                                     // samples inside them
  // True when [begin, end) overlaps an interval.
  bool overlaps(std::size_t begin, std::size_t end) const;
};

class LoopSimulator {
 public:
  LoopSimulator(LoopConfig config, std::uint64_t seed);  // validates; starts at rest
  void reset(std::uint64_t seed);                        // back to t = 0 with a new seed
  // Whether step() keeps the per-sample trace that activity() and valve_pv() read (default on).
  // A simulator stepped without end (the simulated PLC) turns it off: it would grow by a few
  // values per sample for as long as it runs.
  void keep_trace(bool on) { keep_trace_ = on; }
  LoopSample step();
  // The next `samples` samples as LoopData (sp and mv filled); `source` names the run.
  LoopData run(std::size_t samples, const std::string& source = "simulation");
  const LoopConfig& config() const { return config_; }
  // Where each effect of the loop acted since the last reset (see EffectActivity), one entry per
  // valve block (in chain order) and per process effect present (delay, order, integrator,
  // disturbance). `move`: a valve move or lag worth noting, % (default 0.5).
  std::vector<EffectActivity> activity(double move = 0.5) const;
  // PV as the valve alone moves it since the last reset, one value per sample: the process
  // driven by the valve position from rest, without the loads and the measurement noise (the
  // true model's output, to measure what any model of the valve and process could explain).
  const std::vector<double>& valve_pv() const { return trace_.valve_pv; }

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
  // What activity() needs, one entry per sample since the last reset.
  struct Trace {
    std::vector<std::vector<double>> block_in, block_out;  // per valve block
    std::vector<double> x, process_in, load_pv, valve_pv;
  };
  Trace trace_;
  bool keep_trace_ = true;
  DiscreteProcess load_process_;  // the process driven by the input loads only (from rest)
  double x_rest_ = 0.0;
};

// Convenience: a fresh simulator run for `samples` samples.
LoopData simulate_loop(const LoopConfig& config, std::uint64_t seed, std::size_t samples);

}  // namespace valvediag
