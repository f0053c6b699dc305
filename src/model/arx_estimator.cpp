#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <cmath>
#include <complex>
#include <cstring>
#include <limits>
#include <optional>
#include <stdexcept>
#include <tuple>

#include "valvediag/core/hammerstein.hpp"
#include "valvediag/core/simd.hpp"
#include "valvediag/model/effect_estimators.hpp"

namespace valvediag {

// One simulation of A v = B x + load over the estimation window, with its squared output error
// (v integrated back to the output when the process integrates). NA, NB > 0 fix the orders at
// compile time so the sums unroll; 0 takes them from the window. The operations and their order
// are the same either way, so the sums are too. Each sample adds B's terms first and subtracts
// A's from the oldest output to the latest: the dependent chain from one output to the next is
// then one multiply and one subtract (measured: `diagnose --auto` at 4,000 samples 4.05 -> 3.41 s).
struct SseWindow {
  const double* a;
  std::size_t na;
  const double* b;
  std::size_t nb, nk;
  const double *x, *y;
  double* v;  // holds the outputs before t0; filled from t0 on
  std::size_t t0, end;
  double c;
  const double* load;  // nullptr: the constant c (or, with knots, not filled: see below)
  double ylev;         // integrating: the output before t0
  // Integrating: the simulated level restarts from the measured output every `anchor` samples
  // (0: only at t0). Multiple shooting: a random-walk load drifts an integrated simulation
  // without bound, and over a long record that drift, not the valve, would decide the fit.
  std::size_t anchor = 0;
  // The load as its knots: load[t0 + k] = knots[j] (1 - frac[k]) + knots[j + 1] frac[k] with
  // j = k / h (the hat functions). knots == nullptr: no load.
  const double* knots = nullptr;
  std::size_t knot_count = 0, h = 0;
  const double* frac = nullptr;
};

namespace {

// A load at a sample a fraction frac past knot `left` towards knot `right` (the hat functions).
// One expression for every place that makes it: their sums agree to the bit.
inline double hat_load(double left, double right, double frac) {
  return left * (1.0 - frac) + (frac > 0 ? right * frac : 0.0);
}

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

bool stable(const std::vector<double>& a) {
  // Closed forms for the usual small orders (the companion eigen-solve costs more than the fit).
  if (a.empty()) return true;
  for (double v : a)
    if (!std::isfinite(v)) return false;
  if (a.size() == 1) return std::abs(a[0]) < 1.0 - 1e-9;
  if (a.size() == 2) return std::abs(a[1]) < 1.0 - 1e-9 && std::abs(a[0]) < 1.0 + a[1] - 1e-9;
  return is_stable(a);
}

// A's roots outside the unit circle reflected inside (z -> 1 / conj(z)), roots on it pulled to
// radius 0.999: the stable A with the same spectrum magnitude, the usual start for an output-error
// fit when least squares gives an unstable A. False when A has non-finite coefficients.
bool reflect_unstable_poles(std::vector<double>& a) {
  for (double v : a)
    if (!std::isfinite(v)) return false;
  const auto poles = poles_of(a);
  if (!poles) return false;
  const auto na = static_cast<Eigen::Index>(a.size());
  Eigen::VectorXcd poly = Eigen::VectorXcd::Zero(na + 1);
  poly[0] = 1.0;
  for (Eigen::Index k = 0; k < na; ++k) {
    std::complex<double> z = (*poles)[static_cast<std::size_t>(k)];
    const double m = std::abs(z);
    if (m >= 1.0 - 1e-6) z = (m > 1.0 + 1e-6 ? 1.0 / std::conj(z) : z / m * 0.999);
    for (Eigen::Index i = k + 1; i >= 1; --i) poly[i] -= z * poly[i - 1];
  }
  for (Eigen::Index i = 0; i < na; ++i) a[static_cast<std::size_t>(i)] = poly[i + 1].real();
  return stable(a);
}

template <std::size_t NA, std::size_t NB, bool Integrating>
double simulated_sse(const SseWindow& w) {
  const std::size_t na = NA > 0 ? NA : w.na, nb = NB > 0 ? NB : w.nb;
  double ylev = w.ylev, sse = 0.0;
  std::size_t next = w.anchor > 0 ? w.t0 + w.anchor : w.end;
  for (std::size_t t = w.t0; t < w.end; ++t) {
    if constexpr (Integrating)
      if (t == next) {
        ylev = w.y[t - 1];
        next += w.anchor;
      }
    double s = w.load ? w.load[t] : w.c;
    for (std::size_t k = 1; k <= nb; ++k) s += w.b[k - 1] * w.x[t - w.nk - k];
    for (std::size_t i = na; i >= 1; --i) s -= w.a[i - 1] * w.v[t - i];
    w.v[t] = s;
    double ys = s;
    if constexpr (Integrating) ys = ylev += s;
    sse += (ys - w.y[t]) * (ys - w.y[t]);
  }
  return sse;
}

// Four windows of the same orders (na, nb) at once, each lane exactly as simulated_sse computes
// it. Stops, returning sums above bound, once every lane's sum exceeds it (a sum of squares only
// grows). The general orders' loop; simulated_sse4 below is the unrolled one.
template <bool Integrating>
void simulated_sse4_loop(const std::array<SseWindow, 4>& w, double bound, double* out) {
  const std::size_t na = w[0].na, nb = w[0].nb;
  const double* y = w[0].y;
  const double* x = w[0].x;
  std::array<double, 4> ylev{}, sse{};
  ylev.fill(w[0].ylev);
  std::size_t next = w[0].anchor > 0 ? w[0].t0 + w[0].anchor : w[0].end;
  for (std::size_t t = w[0].t0; t < w[0].end; ++t) {
    if constexpr (Integrating)
      if (t == next) {
        ylev.fill(y[t - 1]);
        next += w[0].anchor;
      }
    for (std::size_t l = 0; l < 4; ++l) {
      const SseWindow& q = w[l];
      double s = q.load ? q.load[t] : q.c;
      for (std::size_t k = 1; k <= nb; ++k) s += q.b[k - 1] * x[t - q.nk - k];
      for (std::size_t i = na; i >= 1; --i) s -= q.a[i - 1] * q.v[t - i];
      q.v[t] = s;
      double ys = s;
      if constexpr (Integrating) ys = ylev[l] += s;
      sse[l] += (ys - y[t]) * (ys - y[t]);
    }
    if ((t & 63) == 0 && sse[0] > bound && sse[1] > bound && sse[2] > bound && sse[3] > bound)
      break;
  }
  for (std::size_t l = 0; l < 4; ++l) out[l] = sse[l];
}

// The same for orders NA, NB known at compile time (the loop above serves the others), with
// each lane's load made from its knots as window() fills it, expression for expression, instead
// of read from a buffer filled per lane. The four lanes are one vector V (simd.hpp: Quad with
// AVX, Pairs without): coefficients and past outputs stay in registers (storing each output and
// loading it back on the next sample put a store-to-load forwarding delay on the recursion's
// dependent chain, and testing each lane for a load cost a branch per sample). Same operations in
// the same order: the sums are the loop's, to the bit. Every lane has knots or none (one
// estimator's fits do).
template <class V, std::size_t NA, std::size_t NB, bool Integrating>
[[gnu::always_inline]] inline void simulated_sse4_body(const std::array<SseWindow, 4>& w,
                                                       double bound, double* out) {
  static_assert(NA > 0 && NB > 0);
  const double* y = w[0].y;
  const double* x = w[0].x;
  const std::size_t t0 = w[0].t0, end = w[0].end;
  V a[NA], b[NB], past[NA], c, ylev, sse{};
  std::size_t nk[4];
  for (std::size_t l = 0; l < 4; ++l) {
    const SseWindow& q = w[l];
    for (std::size_t i = 0; i < NA; ++i) {
      set_lane(a[i], static_cast<int>(l), q.a[i]);
      set_lane(past[i], static_cast<int>(l), q.v[t0 - 1 - i]);
    }
    for (std::size_t k = 0; k < NB; ++k) set_lane(b[k], static_cast<int>(l), q.b[k]);
    set_lane(c, static_cast<int>(l), q.c);
    nk[l] = q.nk;
    set_lane(ylev, static_cast<int>(l), q.ylev);
  }
  const auto run = [&]<bool Load>() {
    // Load: the interval j between knots j and j + 1 and those knots, changed every h samples.
    V left{}, right{};
    std::size_t j = 0, next = t0;
    std::size_t next_anchor = w[0].anchor > 0 ? t0 + w[0].anchor : end;
    for (std::size_t t = t0; t < end; ++t) {
      if constexpr (Integrating)
        if (t == next_anchor) {
          set4(ylev, y[t - 1], y[t - 1], y[t - 1], y[t - 1]);
          next_anchor += w[0].anchor;
        }
      V s;
      if constexpr (Load) {
        if (t == next) {
          j = (t - t0) / w[0].h;
          next = t + w[0].h;
          for (std::size_t l = 0; l < 4; ++l) {
            set_lane(left, static_cast<int>(l), w[l].knots[j]);
            set_lane(right, static_cast<int>(l), j + 1 < w[l].knot_count ? w[l].knots[j + 1] : 0.0);
          }
        }
        const double fk = w[0].frac[t - t0];
        // hat_load, lane by lane.
        s = left * (1.0 - fk) + (fk > 0 ? right * fk : V{});
      } else {
        s = c;
      }
      for (std::size_t k = 0; k < NB; ++k) {
        V xk;
        set4(xk, x[t - nk[0] - 1 - k], x[t - nk[1] - 1 - k], x[t - nk[2] - 1 - k],
             x[t - nk[3] - 1 - k]);
        s += b[k] * xk;
      }
      for (std::size_t i = NA; i-- > 0;) s -= a[i] * past[i];
      for (std::size_t i = NA - 1; i > 0; --i) past[i] = past[i - 1];
      past[0] = s;
      V ys = s;
      if constexpr (Integrating) ys = ylev += s;
      const V e = ys - y[t];
      sse += e * e;
      if ((t & 63) == 0 && sse[0] > bound && sse[1] > bound && sse[2] > bound && sse[3] > bound)
        break;
    }
  };
  if (w[0].knots)
    run.template operator()<true>();
  else
    run.template operator()<false>();
  for (std::size_t l = 0; l < 4; ++l) out[l] = sse[l];
}

template <std::size_t NA, std::size_t NB, bool Integrating>
VALVEDIAG_AVX void simulated_sse4_avx(const std::array<SseWindow, 4>& w, double bound,
                                      double* out) {
  simulated_sse4_body<Quad, NA, NB, Integrating>(w, bound, out);
}

template <std::size_t NA, std::size_t NB, bool Integrating>
void simulated_sse4(const std::array<SseWindow, 4>& w, double bound, double* out) {
  if (kHaveAvx) return simulated_sse4_avx<NA, NB, Integrating>(w, bound, out);
  simulated_sse4_body<Pairs, NA, NB, Integrating>(w, bound, out);
}

// dot() of p with each of q in one pass: the same sums (a four-lane V holds each dot's four
// partial sums, the scalar operations lane by lane; simd.hpp), their chains of adds interleaved and
// p's loads shared.
template <class V, std::size_t K>
[[gnu::always_inline]] inline void dots_body(const double* p, const std::array<const double*, K>& q,
                                             std::size_t n, double* out) {
  std::array<V, K> s{};
  V a, b;
  std::size_t k = 0;
  for (; k + 4 <= n; k += 4) {
    load(a, p + k);
    for (std::size_t j = 0; j < K; ++j) {
      load(b, q[j] + k);
      s[j] += a * b;
    }
  }
  for (std::size_t j = 0; j < K; ++j) {
    double s0 = s[j][0];
    for (std::size_t i = k; i < n; ++i) s0 += p[i] * q[j][i];
    out[j] = (s0 + s[j][1]) + (s[j][2] + s[j][3]);
  }
}

template <std::size_t K>
VALVEDIAG_AVX void dots_avx(const double* p, const std::array<const double*, K>& q, std::size_t n,
                            double* out) {
  dots_body<Quad, K>(p, q, n, out);
}

template <std::size_t K>
void dots(const double* p, const std::array<const double*, K>& q, std::size_t n, double* out) {
  if (kHaveAvx) return dots_avx<K>(p, q, n, out);
  dots_body<Pairs, K>(p, q, n, out);
}

// Four partial sums (dots): the adds of one sum would wait on each other.
double dot(const double* p, const double* q, std::size_t n) {
  double out;
  dots<1>(p, {q}, n, &out);
  return out;
}

// f.template operator()<NA, NB>() with orders 1..kUnrolled unrolled, <0, 0> otherwise.
constexpr std::size_t kUnrolled = 4;
template <std::size_t NA, std::size_t NB = 1, class F>
auto with_orders_from(std::size_t na, std::size_t nb, F& f) {
  if constexpr (NA > kUnrolled) {
    return f.template operator()<0, 0>();
  } else if constexpr (NB > kUnrolled) {
    return with_orders_from<NA + 1, 1>(na, nb, f);
  } else {
    if (na == NA && nb == NB) return f.template operator()<NA, NB>();
    return with_orders_from<NA, NB + 1>(na, nb, f);
  }
}
template <class F>
auto with_orders(std::size_t na, std::size_t nb, F&& f) {
  return with_orders_from<1, 1>(na, nb, f);
}

// The normal equations M th = r (ridge included) by LDLT; nullopt when it fails or th is not
// finite.
std::optional<Eigen::VectorXd> solve_normal(const Eigen::MatrixXd& M, const Eigen::VectorXd& r) {
  const Eigen::LDLT<Eigen::MatrixXd> ldlt(M);
  if (ldlt.info() != Eigen::Success) return std::nullopt;
  Eigen::VectorXd th = ldlt.solve(r);
  if (!th.allFinite()) return std::nullopt;
  return th;
}

// a and b from the first na + nb entries of th (A's coefficients enter with their sign flipped).
void set_lags(LinearFit& f, const Eigen::VectorXd& th, int na, int nb) {
  f.a.resize(static_cast<std::size_t>(na));
  f.b.resize(static_cast<std::size_t>(nb));
  for (int i = 0; i < na; ++i) f.a[static_cast<std::size_t>(i)] = -th[i];
  for (int k = 0; k < nb; ++k) f.b[static_cast<std::size_t>(k)] = th[na + k];
}
}  // namespace

struct ArxEstimator::Gram {
  Eigen::MatrixXd XX, XF;
  Eigen::VectorXd Xw;
  // The tail (the constant or the load's hats) eliminated once for every structure (tail()):
  // C = the tail's cross products with every candidate regressor (w lags 1..na_max, then the x
  // lags), T = its own block plus the ridge, Z = T^-1 C, G = C' Z, z = T^-1 (tail' w), v = C' z.
  double rho = 0.0;
  Eigen::MatrixXd Z, G;
  Eigen::VectorXd z, v;
  bool tail_ok = false;
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
    hat_frac_.resize(n);
    for (std::size_t k = 0; k < n; ++k) {
      const std::size_t j = k / h_;
      const double frac = static_cast<double>(k - j * h_) / static_cast<double>(h_);
      hat_frac_[k] = frac;
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
  if (opt_.plain_scan) return dense_blocks(x);
  // Column i of X is x lagged by lag0_ + i over the window, X_i[k] = x[t0_ + k - lag0_ - i], and
  // column i + 1 is column i one sample later. So X'X is Toeplitz up to the window's two ends:
  // XX(i + 1, j + 1) = XX(i, j) + X_i[-1] X_j[-1] - X_i[n-1] X_j[n-1], and likewise X' against
  // the lagged outputs and the constant. One set of dot products, then O(1) per entry, and the hat
  // functions of a load touch two knots per sample: O(n lags) in all, where the dense products
  // cost O(n lags (lags + columns of F)). (X_i[-1] exists: t0_ >= nk_max + nb_max, the
  // largest lag.)
  const std::size_t n = end_ - t0_;
  const int L = lags_, na = opt_.range.na_max;
  const auto X = [&](int i) { return x.data() + t0_ - static_cast<std::size_t>(lag0_ + i); };
  const auto W = [&](int m) { return w_.data() + t0_ - static_cast<std::size_t>(m); };
  const auto ends = [n](const double* p, const double* q) {
    return p[-1] * q[-1] - p[n - 1] * q[n - 1];
  };
  Gram g;
  g.XX.resize(L, L);
  g.XF.resize(L, nfixed_);
  g.Xw.resize(L);
  for (int i = 0; i < L; ++i) {
    std::array<double, 3> d;
    dots<3>(X(i), {X(0), W(1), w_.data() + t0_}, n, d.data());
    g.XX(i, 0) = d[0];
    g.XF(i, 0) = d[1];
    g.Xw[i] = d[2];
  }
  for (int j = 0; j + 1 < L; ++j)
    for (int i = j; i + 1 < L; ++i) g.XX(i + 1, j + 1) = g.XX(i, j) + ends(X(i), X(j));
  g.XX.triangularView<Eigen::StrictlyUpper>() = g.XX.transpose();
  for (int m = 2; m <= na; ++m) {
    g.XF(0, m - 1) = dot(X(0), W(m), n);
    for (int i = 0; i + 1 < L; ++i) g.XF(i + 1, m - 1) = g.XF(i, m - 2) + ends(X(i), W(m - 1));
  }
  if (!opt_.drift) {
    g.XF(0, na) = dot(X(0), F_.data() + static_cast<std::size_t>(na) * n, n);
    for (int i = 0; i + 1 < L; ++i) g.XF(i + 1, na) = g.XF(i, na) + X(i)[-1] - X(i)[n - 1];
    tail(g);
    return g;
  }
  // The hats: sample k weighs 1 - frac on its interval's left knot and frac on the right one, as
  // the constructor's columns of F.
  g.XF.rightCols(nfixed_ - na).setZero();
  for (int i = 0; i < L; ++i) {
    const double* xi = X(i);
    for (std::size_t k0 = 0, j = static_cast<std::size_t>(na); k0 < n; k0 += h_, ++j) {
      double left = 0.0, right = 0.0;
      for (std::size_t k = k0; k < std::min(k0 + h_, n); ++k) {
        const double frac = hat_frac_[k];
        left += xi[k] * (1.0 - frac);
        if (frac > 0) right += xi[k] * frac;
      }
      g.XF(i, static_cast<Eigen::Index>(j)) += left;
      if (j + 1 < static_cast<std::size_t>(nfixed_))
        g.XF(i, static_cast<Eigen::Index>(j + 1)) += right;
    }
  }
  tail(g);
  return g;
}

// A valve that never moves makes its lags collinear with c: a tiny ridge keeps the normal
// equations definite. 1e-10 of the largest diagonal entry over every candidate column (not only
// the structure's), so that all structures of one valve position are regularised alike and the
// tail can be eliminated once for all of them.
double ArxEstimator::ridge(const Gram& g) const {
  double big = 0.0;
  for (int i = 0; i < nfixed_; ++i)
    big = std::max(big, std::abs(FF_[static_cast<std::size_t>(i * nfixed_ + i)]));
  for (int i = 0; i < lags_; ++i) big = std::max(big, std::abs(g.XX(i, i)));
  return 1e-10 * big + 1e-300;
}

// Block elimination of the tail columns, shared by every structure of one valve position: a
// structure then solves only for its na + nb lag coefficients (the Schur complement, looked up
// from G), where one LDLT of all its columns cost O((na + nb + knots)^3) per structure.
void ArxEstimator::tail(Gram& g) const {
  const int na = opt_.range.na_max, K = nfixed_ - na, L = lags_;
  Eigen::MatrixXd T(K, K);
  Eigen::MatrixXd C(K, na + L);
  Eigen::VectorXd tw(K);
  g.rho = ridge(g);
  for (int a = 0; a < K; ++a) {
    for (int b = 0; b < K; ++b)
      T(a, b) = FF_[static_cast<std::size_t>((na + a) * nfixed_ + na + b)];
    T(a, a) += g.rho;
    for (int i = 0; i < na; ++i) C(a, i) = FF_[static_cast<std::size_t>(i * nfixed_ + na + a)];
    for (int i = 0; i < L; ++i) C(a, na + i) = g.XF(i, na + a);
    tw[a] = Fw_[static_cast<std::size_t>(na + a)];
  }
  const Eigen::LDLT<Eigen::MatrixXd> ldlt(T);
  g.tail_ok = ldlt.info() == Eigen::Success;
  if (!g.tail_ok) return;
  g.Z = ldlt.solve(C);
  g.z = ldlt.solve(tw);
  g.G = C.transpose() * g.Z;
  g.v = C.transpose() * g.z;
}

ArxEstimator::Gram ArxEstimator::dense_blocks(const std::vector<double>& x) const {
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

bool ArxEstimator::coefficients(const Gram& g, const ArxStructure& s, LinearFit& f) const {
  if (!opt_.plain_scan) return reduced_coefficients(g, s, f);
  f = LinearFit{};
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
  M.diagonal().array() += ridge(g);
  const auto sol = solve_normal(M, r);
  if (!sol) return false;
  const Eigen::VectorXd& th = *sol;
  set_lags(f, th, na, nb);
  if (opt_.drift) {
    f.drift_knots.assign(th.data() + na + nb, th.data() + p);
  } else {
    f.c = th[na + nb];
  }
  return stable(f.a);
}

bool ArxEstimator::reduced_coefficients(const Gram& g, const ArxStructure& s, LinearFit& f) const {
  f = LinearFit{};
  f.structure = s;
  if (!g.tail_ok) return false;
  const int na = s.na, nb = s.nb, q = na + nb;
  const int na_max = opt_.range.na_max;
  // Candidate index of each lag column (into C, G and Z): w lag i, then x lag nk + 1 + k.
  std::vector<int> c(static_cast<std::size_t>(q));
  for (int i = 0; i < na; ++i) c[static_cast<std::size_t>(i)] = i;
  for (int k = 0; k < nb; ++k) c[static_cast<std::size_t>(na + k)] = na_max + s.nk + 1 + k - lag0_;
  // The lag block of the normal equations, its right-hand side, both less the tail's share.
  Eigen::MatrixXd S(q, q);
  Eigen::VectorXd r(q);
  for (int i = 0; i < q; ++i) {
    const int ci = c[static_cast<std::size_t>(i)];
    const bool wi = i < na;
    r[i] = (wi ? Fw_[static_cast<std::size_t>(ci)] : g.Xw[ci - na_max]) - g.v[ci];
    for (int j = 0; j <= i; ++j) {
      const int cj = c[static_cast<std::size_t>(j)];
      const bool wj = j < na;
      double m;
      if (wi && wj)
        m = FF_[static_cast<std::size_t>(ci * nfixed_ + cj)];
      else if (!wi && !wj)
        m = g.XX(ci - na_max, cj - na_max);
      else
        m = wi ? g.XF(cj - na_max, ci) : g.XF(ci - na_max, cj);
      S(i, j) = S(j, i) = m - g.G(ci, cj);
    }
    S(i, i) += g.rho;
  }
  const auto sol = solve_normal(S, r);
  if (!sol) return false;
  const Eigen::VectorXd& th = *sol;
  set_lags(f, th, na, nb);
  // The tail from the lags: z - Z th.
  Eigen::VectorXd t = g.z;
  for (int i = 0; i < q; ++i) t -= g.Z.col(c[static_cast<std::size_t>(i)]) * th[i];
  if (!t.allFinite()) return false;
  if (opt_.drift)
    f.drift_knots.assign(t.data(), t.data() + t.size());
  else
    f.c = t[0];
  return stable(f.a);
}

void ArxEstimator::score(LinearFit& f, double sse, double bound) const {
  if (!std::isfinite(sse) || sse > bound) return;
  f.sse = sse;
  f.fitness_percent = den_ > 0 ? (1.0 - std::sqrt(sse / den_)) * 100.0 : kNaN;
  f.ok = true;
}

LinearFit ArxEstimator::solve(const Gram& g, const ArxStructure& s,
                              const std::vector<double>& x) const {
  LinearFit f;
  if (coefficients(g, s, f)) score(f, window_sse(f, x), kInf);
  return f;
}

LinearFit ArxEstimator::fit(const std::vector<double>& x, const ArxStructure& s) const {
  const auto& r = opt_.range;
  if (s.na < 1 || s.na > r.na_max || s.nb < 1 || s.nk < r.nk_min ||
      s.nk + s.nb > r.nk_max + r.nb_max)
    throw std::invalid_argument("structure outside the estimator's range");
  return solve(x_blocks(x), s, x);
}

LinearFit ArxEstimator::plain_fit(const Gram& g, const std::vector<double>& x,
                                  bool parsimony) const {
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
  return !parsimony || !best.ok || opt_.parsimony_percent <= 0 ? best : pick(fits);
}

LinearFit ArxEstimator::fit(const std::vector<double>& x, bool parsimony) const {
  const Gram g = x_blocks(x);
  if (opt_.plain_scan) return plain_fit(g, x, parsimony);
  const auto& r = opt_.range;
  std::vector<LinearFit> fits;
  LinearFit best;
  // A structure that cannot be chosen need not be simulated to the end: without parsimony one
  // that cannot beat the best so far; with it, one that cannot come within parsimony_percent of
  // the best so far (the final best is no worse, so its window is no wider). Slack keeps the
  // bound on the safe side of rounding: pick() still applies the exact rule.
  const auto bound = [&](const LinearFit& b) {
    if (!b.ok) return kInf;
    if (!parsimony || opt_.parsimony_percent <= 0) return b.sse;
    const double e = 1.0 - (b.fitness_percent - opt_.parsimony_percent) / 100.0;
    return den_ > 0 && e > 0 ? den_ * e * e * (1.0 + 1e-6) + 1e-300 : kInf;
  };
  // Equal errors go to the first structure in scan order, as a plain scan keeps it.
  const auto order = [](const ArxStructure& s) { return std::make_tuple(s.nk, s.na, s.nb); };
  const auto better = [&](const LinearFit& f) {
    return !best.ok || f.sse < best.sse ||
           (f.sse == best.sse && order(f.structure) < order(best.structure));
  };
  // Without parsimony the structure that won this thread's last fit goes first: a search's
  // successive valve parameters are close, so it usually wins again, and its error bounds the
  // others from the start. The answer does not depend on the hint, only the time.
  thread_local ArxStructure hint{0, 0, -1};
  const bool hinted = !parsimony && hint.na >= r.na_min && hint.na <= r.na_max &&
                      hint.nb >= r.nb_min && hint.nb <= r.nb_max && hint.nk >= r.nk_min &&
                      hint.nk <= r.nk_max;
  if (hinted) best = solve(g, hint, x);
  // Structures that differ only in nk are simulated four at a time: the recursion is a chain of
  // dependent multiply-adds, and four independent chains keep the core busy while one waits.
  std::array<LinearFit, 4> batch;
  std::size_t n = 0;
  const auto flush = [&] {
    std::array<double, 4> sse{};
    window_sse4(batch.data(), n, x, bound(best), sse.data());
    for (std::size_t i = 0; i < n; ++i) {
      LinearFit& f = batch[i];
      score(f, sse[i], bound(best));
      if (!f.ok) continue;
      if (better(f)) best = f;
      if (parsimony) fits.push_back(std::move(f));
    }
    n = 0;
  };
  for (int na = r.na_min; na <= r.na_max; ++na)
    for (int nb = r.nb_min; nb <= r.nb_max; ++nb) {
      for (int nk = r.nk_min; nk <= r.nk_max; ++nk) {
        const ArxStructure s{na, nb, nk};
        if (hinted && s == hint) continue;
        if (!coefficients(g, s, batch[n])) continue;
        if (++n == batch.size()) flush();
      }
      if (n > 0) flush();
    }
  if (!parsimony && best.ok) hint = best.structure;
  if (!parsimony || !best.ok || opt_.parsimony_percent <= 0) return best;
  // pick() breaks equal errors by position: give it the scan order.
  std::sort(fits.begin(), fits.end(), [&](const LinearFit& a, const LinearFit& b) {
    return order(a.structure) < order(b.structure);
  });
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

namespace {

// refine()'s normal equations: rows [w(t-1) .. w(t-na), x(t-nk-1) .. x(t-nk-nb), 1] of the
// filtered series for t in [t0, t0 + n), their sums of products into m's lower triangle (column
// major, p = na + nb + 1 rows) and against w(t) into h. P > 0: p known at compile time, the sums
// in registers rather than read and written back in memory on every row; each sum is added in
// the same order either way, so it is the same to the bit.
template <int P>
[[gnu::always_inline]] inline void normal_sums_body(const double* wf, const double* xf,
                                                    std::size_t t0, std::size_t n, int na, int nb,
                                                    int nk, double* m, double* h) {
  const int p = P > 0 ? P : na + nb + 1;
  constexpr int kMax = P > 0 ? P : 1;
  double M[kMax][kMax] = {}, H[kMax] = {}, row[kMax];
  std::vector<double> dyn_row(P > 0 ? 0 : static_cast<std::size_t>(p));
  double* rw = P > 0 ? row : dyn_row.data();
  for (std::size_t r = 0; r < n; ++r) {
    const std::size_t t = t0 + r;
    for (int i = 1; i <= na; ++i) rw[i - 1] = wf[t - static_cast<std::size_t>(i)];
    for (int k = 1; k <= nb; ++k) rw[na + k - 1] = xf[t - static_cast<std::size_t>(nk + k)];
    rw[p - 1] = 1.0;
    if constexpr (P > 0) {
      for (int j = 0; j < P; ++j)
        for (int i = j; i < P; ++i) M[i][j] += rw[j] * rw[i];
      for (int i = 0; i < P; ++i) H[i] += wf[t] * rw[i];
    } else {
      for (int j = 0; j < p; ++j)
        for (int i = j; i < p; ++i) m[i + j * p] += rw[j] * rw[i];
      for (int i = 0; i < p; ++i) h[i] += wf[t] * rw[i];
    }
  }
  if constexpr (P > 0) {
    for (int j = 0; j < P; ++j) {
      for (int i = j; i < P; ++i) m[i + j * P] = M[i][j];
      h[j] = H[j];
    }
  }
}

template <int P>
VALVEDIAG_AVX void normal_sums_avx(const double* wf, const double* xf, std::size_t t0,
                                   std::size_t n, int na, int nb, int nk, double* m, double* h) {
  normal_sums_body<P>(wf, xf, t0, n, na, nb, nk, m, h);
}

template <int P>
void normal_sums_p(const double* wf, const double* xf, std::size_t t0, std::size_t n, int na,
                   int nb, int nk, double* m, double* h) {
  if (kHaveAvx) return normal_sums_avx<P>(wf, xf, t0, n, na, nb, nk, m, h);
  normal_sums_body<P>(wf, xf, t0, n, na, nb, nk, m, h);
}

// m and h zero on entry.
void normal_sums(const double* wf, const double* xf, std::size_t t0, std::size_t n, int na, int nb,
                 int nk, double* m, double* h) {
  switch (na + nb + 1) {
    case 3:
      return normal_sums_p<3>(wf, xf, t0, n, na, nb, nk, m, h);
    case 4:
      return normal_sums_p<4>(wf, xf, t0, n, na, nb, nk, m, h);
    case 5:
      return normal_sums_p<5>(wf, xf, t0, n, na, nb, nk, m, h);
    default:
      return normal_sums_p<0>(wf, xf, t0, n, na, nb, nk, m, h);
  }
}

}  // namespace

LinearFit ArxEstimator::refine(const LinearFit& ls, const std::vector<double>& x,
                               int iterations) const {
  LinearFit best = ls;
  if (!ls.ok) return best;
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
    // Normal equations accumulated row by row (no n x p matrix), lower triangle. Plain loops:
    // for p of a few, Eigen's dynamic-size rankUpdate spent more in its call than in the sums
    // (half of a sanitized diagnosis's time; Release about even). Same products, same order.
    Eigen::MatrixXd M = Eigen::MatrixXd::Zero(p, p);
    Eigen::VectorXd rhs = Eigen::VectorXd::Zero(p);
    normal_sums(wf.data(), xf.data(), t0_, static_cast<std::size_t>(n), na, nb, nk, M.data(),
                rhs.data());
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
    // The constant of the filtered equation is c / A_prev(1); the model's is c (with drift: a
    // flat load, its knots all equal, as fit_from starts).
    f.c = th[p - 1] * a1;
    if (opt_.drift) {
      f.drift_knots.assign(knots_, f.c);
      f.c = 0.0;
    }
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
        LinearFit f;
        const bool solved = coefficients(g, ArxStructure{na, nb, nk}, f);
        // Solved but with A unstable (a failed solve leaves a and b empty): reflect its poles.
        const bool reflected = !solved && static_cast<int>(f.a.size()) == na &&
                               static_cast<int>(f.b.size()) == nb && !stable(f.a) &&
                               reflect_unstable_poles(f.a);
        if (solved || reflected) score(f, window_sse(f, x), kInf);
        if (!f.ok) continue;
        f = refine(f, x, iterations);
        f.forced_stable = reflected;
        // Forced stable, a model that does worse than the record's mean is no model (an
        // integrating process): the caller's "no stable linear part" path stays open for it.
        if (reflected && !(f.fitness_percent > 0)) continue;
        fits.push_back(std::move(f));
      }
  return pick(fits);
}

LinearFit ArxEstimator::fit_from(const LinearFit& start, const std::vector<double>& x,
                                 int iterations) const {
  const auto& r = opt_.range;
  const ArxStructure& st = start.structure;
  if (x.size() != y_.size() || !start.drift_knots.empty() ||
      static_cast<int>(start.a.size()) != st.na || static_cast<int>(start.b.size()) != st.nb ||
      st.na > r.na_max || st.nb < 1 || st.nk < r.nk_min || st.nk + st.nb > r.nk_max + r.nb_max)
    return {};
  LinearFit f;
  f.structure = st;
  f.a = start.a;
  f.b = start.b;
  if (opt_.drift)
    f.drift_knots.assign(knots_, start.c);
  else
    f.c = start.c;
  if (!stable(f.a)) return {};
  score(f, window_sse(f, x), kInf);
  if (!f.ok || iterations <= 0) return f;
  return refine(f, x, iterations);
}

std::vector<double> ArxEstimator::drift_series(const LinearFit& f) const {
  if (!opt_.drift || f.drift_knots.empty()) return {};
  std::vector<double> d(y_.size(), 0.0);
  for (std::size_t t = t0_; t < y_.size(); ++t) {
    const std::size_t k = std::min(t, end_ - 1) - t0_;
    const std::size_t j = k / h_;
    const double frac = static_cast<double>(k - j * h_) / static_cast<double>(h_);
    d[t] = hat_load(f.drift_knots[j], frac > 0 ? f.drift_knots[j + 1] : 0.0, frac);
  }
  return d;
}

// The buffers of one simulation lane: v seeded with the outputs before t0, and the load over the
// window when the fit has one (else nullptr).
SseWindow ArxEstimator::window(const LinearFit& f, const std::vector<double>& x,
                               std::vector<double>& v, std::vector<double>* load) const {
  const std::size_t na = f.a.size();
  v.resize(end_);
  const std::size_t seed = std::min(t0_, na);  // outputs before t0 the recursion reads
  std::copy(w_.begin() + static_cast<std::ptrdiff_t>(t0_ - seed),
            w_.begin() + static_cast<std::ptrdiff_t>(t0_),
            v.begin() + static_cast<std::ptrdiff_t>(t0_ - seed));
  const double* d = nullptr;
  if (!f.drift_knots.empty() && load) {
    // Interval by interval, with the hat functions' fractions from the constructor (no division
    // per sample: this runs for every structure the search tries).
    std::vector<double>& buf = *load;
    buf.resize(end_);
    const std::size_t n = end_ - t0_, knots = f.drift_knots.size();
    for (std::size_t j = 0, k0 = 0; k0 < n; ++j, k0 += h_) {
      const double left = f.drift_knots[j], right = j + 1 < knots ? f.drift_knots[j + 1] : 0.0;
      for (std::size_t k = k0; k < std::min(k0 + h_, n); ++k)
        buf[t0_ + k] = hat_load(left, right, hat_frac_[k]);
    }
    d = buf.data();
  }
  return SseWindow{.a = f.a.data(),
                   .na = na,
                   .b = f.b.data(),
                   .nb = f.b.size(),
                   .nk = static_cast<std::size_t>(f.structure.nk),
                   .x = x.data(),
                   .y = y_.data(),
                   .v = v.data(),
                   .t0 = t0_,
                   .end = end_,
                   .c = f.c,
                   .load = d,
                   .ylev = opt_.integrating ? y_[t0_ - 1] : 0.0,
                   .anchor = opt_.integrating ? opt_.level_anchor : 0,
                   .knots = f.drift_knots.empty() ? nullptr : f.drift_knots.data(),
                   .knot_count = f.drift_knots.size(),
                   .h = h_,
                   .frac = hat_frac_.data()};
}

double ArxEstimator::window_sse(const LinearFit& f, const std::vector<double>& x) const {
  thread_local std::vector<double> v, load;
  const SseWindow w = window(f, x, v, &load);
  const auto run = [&]<std::size_t NA, std::size_t NB>() {
    return opt_.integrating ? simulated_sse<NA, NB, true>(w) : simulated_sse<NA, NB, false>(w);
  };
  // The reference search keeps the loop of general orders (the benchmark's baseline).
  return opt_.plain_scan ? run.template operator()<0, 0>() : with_orders(w.na, w.nb, run);
}

void ArxEstimator::window_sse4(const LinearFit* fs, std::size_t n, const std::vector<double>& x,
                               double bound, double* sse) const {
  if (n == 0) return;
  // Fewer than four: the spare lanes repeat the first (their sums are dropped).
  thread_local std::array<std::vector<double>, 4> v, load;
  // The unrolled kernels make each lane's load from its knots; the general loop reads it filled.
  const bool unrolled = fs[0].a.size() <= kUnrolled && fs[0].b.size() <= kUnrolled;
  std::array<SseWindow, 4> w;
  for (std::size_t l = 0; l < 4; ++l)
    w[l] = window(fs[l < n ? l : 0], x, v[l], unrolled ? nullptr : &load[l]);
  std::array<double, 4> out{};
  with_orders(w[0].na, w[0].nb, [&]<std::size_t NA, std::size_t NB>() {
    if constexpr (NA == 0) {
      if (opt_.integrating)
        simulated_sse4_loop<true>(w, bound, out.data());
      else
        simulated_sse4_loop<false>(w, bound, out.data());
    } else {
      if (opt_.integrating)
        simulated_sse4<NA, NB, true>(w, bound, out.data());
      else
        simulated_sse4<NA, NB, false>(w, bound, out.data());
    }
  });
  for (std::size_t l = 0; l < n; ++l) sse[l] = out[l];
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
    for (std::size_t k = 1; k <= nb; ++k) s += f.b[k - 1] * x[t - nk - k];
    for (std::size_t i = na; i >= 1; --i) s -= f.a[i - 1] * v[t - i];
    v[t] = s;
    if (opt_.integrating) ys[t] = ys[t - 1] + s;
  }
  return ys;
}

}  // namespace valvediag
