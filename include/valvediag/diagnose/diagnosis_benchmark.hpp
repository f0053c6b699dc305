// The randomized benchmark of the diagnosis (random_loop.hpp): one case is a drawn loop with its
// hidden effects; `diagnose` runs from the case's start model, and the outcome is judged against
// the truth: named first, in the top two, whether adding the true effect gains on held-out data,
// how close its fitted parameters come, and for controls whether anything was found at all.
// scripts/accuracy.sh prints the tables over a development and a test range of seeds; CI runs a
// small fixed sample (test/diagnose/test_benchmark_sample.cpp).
#pragma once

#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "valvediag/diagnose/diagnosis.hpp"
#include "valvediag/sim/random_loop.hpp"

namespace valvediag {

struct ParameterError {
  std::string effect, name;
  double truth = 0.0, estimate = 0.0;
  // The same figure refitted to the one-step prediction (Finding::prediction_parameters; the
  // estimate when the refit kept the trial's), NaN for effects that are not refitted.
  double refit = std::numeric_limits<double>::quiet_NaN();
};

struct BenchmarkOutcome {
  RandomLoop loop;
  std::vector<std::string> ranked;  // the findings' effects, most likely first
  std::vector<bool> supported;      // same order
  std::string first;                // "" when diagnose named nothing
  bool named_first = false;         // a hidden effect ranks first (controls: false)
  bool top_two = false;             // every hidden effect in the top two (one: in the top two)
  bool true_supported = false;      // the (first) hidden effect's finding is supported
  // The hidden effect's trial against the start model: the gain the diagnosis scores (the smaller
  // of the held-out and estimation gains) and the gain on the held-out part, in points.
  double true_gain = 0.0, true_validation_gain = 0.0;
  bool gains = false;  // true_gain >= 2 points (the target)
  // What the true model gains over the fitted start model, in points, on the same parts and as
  // the gains are scored (the smaller of the two parts): the true process driven by the true
  // valve position, without loads or measurement noise (LoopSimulator::valve_pv). Below 2 the
  // issue's target is out of reach of the right model itself: the effect changes PV less than
  // the loads and the noise leave. NaN where not measured: a hidden load (the true model would
  // carry it) or a k-step judge (an integrating start model, whose simulation drifts).
  double true_model_gain = std::numeric_limits<double>::quiet_NaN();
  // The hidden valve effect's search measured against the true valve position: the trial's
  // process part (its spec without the valve effects) fitted with the simulator's valve position
  // as input, its estimation fitness less the trial's, in points. Above 0 the search stopped
  // short of a valve that fits the estimation part better (or the true valve lies outside the
  // trial's class): a miss there is the search's. At or below 0 the search found as good a
  // valve by its own criterion, and a miss is the criterion's or the closed loop's. NaN where
  // not measured: a process effect, two hidden effects, a k-step judge.
  double valve_search_shortfall = std::numeric_limits<double>::quiet_NaN();
  bool false_alarm = false;            // a control with a supported finding
  std::string false_effect;            // what it found
  std::vector<ParameterError> errors;  // the hidden effects' fitted parameters against the truth
  // A case with two hidden effects, climbed (run_benchmark_case's `climb`): the model
  // diagnose_auto reaches from the start model, and how many hidden effects it holds. One step
  // ranks each effect against a model that lacks both; the climb adds one, then looks again.
  bool climbed = false;
  std::string climbed_model;
  std::size_t climb_found = 0;
  // Each finding, ranked: effect:estimation gain/held-out gain/prediction BIC change/held-out
  // prediction gain.
  std::string detail;
  std::vector<Finding> findings;  // the step's findings, ranked (valvediag_accuracy --json)
  KStepJudge judge;               // what their gains measure
  std::vector<ResidualTest> residual_tests;     // the start model's residual analysis
  std::size_t samples = 0, estimation_end = 0;  // the record's, and where its held-out part starts
  double seconds = 0.0;
  std::string error;  // the diagnosis threw: why
};

// Runs the diagnosis of one case (single step from its start model, its validation fraction);
// `climb`: a case with two hidden effects is also climbed (diagnose_auto) from the start model.
BenchmarkOutcome run_benchmark_case(const RandomLoop& loop, DiagnoseOptions opt = {},
                                    bool climb = false);

// The cases of a seed range: seed s draws category random_loop_categories()[s % 12], so any 12
// consecutive seeds hold each category once.
std::vector<std::string> benchmark_categories(std::uint64_t first_seed, std::uint64_t count);

// Per category and overall: counts, named first, top two, gains >= 2, false alarms, parameter
// errors; then the confusion table (hidden effect against first finding). Plain text.
std::string format_benchmark(const std::vector<BenchmarkOutcome>& outcomes,
                             const std::string& title);
// Two ranges side by side (development and test), one row per category.
std::string format_benchmark_pair(const std::vector<BenchmarkOutcome>& dev,
                                  const std::vector<BenchmarkOutcome>& test);

}  // namespace valvediag
