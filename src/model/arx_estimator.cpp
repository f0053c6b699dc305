#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "valvediag/effect_estimators.hpp"
#include "valvediag/hammerstein.hpp"

namespace valvediag {

namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

bool stable(const std::vector<double>& a) {
  // Closed forms for the usual small orders (the companion eigen-solve costs more than the fit).
  if (a.empty()) return true;
  for (double v : a)
    if (!std::isfinite(v)) return false;
  if (a.size() == 1) return std::abs(a[0]) < 1.0 - 1e-9;
  if (a.size() == 2) return std::abs(a[1]) < 1.0 - 1e-9 && std::abs(a[0]) < 1.0 + a[1] - 1e-9;
  return is_stable(a);
}

}  // namespace

struct ArxEstimator::Gram {
  Eigen::MatrixXd XX, XF;
  Eigen::VectorXd Xw;
};

ArxEstimator::ArxEstimator(std::vector<double> y, const LinearOptions& opt)
    : y_(std::move(y)), opt_(opt) {
  const auto& r = opt_.range;
  if (r.na_min < 1 || r.na_max < r.na_min || r.nb_min < 1 || r.nb_max < r.nb_min || r.nk_min < 0 ||
      r.nk_max < r.nk_min)
    throw std::invalid_argument(
        "structure range must satisfy 1 <= na, 1 <= nb, 0 <= nk, min <= max");
  const std::size_t N = y_.size();
  const std::size_t need = static_cast<std::size_t>(
      std::max({r.na_max + (opt_.integrating ? 1 : 0), r.nk_max + r.nb_max, 1}));
  t0_ = std::max(opt_.start, need);
  end_ = opt_.end > 0 ? std::min(opt_.end, N) : N;
  const std::size_t params = static_cast<std::size_t>(r.na_max + r.nb_max) + 2;
  if (end_ <= t0_ + 4 * params + 20)
    throw std::invalid_argument("too few estimation samples for the structure range");
  w_ = y_;
  if (opt_.integrating) {
    w_[0] = 0.0;
    for (std::size_t t = 1; t < N; ++t) w_[t] = y_[t] - y_[t - 1];
  }
  lag0_ = r.nk_min + 1;
  lags_ = r.nk_max + r.nb_max - r.nk_min;
  const std::size_t n = end_ - t0_;
  if (opt_.drift) {
    h_ = opt_.drift_knot_spacing > 0 ? opt_.drift_knot_spacing : std::max<std::size_t>(30, n / 16);
    h_ = std::min(h_, n - 1);
    knots_ = (n - 1 + h_ - 1) / h_ + 1;
  }
  nfixed_ = r.na_max + (opt_.drift ? static_cast<int>(knots_) : 1);
  F_.assign(n * static_cast<std::size_t>(nfixed_), 0.0);
  auto col = [&](int j) { return F_.data() + static_cast<std::size_t>(j) * n; };
  for (int i = 1; i <= r.na_max; ++i)
    for (std::size_t k = 0; k < n; ++k) col(i - 1)[k] = w_[t0_ + k - static_cast<std::size_t>(i)];
  if (opt_.drift) {
    for (std::size_t k = 0; k < n; ++k) {
      const std::size_t j = k / h_;
      const double frac = static_cast<double>(k - j * h_) / static_cast<double>(h_);
      col(r.na_max + static_cast<int>(j))[k] = 1.0 - frac;
      if (frac > 0) col(r.na_max + static_cast<int>(j) + 1)[k] = frac;
    }
  } else {
    std::fill(col(r.na_max), col(r.na_max) + n, 1.0);
  }
  const Eigen::Map<const Eigen::MatrixXd> F(F_.data(), static_cast<Eigen::Index>(n), nfixed_);
  const Eigen::Map<const Eigen::VectorXd> w(w_.data() + t0_, static_cast<Eigen::Index>(n));
  const Eigen::MatrixXd FF = F.transpose() * F;
  const Eigen::VectorXd Fw = F.transpose() * w;
  FF_.assign(FF.data(), FF.data() + FF.size());
  Fw_.assign(Fw.data(), Fw.data() + Fw.size());
  ww_ = w.squaredNorm();
  double mean = 0.0;
  for (std::size_t t = t0_; t < end_; ++t) mean += y_[t];
  mean /= static_cast<double>(n);
  for (std::size_t t = t0_; t < end_; ++t) den_ += (y_[t] - mean) * (y_[t] - mean);
}

ArxEstimator::Gram ArxEstimator::x_blocks(const std::vector<double>& x) const {
  if (x.size() != y_.size())
    throw std::invalid_argument("valve position and output differ in length");
  const auto n = static_cast<Eigen::Index>(end_ - t0_);
  Eigen::MatrixXd X(n, lags_);
  for (int j = 0; j < lags_; ++j) {
    const std::size_t d = static_cast<std::size_t>(lag0_ + j);
    X.col(j) = Eigen::Map<const Eigen::VectorXd>(x.data() + t0_ - d, n);
  }
  const Eigen::Map<const Eigen::MatrixXd> F(F_.data(), n, nfixed_);
  const Eigen::Map<const Eigen::VectorXd> w(w_.data() + t0_, n);
  Gram g;
  g.XX = Eigen::MatrixXd::Zero(lags_, lags_);
  g.XX.selfadjointView<Eigen::Lower>().rankUpdate(X.transpose());
  g.XX = g.XX.selfadjointView<Eigen::Lower>();
  g.XF = X.transpose() * F;
  g.Xw = X.transpose() * w;
  return g;
}

LinearFit ArxEstimator::solve(const Gram& g, const ArxStructure& s,
                              const std::vector<double>& x) const {
  LinearFit f;
  f.structure = s;
  const int na = s.na, nb = s.nb;
  const int na_max = opt_.range.na_max;
  const int tail = nfixed_ - na_max;
  const int p = na + nb + tail;
  // Column map: kind 0 = fixed column index, kind 1 = x lag index.
  std::vector<std::pair<int, int>> cols;
  cols.reserve(static_cast<std::size_t>(p));
  for (int i = 0; i < na; ++i) cols.emplace_back(0, i);
  for (int k = 0; k < nb; ++k) cols.emplace_back(1, s.nk + 1 + k - lag0_);
  for (int j = 0; j < tail; ++j) cols.emplace_back(0, na_max + j);
  Eigen::MatrixXd M(p, p);
  Eigen::VectorXd r(p);
  for (int i = 0; i < p; ++i) {
    const auto [ki, ii] = cols[static_cast<std::size_t>(i)];
    r[i] = ki == 0 ? Fw_[static_cast<std::size_t>(ii)] : g.Xw[ii];
    for (int j = 0; j <= i; ++j) {
      const auto [kj, jj] = cols[static_cast<std::size_t>(j)];
      double v;
      if (ki == 0 && kj == 0) {
        v = FF_[static_cast<std::size_t>(ii * nfixed_ + jj)];
      } else if (ki == 1 && kj == 1) {
        v = g.XX(ii, jj);
      } else {
        v = ki == 1 ? g.XF(ii, jj) : g.XF(jj, ii);
      }
      M(i, j) = M(j, i) = v;
    }
  }
  // A valve that never moves makes its lags collinear with c: a tiny ridge keeps LDLT defined.
  M.diagonal().array() += 1e-10 * M.diagonal().cwiseAbs().maxCoeff() + 1e-300;
  Eigen::LDLT<Eigen::MatrixXd> ldlt(M);
  if (ldlt.info() != Eigen::Success) return f;
  const Eigen::VectorXd th = ldlt.solve(r);
  if (!th.allFinite()) return f;
  f.a.resize(static_cast<std::size_t>(na));
  f.b.resize(static_cast<std::size_t>(nb));
  for (int i = 0; i < na; ++i) f.a[static_cast<std::size_t>(i)] = -th[i];
  for (int k = 0; k < nb; ++k) f.b[static_cast<std::size_t>(k)] = th[na + k];
  if (opt_.drift) {
    f.drift_knots.assign(th.data() + na + nb, th.data() + p);
  } else {
    f.c = th[na + nb];
  }
  if (!stable(f.a)) return f;
  const double sse = window_sse(f, x);
  if (!std::isfinite(sse)) return f;
  f.sse = sse;
  f.fitness_percent = den_ > 0 ? (1.0 - std::sqrt(sse / den_)) * 100.0 : kNaN;
  f.ok = true;
  return f;
}

LinearFit ArxEstimator::fit(const std::vector<double>& x, const ArxStructure& s) const {
  const auto& r = opt_.range;
  if (s.na < 1 || s.na > r.na_max || s.nb < 1 || s.nk < r.nk_min ||
      s.nk + s.nb > r.nk_max + r.nb_max)
    throw std::invalid_argument("structure outside the estimator's range");
  return solve(x_blocks(x), s, x);
}

LinearFit ArxEstimator::fit(const std::vector<double>& x, bool parsimony) const {
  const Gram g = x_blocks(x);
  const auto& r = opt_.range;
  std::vector<LinearFit> fits;
  LinearFit best;
  for (int nk = r.nk_min; nk <= r.nk_max; ++nk)
    for (int na = r.na_min; na <= r.na_max; ++na)
      for (int nb = r.nb_min; nb <= r.nb_max; ++nb) {
        LinearFit f = solve(g, ArxStructure{na, nb, nk}, x);
        if (!f.ok) continue;
        if (!best.ok || f.sse < best.sse) best = f;
        if (parsimony) fits.push_back(std::move(f));
      }
  if (!parsimony || !best.ok || opt_.parsimony_percent <= 0) return best;
  return pick(fits);
}

LinearFit ArxEstimator::pick(const std::vector<LinearFit>& fits) const {
  const LinearFit* best = nullptr;
  for (const auto& f : fits)
    if (f.ok && (!best || f.sse < best->sse)) best = &f;
  if (!best) return {};
  if (opt_.parsimony_percent <= 0) return *best;
  auto key = [](const LinearFit& f) {
    return std::make_tuple(f.structure.na + f.structure.nb, f.structure.nk, f.structure.na);
  };
  const LinearFit* p = best;
  for (const auto& f : fits)
    if (f.ok && f.fitness_percent >= best->fitness_percent - opt_.parsimony_percent &&
        key(f) < key(*p))
      p = &f;
  return *p;
}

LinearFit ArxEstimator::refine(const LinearFit& ls, const std::vector<double>& x,
                               int iterations) const {
  LinearFit best = ls;
  if (!ls.ok || opt_.drift) return best;
  const std::size_t N = end_;
  const int na = ls.structure.na, nb = ls.structure.nb, nk = ls.structure.nk;
  const int p = na + nb + 1;
  const auto n = static_cast<Eigen::Index>(end_ - t0_);
  std::vector<double> a = ls.a;
  std::vector<double> wf(N), xf(N);
  for (int it = 0; it < iterations; ++it) {
    // 1/A filter from the steady state of the first samples.
    double a1 = 1.0;
    for (double v : a) a1 += v;
    if (!(std::abs(a1) > 1e-9)) break;
    const std::size_t na_s = a.size();
    for (std::size_t t = 0; t < N; ++t) {
      if (t < na_s) {
        wf[t] = w_[0] / a1;
        xf[t] = x[0] / a1;
        continue;
      }
      double sw = w_[t], sx = x[t];
      for (std::size_t i = 1; i <= na_s; ++i) {
        sw -= a[i - 1] * wf[t - i];
        sx -= a[i - 1] * xf[t - i];
      }
      wf[t] = sw;
      xf[t] = sx;
    }
    // Normal equations accumulated row by row (no n x p matrix).
    Eigen::MatrixXd M = Eigen::MatrixXd::Zero(p, p);
    Eigen::VectorXd rhs = Eigen::VectorXd::Zero(p);
    Eigen::VectorXd row(p);
    for (Eigen::Index r = 0; r < n; ++r) {
      const std::size_t t = t0_ + static_cast<std::size_t>(r);
      for (int i = 1; i <= na; ++i) row[i - 1] = wf[t - static_cast<std::size_t>(i)];
      for (int k = 1; k <= nb; ++k) row[na + k - 1] = xf[t - static_cast<std::size_t>(nk + k)];
      row[p - 1] = 1.0;
      M.selfadjointView<Eigen::Lower>().rankUpdate(row);
      rhs += wf[t] * row;
    }
    M = M.selfadjointView<Eigen::Lower>();
    M.diagonal().array() += 1e-10 * M.diagonal().cwiseAbs().maxCoeff() + 1e-300;
    const Eigen::VectorXd th = M.ldlt().solve(rhs);
    if (!th.allFinite()) break;
    LinearFit f;
    f.structure = ls.structure;
    f.a.resize(static_cast<std::size_t>(na));
    f.b.resize(static_cast<std::size_t>(nb));
    for (int i = 0; i < na; ++i) f.a[static_cast<std::size_t>(i)] = -th[i];
    for (int k = 0; k < nb; ++k) f.b[static_cast<std::size_t>(k)] = th[na + k];
    // The constant of the filtered equation is c / A_prev(1); the model's is c.
    f.c = th[p - 1] * a1;
    if (!stable(f.a)) break;
    const double sse = window_sse(f, x);
    if (!std::isfinite(sse)) break;
    f.sse = sse;
    f.fitness_percent = den_ > 0 ? (1.0 - std::sqrt(sse / den_)) * 100.0 : kNaN;
    f.ok = true;
    const bool converged = f.sse > best.sse * (1.0 - 1e-3);
    if (f.sse < best.sse) best = f;
    if (converged) break;  // no longer improving by 0.1 %
    a = f.a;
  }
  return best;
}

LinearFit ArxEstimator::fit_output_error(const std::vector<double>& x, int iterations) const {
  if (opt_.drift || iterations <= 0) return fit(x, true);
  const Gram g = x_blocks(x);
  const auto& r = opt_.range;
  std::vector<LinearFit> fits;
  for (int nk = r.nk_min; nk <= r.nk_max; ++nk)
    for (int na = r.na_min; na <= r.na_max; ++na)
      for (int nb = r.nb_min; nb <= r.nb_max; ++nb) {
        const LinearFit f = solve(g, ArxStructure{na, nb, nk}, x);
        if (f.ok) fits.push_back(refine(f, x, iterations));
      }
  return pick(fits);
}

std::vector<double> ArxEstimator::drift_series(const LinearFit& f) const {
  if (!opt_.drift || f.drift_knots.empty()) return {};
  std::vector<double> d(y_.size(), 0.0);
  for (std::size_t t = t0_; t < y_.size(); ++t) {
    const std::size_t k = std::min(t, end_ - 1) - t0_;
    const std::size_t j = k / h_;
    const double frac = static_cast<double>(k - j * h_) / static_cast<double>(h_);
    d[t] = f.drift_knots[j] * (1.0 - frac) + (frac > 0 ? f.drift_knots[j + 1] * frac : 0.0);
  }
  return d;
}

double ArxEstimator::window_sse(const LinearFit& f, const std::vector<double>& x) const {
  // The search's inner loop: only the estimation window, no allocation beyond one buffer.
  thread_local std::vector<double> v;
  v.assign(w_.begin(), w_.begin() + static_cast<std::ptrdiff_t>(end_));
  const std::size_t na = f.a.size(), nb = f.b.size();
  const std::size_t nk = static_cast<std::size_t>(f.structure.nk);
  const double* a = f.a.data();
  const double* b = f.b.data();
  const std::size_t nh = f.drift_knots.size();
  double ylev = opt_.integrating ? y_[t0_ - 1] : 0.0;
  double sse = 0.0;
  for (std::size_t t = t0_; t < end_; ++t) {
    double s;
    if (nh > 0) {
      const std::size_t k = t - t0_, j = k / h_;
      const double frac = static_cast<double>(k - j * h_) / static_cast<double>(h_);
      s = f.drift_knots[j] * (1.0 - frac) + (frac > 0 ? f.drift_knots[j + 1] * frac : 0.0);
    } else {
      s = f.c;
    }
    for (std::size_t i = 1; i <= na; ++i) s -= a[i - 1] * v[t - i];
    for (std::size_t k = 1; k <= nb; ++k) s += b[k - 1] * x[t - nk - k];
    v[t] = s;
    double ys = s;
    if (opt_.integrating) ys = ylev += s;
    sse += (ys - y_[t]) * (ys - y_[t]);
  }
  return sse;
}

std::vector<double> ArxEstimator::simulate(const LinearFit& f, const std::vector<double>& x) const {
  const std::size_t N = y_.size();
  std::vector<double> ys(y_.begin(), y_.end());
  std::vector<double> ws(w_.begin(), w_.end());
  const std::vector<double> d = drift_series(f);
  const std::size_t na = f.a.size(), nb = f.b.size();
  const std::size_t nk = static_cast<std::size_t>(f.structure.nk);
  std::vector<double>& v = opt_.integrating ? ws : ys;
  for (std::size_t t = t0_; t < N; ++t) {
    double s = d.empty() ? f.c : d[t];
    for (std::size_t i = 1; i <= na; ++i) s -= f.a[i - 1] * v[t - i];
    for (std::size_t k = 1; k <= nb; ++k) s += f.b[k - 1] * x[t - nk - k];
    v[t] = s;
    if (opt_.integrating) ys[t] = ys[t - 1] + s;
  }
  return ys;
}

}  // namespace valvediag
