// Randomized closed loops for judging the diagnosis on loops nobody tuned it to: every loop
// property drawn from wide, realistic ranges (process type and dynamics, dead time up to a few
// minutes, PI tuning from tight to sluggish, measurement and load noise, load steps, ramps and
// random walks, set-point programme, record length, sample period), with one physical effect
// (../shared/design/effects.md) hidden from the model a diagnosis starts from, two hidden, or
// none (a control).
//
// A case is fair only when its hidden effect acts in both the estimation part and the held-out
// part of the record (the valve really reaches its limit there, really crosses the position where
// its friction changes, ...): fair_case() says which, and draw_random_loop() redraws the loop's
// parameters (from the same seed) until it is, so each seed gives one fair case.
//
// The draw depends on the seed and the requested effect only: the benchmark's development seeds
// and test seeds are disjoint ranges of the same generator.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "valvediag/io/loop_data.hpp"
#include "valvediag/sim/scenarios.hpp"

namespace valvediag {

// One true parameter of a hidden effect, in the units the fitted effect reports: a band, a limit
// or a lag in % of OP or s, a dead time in s, a curvature as ln of the rangeability.
struct TrueParameter {
  std::string effect;  // effect name
  std::string name;    // "band", "limit", "tau", "dead_time", "log_rangeability"
  double value = 0.0;
  std::string unit;
};

struct RandomLoop {
  std::uint64_t seed = 0;
  std::string category;          // what was asked for: an effect, "none" or "pair"
  std::uint64_t noise_seed = 0;  // the simulator's seed (drawn from `seed`)
  // The effects hidden from the start model (empty: a control with nothing hidden).
  std::vector<std::string> hidden;
  // The model a diagnosis starts from: the true model without the hidden effects, written as a
  // model spec ("linear", "stiction", "stiction:kano+integrator", ...), a friction as its own
  // variant. Effects the loop has that are not hidden are in it.
  std::string start_model;
  // The true model spec (start model plus the hidden effects).
  std::string true_model;
  Scenario scenario;  // the loop; scenario.description says what was drawn, in one line
  std::size_t samples = 0;
  double validation_fraction = 0.3;  // the held-out tail the case is made fair for
  std::vector<TrueParameter> truth;  // the hidden effects' true parameters
  int redraws = 0;                   // draws rejected as unfair before this one
};

// The categories the benchmark cycles through: every effect of the vocabulary, "none" (a
// control) and "pair" (two effects hidden).
const std::vector<std::string>& random_loop_categories();

// Draws a fair case of `category` (an effect name, "none" or "pair") from `seed`. Throws
// std::invalid_argument for an unknown category, std::runtime_error when no fair draw was found
// within `max_draws` (the caller reports it; it does not happen with the defaults).
RandomLoop draw_random_loop(std::uint64_t seed, const std::string& category,
                            double validation_fraction = 0.3, int max_draws = 40);

// The same loop simulated (LoopData::source names seed and category).
LoopData simulate_random_loop(const RandomLoop& loop);

// Whether every hidden effect acts in both the estimation part and the held-out part of `data`
// (simulated from `loop`); "" when fair, else why not (one line). Controls are always fair.
std::string fair_case(const RandomLoop& loop, const ScenarioRun& run);

}  // namespace valvediag
