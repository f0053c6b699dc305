#include "valvediag/diagnose/prediction_error.hpp"

#include <Eigen/Dense>
#include <cmath>
#include <limits>

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
  if (!differenced_input) {
    // The dead time by the search's estimation variances (PV's sums formed once), the full
    // figures, held-out part included, formed again only at the best one.
    const PredictionErrorSearch search(y, order, from, estimation_end, integrating);
    std::size_t best_nk = nk_max + 1;
    double least = std::numeric_limits<double>::infinity();
    for (std::size_t nk = 0; nk <= nk_max; ++nk)
      if (const double v = search.estimation_variance(x, nk); v < least) {
        least = v;
        best_nk = nk;
      }
    if (best_nk <= nk_max)
      return arx_prediction_error(y, x, best_nk, order, from, estimation_end, integrating);
  }
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

namespace valvediag {

PredictionErrorSearch::PredictionErrorSearch(const std::vector<double>& y, std::size_t order,
                                             std::size_t from, std::size_t estimation_end,
                                             bool integrating)
    : order_(order),
      ny_(integrating ? order - 1 : order),
      from_(from),
      end_(estimation_end),
      integrating_(integrating) {
  const std::size_t N = y.size();
  if (order == 0 || estimation_end > N || from < order + 1 || estimation_end <= from) return;
  a_.assign(N, 0.0);
  for (std::size_t t = integrating ? 1 : 0; t < N; ++t)
    a_[t] = integrating ? y[t] - y[t - 1] : y[t];
  // Columns j < ny: a(t - 1 - j); column ny: the constant.
  const std::size_t m = ny_ + 1;
  yy_.assign(m * m, 0.0);
  hy_.assign(m, 0.0);
  for (std::size_t t = from; t < estimation_end; ++t) {
    for (std::size_t j = 0; j < m; ++j) {
      const double cj = j < ny_ ? a_[t - 1 - j] : 1.0;
      for (std::size_t k = j; k < m; ++k) yy_[j * m + k] += cj * (k < ny_ ? a_[t - 1 - k] : 1.0);
      hy_[j] += cj * a_[t];
    }
    aa_ += a_[t] * a_[t];
  }
  for (std::size_t j = 0; j < m; ++j)
    for (std::size_t k = 0; k < j; ++k) yy_[j * m + k] = yy_[k * m + j];
  ok_ = std::isfinite(aa_);
}

double PredictionErrorSearch::estimation_variance(const std::vector<double>& x,
                                                  std::size_t nk) const {
  constexpr double nan = std::numeric_limits<double>::quiet_NaN();
  const std::size_t cols = ny_ + order_ + 1;
  if (!ok_ || x.size() != a_.size() || from_ < nk + order_ || end_ <= from_ + 4 * cols) return nan;
  // Rows t in [from, end): x's column i is x(t - nk - 1 - i), i.e. x(s) for s in the window
  // [lo - i, hi - i) with lo = from - nk - 1. Each sum over a shifted window is the previous
  // one with one product dropped at the top and one added at the bottom.
  const std::ptrdiff_t lo =
      static_cast<std::ptrdiff_t>(from_) - static_cast<std::ptrdiff_t>(nk) - 1;
  const std::ptrdiff_t hi = lo + static_cast<std::ptrdiff_t>(end_ - from_);
  const auto X = [&x](std::ptrdiff_t s) { return x[static_cast<std::size_t>(s)]; };
  const auto A = [this](std::ptrdiff_t s) { return a_[static_cast<std::size_t>(s)]; };
  const auto P = static_cast<Eigen::Index>(cols);
  Eigen::MatrixXd G(P, P);
  Eigen::VectorXd h(P);
  // PV's block: column order y-lags 0..ny-1, x-lags ny..ny+order-1, constant last.
  const std::size_t m = ny_ + 1;
  const auto yi = [this](std::size_t j) {
    return static_cast<Eigen::Index>(j < ny_ ? j : ny_ + order_);
  };
  for (std::size_t j = 0; j < m; ++j) {
    h(yi(j)) = hy_[j];
    for (std::size_t k = 0; k < m; ++k) G(yi(j), yi(k)) = yy_[j * m + k];
  }
  const auto xi = [this](std::size_t i) { return static_cast<Eigen::Index>(ny_ + i); };
  const std::ptrdiff_t R = static_cast<std::ptrdiff_t>(order_);
  // x with x at lag d (sum over s of x(s) x(s - d)), windows shifted by i.
  for (std::ptrdiff_t d = 0; d < R; ++d) {
    double sum = 0.0;
    for (std::ptrdiff_t s = lo; s < hi; ++s) sum += X(s) * X(s - d);
    for (std::ptrdiff_t i = 0; i + d < R; ++i) {
      if (i > 0) sum += X(lo - i) * X(lo - i - d) - X(hi - i) * X(hi - i - d);
      G(xi(static_cast<std::size_t>(i)), xi(static_cast<std::size_t>(i + d))) = sum;
      G(xi(static_cast<std::size_t>(i + d)), xi(static_cast<std::size_t>(i))) = sum;
    }
  }
  // x's column i with the constant: the window's sum.
  {
    double sum = 0.0;
    for (std::ptrdiff_t s = lo; s < hi; ++s) sum += X(s);
    for (std::ptrdiff_t i = 0; i < R; ++i) {
      if (i > 0) sum += X(lo - i) - X(hi - i);
      G(xi(static_cast<std::size_t>(i)), yi(ny_)) = G(yi(ny_), xi(static_cast<std::size_t>(i))) =
          sum;
    }
  }
  // x's column i with PV's column j (j = -1: the target): sum over the row t of
  // x(t - nk - 1 - i) a(t - 1 - j) = sum over s in [lo - i, hi - i) of x(s) a(s + e),
  // e = nk + i - j; (i, j) slides from (i - 1, j - 1), the same e.
  const std::ptrdiff_t ny = static_cast<std::ptrdiff_t>(ny_);
  const std::ptrdiff_t k0 = static_cast<std::ptrdiff_t>(nk);
  const auto put = [&](std::ptrdiff_t i, std::ptrdiff_t j, double v) {
    if (j < 0)
      h(xi(static_cast<std::size_t>(i))) = v;
    else
      G(xi(static_cast<std::size_t>(i)), yi(static_cast<std::size_t>(j))) =
          G(yi(static_cast<std::size_t>(j)), xi(static_cast<std::size_t>(i))) = v;
  };
  // Diagonals start at i = 0 (j from -1 to ny - 1) or at j = -1 (i from 1 on).
  const auto diagonal = [&](std::ptrdiff_t i, std::ptrdiff_t j) {
    const std::ptrdiff_t e = k0 + i - j;
    double sum = 0.0;
    for (std::ptrdiff_t s = lo - i; s < hi - i; ++s) sum += X(s) * A(s + e);
    put(i, j, sum);
    for (++i, ++j; i < R && j < ny; ++i, ++j) {
      sum += X(lo - i) * A(lo - i + e) - X(hi - i) * A(hi - i + e);
      put(i, j, sum);
    }
  };
  for (std::ptrdiff_t j = -1; j < ny; ++j) diagonal(0, j);
  for (std::ptrdiff_t i = 1; i < R; ++i) diagonal(i, -1);
  if (!G.allFinite() || !h.allFinite()) return nan;
  const Eigen::VectorXd theta = G.colPivHouseholderQr().solve(h);
  if (!theta.allFinite()) return nan;
  // The least-squares residual: a'a - theta'h.
  const double sse = std::max(aa_ - theta.dot(h), 0.0);
  const double v = sse / static_cast<double>(end_ - from_);
  return std::isfinite(v) && v > 0 ? v : nan;
}

}  // namespace valvediag
