#include "valvediag/diagnose/prediction_error.hpp"

#include <Eigen/Dense>
#include <cmath>

#include "valvediag/core/simd.hpp"

namespace valvediag {

namespace {

// arx_prediction_error's work, compiled twice (simd.hpp): its sums of products are each summed
// in sample order, so the vectorised loops over a row's entries give the same bits with AVX.
[[gnu::always_inline]] inline PredictionError prediction_error_body(
    const std::vector<double>& y, const std::vector<double>& x, std::size_t nk, std::size_t order,
    std::size_t from, std::size_t estimation_end, bool integrating, bool differenced_input) {
  PredictionError out;
  differenced_input = differenced_input && integrating;
  const std::size_t N = y.size();
  if (x.size() != N || estimation_end > N || order == 0) return out;
  if (from < nk + order) return out;
  // Integrating: the target is PV's change, its own past changes the first order - 1 columns.
  const std::size_t ny = integrating ? order - 1 : order;
  const std::size_t nx = differenced_input ? order - 1 : order;
  const std::size_t cols = ny + nx + 1;
  if (estimation_end <= from + 4 * cols) return out;
  auto target = [&](std::size_t t) { return integrating ? y[t] - y[t - 1] : y[t]; };
  auto row = [&](std::size_t t, double* r) {
    for (std::size_t i = 0; i < ny; ++i) r[i] = target(t - 1 - i);
    for (std::size_t i = 0; i < nx; ++i)
      r[ny + i] = differenced_input ? x[t - nk - 1 - i] - x[t - nk - 2 - i] : x[t - nk - 1 - i];
    r[ny + nx] = 1.0;
  };
  // The normal equations, accumulated row by row: memory stays that of the coefficients
  // however long the record.
  const auto P = static_cast<Eigen::Index>(cols);
  Eigen::MatrixXd G = Eigen::MatrixXd::Zero(P, P);
  Eigen::VectorXd h = Eigen::VectorXd::Zero(P);
  std::vector<double> r(cols);
  // Plain loops on the lower triangle: for a row of 25, Eigen's dynamic-size rankUpdate spent
  // more in its call than in the sums.
  double* g = G.data();
  double* hv = h.data();
  for (std::size_t t = from; t < estimation_end; ++t) {
    row(t, r.data());
    for (std::size_t j = 0; j < cols; ++j) {
      const double rj = r[j];
      double* gj = g + j * cols;
      for (std::size_t i = j; i < cols; ++i) gj[i] += rj * r[i];
      hv[j] += target(t) * rj;
    }
  }
  G = G.selfadjointView<Eigen::Lower>();
  if (!G.allFinite() || !h.allFinite()) return out;
  const Eigen::VectorXd theta = G.colPivHouseholderQr().solve(h);
  if (!theta.allFinite()) return out;
  auto mse = [&](std::size_t a, std::size_t e, std::size_t& count) {
    double s = 0.0;
    count = 0;
    for (std::size_t t = a; t < e; ++t) {
      row(t, r.data());
      double p = 0.0;
      for (std::size_t i = 0; i < cols; ++i) p += theta(static_cast<Eigen::Index>(i)) * r[i];
      s += (target(t) - p) * (target(t) - p);
      ++count;
    }
    return count > 0 ? s / static_cast<double>(count) : std::numeric_limits<double>::quiet_NaN();
  };
  out.order = order;
  out.nk = nk;
  out.integrating = integrating;
  out.differenced_input = differenced_input;
  out.parameters = cols;
  out.estimation_variance = mse(from, estimation_end, out.estimation_samples);
  if (estimation_end + 1 < N)
    out.validation_variance = mse(estimation_end, N, out.validation_samples);
  out.ok = std::isfinite(out.estimation_variance) && out.estimation_variance > 0;
  return out;
}

VALVEDIAG_AVX PredictionError prediction_error_avx(const std::vector<double>& y,
                                                   const std::vector<double>& x, std::size_t nk,
                                                   std::size_t order, std::size_t from,
                                                   std::size_t estimation_end, bool integrating,
                                                   bool differenced_input) {
  return prediction_error_body(y, x, nk, order, from, estimation_end, integrating,
                               differenced_input);
}

}  // namespace

PredictionError arx_prediction_error(const std::vector<double>& y, const std::vector<double>& x,
                                     std::size_t nk, std::size_t order, std::size_t from,
                                     std::size_t estimation_end, bool integrating,
                                     bool differenced_input) {
  if (kHaveAvx)
    return prediction_error_avx(y, x, nk, order, from, estimation_end, integrating,
                                differenced_input);
  return prediction_error_body(y, x, nk, order, from, estimation_end, integrating,
                               differenced_input);
}

PredictionError best_arx_prediction_error(const std::vector<double>& y,
                                          const std::vector<double>& x, std::size_t nk_max,
                                          std::size_t order, std::size_t from,
                                          std::size_t estimation_end, bool integrating,
                                          bool differenced_input) {
  PredictionError best;
  if (from < nk_max + order) return best;  // every dead time on the same samples
  for (std::size_t nk = 0; nk <= nk_max; ++nk) {
    PredictionError p =
        arx_prediction_error(y, x, nk, order, from, estimation_end, integrating, differenced_input);
    if (p.ok && (!best.ok || p.estimation_variance < best.estimation_variance)) best = p;
  }
  return best;
}

PredictionGain prediction_gain(const PredictionError& model, const PredictionError& reference) {
  PredictionGain g;
  if (!model.ok || !reference.ok) return g;
  auto gain = [](double v, double ref) {
    return v >= 0 && ref > 0 ? 100.0 * (1.0 - std::sqrt(v / ref))
                             : std::numeric_limits<double>::quiet_NaN();
  };
  g.estimation = gain(model.estimation_variance, reference.estimation_variance);
  g.validation = gain(model.validation_variance, reference.validation_variance);
  return g;
}

double prediction_bic_change(const PredictionError& model, const PredictionError& reference,
                             double extra_parameters) {
  if (!model.ok || !reference.ok || model.estimation_samples != reference.estimation_samples)
    return std::numeric_limits<double>::quiet_NaN();
  const double n = static_cast<double>(model.estimation_samples);
  const double k = static_cast<double>(model.parameters) -
                   static_cast<double>(reference.parameters) + extra_parameters;
  return n * std::log(model.estimation_variance / reference.estimation_variance) + k * std::log(n);
}

double prediction_validation_deviance(const PredictionError& model,
                                      const PredictionError& reference) {
  if (model.validation_samples == 0 || model.validation_samples != reference.validation_samples ||
      !(model.validation_variance > 0) || !(reference.validation_variance > 0))
    return std::numeric_limits<double>::quiet_NaN();
  return static_cast<double>(model.validation_samples) *
         std::log(model.validation_variance / reference.validation_variance);
}

}  // namespace valvediag
