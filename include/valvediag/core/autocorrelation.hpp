// Autocorrelation of a record and what it implies for tests on it. Standard library and Eigen.
#pragma once

#include <cstddef>
#include <vector>

namespace valvediag {

// Normalised autocorrelation of x about its mean for lags 0..N-1, through one FFT (zero-padded:
// no wrap-around). Empty for a constant signal.
std::vector<double> autocorrelation(const std::vector<double>& x);

// How many independent samples a record of correlated residuals is worth: N / tau with tau =
// 1 + 2 * sum of the autocorrelation over the initial positive sequence (Geyer 1992), at least
// 1. A likelihood-ratio test on N correlated samples counts each one as new evidence; on N / tau
// it does not take a slow load's wander, seen hundreds of times over, for hundreds of proofs.
double effective_sample_size(const std::vector<double>& residual);
// The same for the residual y - y_sim over samples [t0, t1) (both the same length, t1 <= size).
double effective_sample_size(const std::vector<double>& y, const std::vector<double>& y_sim,
                             std::size_t t0, std::size_t t1);

// MATLAB's `resid`: a residual's autocorrelation and its cross-correlation with the input, each
// with the 99 % band of the hypothesis "the residual is white and independent of the input"
// (Ljung, System Identification, 2nd ed., 16.6). A model that leaves nothing to explain keeps both
// inside their bands; a lag outside says what is left: slow error (autocorrelation), or input
// the model does not carry through (cross-correlation at positive lags).
struct ResidualCorrelation {
  std::size_t samples = 0;
  std::size_t max_lag = 0;
  std::vector<double> autocorrelation;  // lags 0..max_lag (1 at lag 0)
  double autocorrelation_band = 0.0;    // 2.576 / sqrt(N)
  // r(k) for k = -max_lag..max_lag (index k + max_lag): e(t) against u(t - k). Positive lags: the
  // input before the residual; in closed loop the negative ones carry the controller's answer.
  std::vector<double> cross_correlation;
  // 2.576 sqrt(sum over |k| <= max_lag of r_e(k) r_u(k) / N): wider when both are coloured.
  double cross_correlation_band = 0.0;
};
// e and u of one length, at least 2 max_lag + 2 samples (else empty results).
ResidualCorrelation residual_correlation(const std::vector<double>& e, const std::vector<double>& u,
                                         std::size_t max_lag);

}  // namespace valvediag
