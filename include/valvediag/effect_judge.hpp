// Does an effect help? The judge of a trial fit (a model with the effect added) against the model
// it extends, on statistics a control engineer reads (Box-Jenkins prediction-error scoring):
//
//  - Each model gets a noise model: an AR model of its simulated output's residual, fitted to the
//    estimation part by least squares, its order chosen by BIC (y = G x + e / A_n). A slow load,
//    an integrator's drift or a misfit the model leaves is then predicted from the residual's
//    own past, as MATLAB's compare(data, model, k) does with a model's noise model.
//  - PV is predicted k samples ahead: the simulated output plus the residual the noise model
//    predicts from the measured past, k the start model's response time (prediction_horizon,
//    model_fit.hpp). Unlike the simulated output it stays meaningful for an integrating process,
//    a drifting load and a long record, where a simulation runs away and its fitness (-800 %)
//    says nothing. Gains are k-step fits in % (100 (1 - |y - y_k| / |y - mean y|)).
//  - On the held-out part: the likelihood ratio N_eff ln(SSE_model / SSE_trial) of the k-step
//    errors, N_eff the effective number of independent samples of the model's errors there
//    (autocorrelation.hpp): k-step errors overlap, and a slow excursion is not many proofs. With
//    the model's N_eff every trial of one model counts the same samples, so their ratios rank as
//    their errors do and two trials differ by the difference of their ratios. Against
//    chi-square with one degree of freedom (no parameter was fitted there).
//  - On the estimation part, where the trial's extra parameters were fitted: the same ratio
//    against BIC's penalty, the added parameters (the effect's, and the noise model's change)
//    times ln N_eff.
//
// The simulated output's fitness (eq 20) is reported beside these by the callers, never decisive.
#pragma once

#include <cstddef>
#include <limits>
#include <vector>

#include "valvediag/model_fit.hpp"

namespace valvediag {

struct JudgeOptions {
  // Critical value of the held-out likelihood ratio: 6.635 is chi-square's 1 % level, 1 dof.
  double critical_lr = 6.635;
};

// A model's k-step predictions (its simulated output plus the residual its noise model predicts
// k samples ahead), with where they can be scored.
struct Prediction {
  std::size_t horizon = 0;
  std::vector<double> y_k;  // PV predicted `horizon` ahead; NaN where not predicted
  bool valid = false;       // the fit has a simulated output to predict with
  int noise_order = 0;      // the noise model's AR order
};
Prediction predict(const ModelFit& fit, const std::vector<double>& y, std::size_t horizon);

// The k-step fit (%) of a prediction over [from, to); NaN when nothing there is predicted.
double prediction_fit_percent(const std::vector<double>& y, const Prediction& p, std::size_t from,
                              std::size_t to);

struct Judgement {
  static constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
  std::size_t horizon = 0;  // samples
  // k-step fits of the model and the trial on each part, and the trial's gains in points.
  double model_estimation_fit = kNaN, model_validation_fit = kNaN;
  double trial_estimation_fit = kNaN, trial_validation_fit = kNaN;
  double estimation_gain = kNaN, validation_gain = kNaN;
  // Held out: N_eff ln(SSE_model / SSE_trial), N_eff of the model's errors there; and the
  // Diebold-Mariano t of the same errors (positive: the trial predicts better), reported.
  double validation_lr = kNaN, validation_n_eff = 0.0;
  double validation_t = kNaN;
  // Estimation part: N_eff ln(SSE_model / SSE_trial) and BIC's penalty for the added parameters.
  double estimation_lr = kNaN, estimation_penalty = kNaN, estimation_n_eff = 0.0;
  double added_parameters = 0.0;
  // The trial predicts the held-out part better beyond chance and earns its parameters on the
  // estimation part.
  bool significant = false;
};

// The trial against the model, both fitted to y with the same estimation part [.., e0) and
// scored over the samples both predict. added_parameters: what the trial's effect adds
// (effect_parameter_count).
Judgement judge(const std::vector<double>& y, std::size_t e0, const Prediction& model,
                const Prediction& trial, double added_parameters, const JudgeOptions& opt = {});

// The held-out test's one-sided confidence that the trial predicts better, when the estimation
// part pays for its parameters, else 0: chi-square's distribution function at the held-out
// likelihood ratio (1 dof).
double confidence(const Judgement& j);

// N_eff ln(SSE_a / SSE_b) of two error series over the same samples, N_eff of the smaller one's
// errors: positive when b predicts better. NaN with fewer than 10 samples.
double likelihood_ratio(const std::vector<double>& ea, const std::vector<double>& eb);

// Diebold-Mariano t of two error series over the same samples (positive: b's errors are
// smaller), with the effective sample size of the loss differences; n_eff receives it. NaN when
// fewer than 10 samples or the differences are constant.
double diebold_mariano(const std::vector<double>& ea, const std::vector<double>& eb,
                       double* n_eff = nullptr);

}  // namespace valvediag
