// The whole-record test for a valve with memory: what a held-out tail cannot confirm.
//
// Why: a diagnosis scores each trial on the last part of the record, which confirms a friction
// band only when that part holds slips the band predicts. A valve that slips once or twice in a
// record (the common case in a 2-hour window of a running loop) leaves a tail with one event or
// none: a band learnt from the first part misses a slip that comes a little early, and the
// simulated PV then stays off for the rest of the tail. The trial loses there by a hundred points
// while it explains the whole record far better than any memoryless model.
//
// So, when the trial fits do not confirm it, the record is fitted whole and a valve with memory
// (He's, Kano's or Stenman's stiction, or backlash) is accepted only when
//   - it explains at least `min_relative_gain` of the error the start model leaves, and at
//     least `min_gain_percent` points;
//   - it fits better than every memoryless effect of the vocabulary added alone (saturation,
//     characteristic, actuator lag, delay, more lags, an integrator): a static curve or a lag
//     cannot stand in for it;
//   - it fits at least as well as a slow unmeasured load (`disturbance`) after the load is
//     charged for its extra parameters by the Bayesian information criterion. A load step that
//     the controller compensates leaves OP moved and PV where it was, which a stuck valve
//     imitates; but a load curve with one knot every few minutes explains such a record far
//     better than two friction parameters can, while a slip-stick record is explained by the
//     friction parameters as well as by the whole load curve.
// Both comparisons count parameters by the Bayesian information criterion (a load one level per
// knot, He's stiction its fs, fd and starting motion): a more flexible model must fit better by
// more than its extra parameters would anyway.
// Standard library, Eigen and NLopt only (through model_fit).
#pragma once

#include <cstddef>
#include <limits>
#include <string>
#include <vector>

#include "valvediag/model/model_fit.hpp"
#include "valvediag/model/model_spec.hpp"

namespace valvediag {

struct WholeRecordOptions {
  // The relative gain at which a diagnosis finding's score saturates (diagnosis.cpp): the
  // memory must explain that share of the error left.
  double min_relative_gain = 0.3;
  double min_gain_percent = 2.0;  // as DiagnoseOptions::min_gain_percent
};

struct WholeRecordTest {
  static constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
  bool tested = false;       // false: not needed, or the start model has no stable fit
  bool confirmed = false;    // a valve with memory explains the record (the verdict may rest on it)
  std::string memory_model;  // the best stiction variant's spec, e.g. "stiction:kano"
  double start_fitness = kNaN;     // whole-record fitness of the start model, %
  double memory_fitness = kNaN;    // ... of the start model with the memory
  double relative_gain = kNaN;     // share of the start model's error the memory removes
  double load_fitness = kNaN;      // ... with `disturbance`
  double load_bic_margin = kNaN;   // BIC(load) - BIC(memory); > 0: the memory is preferred
  std::string rival;               // the best memoryless effect
  double rival_fitness = kNaN;     // its whole-record fitness
  double rival_bic_margin = kNaN;  // BIC(rival) - BIC(memory); > 0: the memory is preferred
  // The memoryless effect (or `disturbance`) the record prefers to the memory, "" when none.
  std::string preferred;
  std::vector<FittedEffect> memory_effects;  // the memory model's fitted effects (friction size)
  std::vector<double> memory_coordinates;    // its valve coordinates (ModelFit, band_interval)
  std::string summary;  // one sentence: what was found and why it counts or not
};

// The diagnosis's fit options as the test uses them: without a hold-out (the record is fitted
// whole). For callers that re-examine its memory fit (band_interval).
ModelFitOptions whole_record_fit_options(ModelFitOptions fit);

// u: OP, y: PV, Ts: s. `start` is the diagnosis's start model (no valve effect with memory);
// `fit` the diagnosis's fit options (the hold-out is dropped: the record is fitted whole). The
// memory candidates are He's, Kano's and Stenman's stiction and backlash (`deadband`); the best
// on the whole record is tested. The fits run in stages, cheapest verdict first: the memory
// against the start model, then the load, then the memoryless effects.
WholeRecordTest whole_record_test(const std::vector<double>& u, const std::vector<double>& y,
                                  double Ts, const ModelSpec& start, ModelFitOptions fit,
                                  const WholeRecordOptions& opt = {});

}  // namespace valvediag
