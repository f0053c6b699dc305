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

}  // namespace valvediag
