#pragma once
// One-step-ahead prediction error of PV given a model's valve position: the judge between effects
// on the path from OP to PV. Simulated output compares models by how well G x alone tracks PV;
// in closed loop OP carries the load through the controller, so a wrong G can track PV better
// than the true one. The prediction error of a flexible linear model from the same valve
// position (a high-order ARX, which stands for any noise model) is least for the true valve and
// dead time: the direct prediction-error method is consistent in closed loop (Ljung, System
// Identification, 13.4).
#include <cstddef>
#include <limits>
#include <vector>

namespace valvediag {

struct PredictionError {
  bool ok = false;
  std::size_t order = 0;           // na = nb of the ARX structure
  std::size_t nk = 0;              // B's taps from x(t - nk - 1) on
  bool integrating = false;        // A has the factor (1 - q^-1): PV's changes predicted
  bool differenced_input = false;  // and B too: x's changes drive them
  std::size_t parameters = 0;      // coefficients fitted (A's free ones, B's, the constant)
  // Mean squared one-step prediction error on each part; the held-out part's with the
  // coefficients fitted on the estimation part.
  double estimation_variance = std::numeric_limits<double>::quiet_NaN();
  double validation_variance = std::numeric_limits<double>::quiet_NaN();
  std::size_t estimation_samples = 0, validation_samples = 0;
};

// PV predicted one step ahead from its own past and the valve position x: an ARX structure of
// `order` (A and B of that order, B's taps from x(t - nk - 1) on, and a constant) fitted by least
// squares, its prediction-error fit, on [from, estimation_end), scored there and on
// [estimation_end, N). Needs from >= nk + order; not ok on too few samples or non-finite data.
// `integrating`: A = (1 - q^-1) A'(q^-1), A' of order - 1 (the restriction A(1) = 0, one
// coefficient fewer): the change of PV predicted from its past changes and x. A process that
// integrates predicts as well so restricted; one that settles does not.
// `differenced_input` (with `integrating`): B = (1 - q^-1) B'(q^-1) too, B' of order - 1 (B(1) = 0,
// one coefficient fewer again): PV's change driven by x's changes, not its level. That is the
// form of a process that settles under a load that drifts (a random walk: the unit root is the
// noise's, so A and B share it); a process that integrates refutes it.
PredictionError arx_prediction_error(const std::vector<double>& y, const std::vector<double>& x,
                                     std::size_t nk, std::size_t order, std::size_t from,
                                     std::size_t estimation_end, bool integrating = false,
                                     bool differenced_input = false);

// The same with the dead time profiled out: the nk in [0, nk_max] whose prediction error on
// the estimation part is least (a model's own dead time, fitted to simulated output, need not
// be the one that predicts best; comparing two models at their own dead times would compare
// dead times). Needs from >= nk_max + order.
PredictionError best_arx_prediction_error(const std::vector<double>& y,
                                          const std::vector<double>& x, std::size_t nk_max,
                                          std::size_t order, std::size_t from,
                                          std::size_t estimation_end, bool integrating = false,
                                          bool differenced_input = false);

// How much less one-step prediction error a model leaves than a reference: 100 (1 - rms/rms_ref)
// on the estimation and on the held-out part (NaN where either has none).
struct PredictionGain {
  double estimation = std::numeric_limits<double>::quiet_NaN();
  double validation = std::numeric_limits<double>::quiet_NaN();
};
PredictionGain prediction_gain(const PredictionError& model, const PredictionError& reference);

// The change of BIC from `reference` to `model` on the estimation part, n ln(variance ratio) +
// (k - k_ref + extra_parameters) ln n: the predictors' own coefficients counted (an integrating
// one has fewer) and `extra_parameters` besides (an effect's own). NaN unless both are ok on the
// same samples.
double prediction_bic_change(const PredictionError& model, const PredictionError& reference,
                             double extra_parameters = 0.0);
// The likelihood-ratio statistic on the held-out part, n ln(variance ratio); NaN unless both
// have the same held-out samples.
double prediction_validation_deviance(const PredictionError& model,
                                      const PredictionError& reference);

// The estimation part's mean squared one-step prediction error (arx_prediction_error's, not
// differenced_input) for many valve positions x on the same PV: PV's own columns are summed
// once, and the sums with x's columns, shifts of one series, by sliding lagged sums - O(N order)
// per x instead of O(N order^2), for the searches that score thousands of valve positions. Equal
// to arx_prediction_error's estimation_variance up to rounding (the sums run in another order).
class PredictionErrorSearch {
 public:
  PredictionErrorSearch(const std::vector<double>& y, std::size_t order, std::size_t from,
                        std::size_t estimation_end, bool integrating = false);
  // NaN where arx_prediction_error would not be ok (x's length, from < nk + order, too few
  // samples, a singular or non-finite system).
  double estimation_variance(const std::vector<double>& x, std::size_t nk) const;

 private:
  std::vector<double> a_;  // the target: PV, or its change when integrating (a_[0] unused then)
  std::size_t order_ = 0, ny_ = 0, from_ = 0, end_ = 0;
  bool integrating_ = false;
  bool ok_ = false;
  std::vector<double> yy_;  // PV's columns and the constant: their Gram (ny + 1)^2, row-major
  std::vector<double> hy_;  // and their sums with the target (ny + 1)
  double aa_ = 0.0;         // the target's sum of squares
};

}  // namespace valvediag
