#pragma once
// A trial's valve effect fitted again, to predict PV one step ahead (prediction_error.hpp)
// rather than to track it in simulation. In closed loop the simulated output from OP can
// prefer a model without the effect (OP carries the load through the controller); the
// one-step prediction of a flexible linear model from the valve position does not, so the
// effect's parameters it prefers are the ones the prediction ranking should score (measured,
// development seed 48: Kano stiction of S 1.97, the simulated-output search found S 0.003,
// one-step prediction is least near S 2).
#include <cstddef>
#include <string>
#include <vector>

#include "valvediag/diagnose/prediction_error.hpp"
#include "valvediag/model/effect_estimators.hpp"
#include "valvediag/model/model_fit.hpp"

namespace valvediag {

struct PredictionRefitOptions {
  std::size_t order = 12;          // the ARX predictor's na = nb
  std::size_t nk_max = 10;         // its dead time is profiled over [0, nk_max]
  std::size_t from = 0;            // first sample scored (>= nk_max + order)
  std::size_t estimation_end = 0;  // fitted on [from, estimation_end); held out after
  bool integrating = false;        // the predictor's A has the factor (1 - q^-1)
  std::size_t grid_points = 16;    // the first coordinate's grid before the local polish
  int local_evaluations = 60;      // Nelder-Mead's budget per searched coordinate
};

struct PredictionRefit {
  bool ok = false;                     // false: the trial has no such block, or nothing predicted
  PredictionError error;               // at the refitted parameters, the dead time profiled
  bool moved = false;                  // false: the trial's own parameters predicted best
  std::vector<NamedValue> parameters;  // the effect's block as refitted (block_parameters)
  std::vector<double> x_hat;           // the valve position it gives
  int evaluations = 0;
};

// Whether the diagnosis refits `effect` to the prediction: a valve effect (the actuator's lag
// too) or `order`'s extra lag, which commutes with it on a linear valve. Not the Preisach plane
// (no coordinates) nor its position-dependent friction (six), nor `delay` (its dead time is the
// predictor's own, profiled).
bool refitted_to_prediction(const std::string& effect);

// Refits the block of `effect` in `trial`'s valve chain (the other blocks held) to minimize
// the one-step prediction error on the estimation part: a grid over the effect's first search
// coordinate with the others at the trial's values; for a friction, a grid over its band (half
// to 2.2 times that grid's best) and its second coordinate (the whole range); then Nelder-Mead
// over all of them from the best point (profiled coordinates, as the valve search's, take their
// best value at each point). The trial's own parameters are a candidate, so the refit never
// predicts worse. Each point is scored by PredictionErrorSearch at the trial's best dead time.
PredictionRefit refit_by_prediction(const std::vector<double>& u, const std::vector<double>& y,
                                    double Ts, const ModelFit& trial, const std::string& effect,
                                    const PredictionRefitOptions& opt);

}  // namespace valvediag
