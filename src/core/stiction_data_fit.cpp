#include "stiction_data_fit.hpp"

#include <nlopt.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>

#include "valvediag/core/simd.hpp"

namespace valvediag::detail {

namespace {

Pair load_pair(const double* p) {
  Pair v;
  load(v, p);
  return v;
}

// The dot products of l with r[0 .. K) over n samples, each summed as Eigen 3.4's VectorXd::dot
// sums it with SSE2 (Redux.h, the linear vectorised traversal: two sums of pairs over the
// quadruples, then the odd pair, the pair's halves and the odd sample), so that each is Eigen's
// to the bit; in one pass they share l's loads and their chains of adds interleave (one dot's
// chain left the core waiting). A four-lane V (simd.hpp) holds the two pair sums side by side
// (lanes 0-1 the pairs at i, 2-3 those at i + 2): with AVX one instruction per step, same bits.
template <class V, std::size_t K>
[[gnu::always_inline]] inline void dots_body(const double* l, const std::array<const double*, 4>& r,
                                             std::size_t n, double* out) {
  if (n < 2) {
    for (std::size_t k = 0; k < K; ++k) out[k] = n == 1 ? l[0] * r[k][0] : 0.0;
    return;
  }
  const std::size_t end2 = n / 4 * 4, end = n / 2 * 2;
  std::array<Pair, K> s0;
  if (end2 < 4) {  // two or three samples: one pair
    const Pair a0 = load_pair(l);
    for (std::size_t k = 0; k < K; ++k) s0[k] = a0 * load_pair(r[k]);
  } else {
    std::array<V, K> s;
    V a, b;
    load(a, l);
    for (std::size_t k = 0; k < K; ++k) {
      load(b, r[k]);
      s[k] = a * b;
    }
    for (std::size_t i = 4; i < end2; i += 4) {
      load(a, l + i);
      for (std::size_t k = 0; k < K; ++k) {
        load(b, r[k] + i);
        s[k] += a * b;
      }
    }
    for (std::size_t k = 0; k < K; ++k) {
      s0[k] = Pair{s[k][0], s[k][1]} + Pair{s[k][2], s[k][3]};
      if (end > end2) s0[k] += load_pair(l + end2) * load_pair(r[k] + end2);
    }
  }
  for (std::size_t k = 0; k < K; ++k) {
    double res = s0[k][0] + s0[k][1];
    for (std::size_t i = end; i < n; ++i) res += l[i] * r[k][i];
    out[k] = res;
  }
}

template <std::size_t K>
VALVEDIAG_AVX void dots_avx(const double* l, const std::array<const double*, 4>& r, std::size_t n,
                            double* out) {
  dots_body<Quad, K>(l, r, n, out);
}

template <std::size_t K>
void dots_best(const double* l, const std::array<const double*, 4>& r, std::size_t n, double* out) {
  if (kHaveAvx) return dots_avx<K>(l, r, n, out);
  dots_body<Pairs, K>(l, r, n, out);
}

// dots() for any count: four at a time.
void dots(const double* l, const double* const* r, std::size_t count, std::size_t n, double* out) {
  for (std::size_t k = 0; k < count; k += 4) {
    std::array<const double*, 4> q{};
    const std::size_t m = std::min<std::size_t>(4, count - k);
    for (std::size_t j = 0; j < m; ++j) q[j] = r[k + j];
    switch (m) {
      case 1:
        dots_best<1>(l, q, n, out + k);
        break;
      case 2:
        dots_best<2>(l, q, n, out + k);
        break;
      case 3:
        dots_best<3>(l, q, n, out + k);
        break;
      default:
        dots_best<4>(l, q, n, out + k);
    }
  }
}

}  // namespace

HeDataFit::HeDataFit(const HammersteinModel& m, const std::vector<double>& op,
                     const std::vector<double>& y, double width, int max_delay, bool remember,
                     bool plain_sums)
    : u_(op), y_(y), ones_(op.size(), 1.0), remember_(remember), plain_sums_(plain_sums) {
  identity_ = m.block == LinearBlock::Identity;
  if (!identity_) {
    nb_ = std::max<int>(1, static_cast<int>(m.b.size()));
    nk_ = m.structure.nk;
  }
  const std::size_t N = u_.size();
  double travel = 0.0;
  t0_ = N;
  for (std::size_t t = 1; t < N; ++t) {
    travel += std::abs(u_[t] - u_[t - 1]);
    if (travel >= width) {
      t0_ = t;
      break;
    }
  }
  t0_ = std::max(t0_, static_cast<std::size_t>(std::max(nk_, max_delay) + nb_ + 4));
  double sy = 0, syy = 0, n = 0;
  for (std::size_t t = t0_; t < N; ++t) {
    sy += y_[t];
    syy += y_[t] * y_[t];
    n += 1;
  }
  var_y_ = n > 0 ? syy - sy * sy / n : 0.0;
  set_poles(identity_ ? std::vector<double>{} : m.a);
  // For ls_poles: sums of products of [y(t), y(t-1) .. y(t-na), 1] over the scored rows; they
  // do not depend on the valve.
  const int na = static_cast<int>(a_.size());
  if (na > 0 && t0_ < N && static_cast<std::size_t>(na) <= t0_) {
    Columns c;
    for (int i = 0; i <= na; ++i) c.add(y_, static_cast<std::size_t>(i));
    c.add(ones_, 0);
    y_lags_.resize(c.n, c.n);
    scored_dots(c, c, y_lags_);
  }
}

std::vector<double> HeDataFit::ls_poles(const std::vector<double>& x) const {
  const int na = static_cast<int>(a_.size());
  if (na == 0 || identity_ || y_lags_.rows() != na + 2) return {};
  Columns taps, all;
  for (int i = 0; i <= na; ++i) all.add(y_, static_cast<std::size_t>(i));
  for (int j = 1; j <= nb_; ++j) {
    taps.add(x, static_cast<std::size_t>(nk_ + j));
    all.add(x, static_cast<std::size_t>(nk_ + j));
  }
  all.add(ones_, 0);
  products_.resize(taps.n, all.n);
  scored_dots(taps, all, products_);
  // The products of all columns: y's and the constant's from the constructor, the taps' here.
  const int n = all.n, one = n - 1;
  Eigen::MatrixXd P(n, n);
  for (int i = 0; i <= na; ++i) {
    for (int k = 0; k <= na; ++k) P(i, k) = y_lags_(i, k);
    P(i, one) = P(one, i) = y_lags_(i, na + 1);
  }
  P(one, one) = y_lags_(na + 1, na + 1);
  for (int j = 0; j < nb_; ++j)
    for (int k = 0; k < n; ++k) P(na + 1 + j, k) = P(k, na + 1 + j) = products_(j, k);
  return arx_poles(P, na);
}

std::vector<double> HeDataFit::sm_poles(const std::vector<double>& x, int passes) const {
  const int na = static_cast<int>(a_.size());
  if (na == 0 || identity_) return {};
  std::vector<double> a = a_;
  auto mean = [](const std::vector<double>& v) {
    return Eigen::Map<const Eigen::VectorXd>(v.data(), static_cast<Eigen::Index>(v.size())).mean();
  };
  const double my = mean(y_), mx = mean(x);
  for (int pass = 0; pass < passes; ++pass) {
    // The first pass starts from the same poles for every x (the Preisach valve's): y through
    // them is kept.
    const bool same_y = pass == 0 && sm_y0_valid_ && sm_y0_poles_ == a;
    if (!same_y) through(y_, my, a, sm_y_);
    if (pass == 0 && !same_y) {
      sm_y0_ = sm_y_;
      sm_y0_poles_ = a;
      sm_y0_valid_ = true;
    }
    const std::vector<double>& fy = pass == 0 ? sm_y0_ : sm_y_;
    through(x, mx, a, sm_x_);
    Columns c;  // as arx_poles takes them
    for (int i = 0; i <= na; ++i) c.add(fy, static_cast<std::size_t>(i));
    for (int j = 1; j <= nb_; ++j) c.add(sm_x_, static_cast<std::size_t>(nk_ + j));
    c.add(ones_, 0);
    scored_dots(c, c, products_);
    a = arx_poles(products_, na);
    if (a.empty()) return {};
  }
  return a;
}

double HeDataFit::cost(const std::vector<Band>& bands) const {
  const std::uint64_t key = valve_into(bands, x_);
  if (!remember_) return cost(x_);
  const auto hit = costs_.find(key);
  if (hit != costs_.end()) return hit->second;
  return costs_[key] = cost(x_);
}

double HeDataFit::cost(std::uint64_t key, const std::vector<double>& x) const {
  if (!remember_) return cost(x);
  const auto hit = costs_.find(key);
  if (hit != costs_.end()) return hit->second;
  return costs_[key] = cost(x);
}

void HeDataFit::costs(const Band* bands, std::size_t n, double* out) const {
  n = std::min(n, kLanes);
  // The positions, lane by lane as valve_into makes them (one band: no regions).
  std::array<std::uint64_t, kLanes> key{};
  std::array<double, kLanes> u_r{}, xv{}, fs{}, fd{};
  std::array<double*, kLanes> x{};
  for (std::size_t l = 0; l < n; ++l) {
    lane_x_[l].resize(u_.size());
    x[l] = lane_x_[l].data();
    xv[l] = u_.front();
    key[l] = mix(std::bit_cast<std::uint64_t>(xv[l]));
    fs[l] = bands[l].fs;
    fd[l] = bands[l].fd;
  }
  double u_prev = u_.front();
  for (std::size_t t = 0; t < u_.size(); ++t) {
    const double du = u_[t] - u_prev;
    u_prev = u_[t];
    for (std::size_t l = 0; l < n; ++l) {
      const double u_cum = u_r[l] + du;
      if (std::abs(u_cum) > fs[l]) {
        u_r[l] = u_cum > 0 ? fd[l] : -fd[l];
        xv[l] = u_[t] - u_r[l];
        key[l] = mix(mix(key[l] ^ t) ^ std::bit_cast<std::uint64_t>(xv[l]));
      } else {
        u_r[l] = u_cum;
      }
      x[l][t] = xv[l];
    }
  }
  // The lanes not remembered (nor repeated in an earlier lane) are solved; the first one alone
  // when the fixed regressors are to be made.
  std::array<std::size_t, kLanes> todo{};
  std::size_t m = 0;
  for (std::size_t l = 0; l < n; ++l) {
    out[l] = -1.0;
    if (remember_) {
      const auto hit = costs_.find(key[l]);
      if (hit != costs_.end()) {
        out[l] = hit->second;
        continue;
      }
      bool repeated = false;
      for (std::size_t k = 0; k < m && !repeated; ++k) repeated = key[todo[k]] == key[l];
      if (repeated) continue;
    }
    todo[m++] = l;
  }
  std::size_t first = 0;
  if (m > 0 && !fixed_ready_) out[todo[first++]] = solve(lane_x_[todo[0]], nullptr);
  if (first < m) {
    std::array<const double*, kLanes> in{};
    for (std::size_t k = first; k < m; ++k) in[k - first] = lane_x_[todo[k]].data();
    for (std::size_t k = m - first; k < kLanes; ++k) in[k] = in[0];  // spare lanes repeat
    switch (a_.size()) {
      case 0:
        filter_lanes<0>(in, m - first);
        break;
      case 1:
        filter_lanes<1>(in, m - first);
        break;
      case 2:
        filter_lanes<2>(in, m - first);
        break;
      case 3:
        filter_lanes<3>(in, m - first);
        break;
      default:
        filter_lanes<-1>(in, m - first);
    }
    for (std::size_t k = first; k < m; ++k)
      out[todo[k]] = solve_filtered(lane_f_[k - first], nullptr);
  }
  for (std::size_t l = 0; l < n; ++l) {
    if (out[l] >= 0) continue;
    for (std::size_t k = 0; k < l; ++k)  // a lane that repeats an earlier one
      if (key[k] == key[l]) out[l] = out[k];
  }
  if (remember_)
    for (std::size_t k = 0; k < m; ++k) costs_[key[todo[k]]] = out[todo[k]];
}

// filter_n's recursion of x (not of the fixed regressors) for n series into lane_f_, the lanes
// interleaved; each lane's operations are filter_n's, in its order.
template <int NA>
void HeDataFit::filter_lanes(const std::array<const double*, kLanes>& x, std::size_t n) const {
  const std::size_t N = u_.size();
  const std::size_t na = NA >= 0 ? static_cast<std::size_t>(NA) : a_.size();
  const double* a = a_.data();
  std::array<double*, kLanes> f{};
  for (std::size_t l = 0; l < n; ++l) {
    lane_f_[l].resize(N);
    f[l] = lane_f_[l].data();
  }
  const std::size_t head = NA >= 0 ? std::min(na, N) : N;
  for (std::size_t l = 0; l < n; ++l)
    for (std::size_t t = 0; t < head; ++t) {
      double v = x[l][t];
      const std::size_t k = t >= na ? na : t;
      for (std::size_t i = 1; i <= k; ++i) v -= a[i - 1] * f[l][t - i];
      f[l][t] = v;
    }
  if constexpr (NA >= 0) {
    // Two lanes to a vector register (GCC's vector extension: the same IEEE operations lane by
    // lane); as arrays of doubles the past outputs went through the stack, and loading two
    // stored halves as one vector stalled store forwarding on every sample.
    using Pair = double __attribute__((vector_size(16)));
    constexpr std::size_t kPairs = kLanes / 2;
    std::array<Pair, NA + 1> c{};
    std::array<std::array<Pair, NA + 1>, kPairs> fp{};
    for (std::size_t i = 0; i < na; ++i) c[i] = Pair{a[i], a[i]};
    for (std::size_t l = 0; l < n; ++l)
      for (std::size_t i = 0; i < na; ++i) fp[l / 2][i][l % 2] = f[l][head - 1 - i];
    for (std::size_t t = head; t < N; ++t) {
      std::array<Pair, kPairs> out;
      for (std::size_t p = 0; p < kPairs; ++p) {
        Pair v{x[2 * p][t], x[2 * p + 1][t]};
        for (std::size_t i = 0; i < na; ++i) v -= c[i] * fp[p][i];
        for (std::size_t i = na; i-- > 1;) fp[p][i] = fp[p][i - 1];
        if (na > 0) fp[p][0] = v;
        out[p] = v;
      }
      for (std::size_t l = 0; l < n; ++l) f[l][t] = out[l / 2][l % 2];
    }
  }
}

double HeDataFit::solve(const std::vector<double>& x, std::vector<double>* residual) const {
  filter(x);
  return solve_filtered(f_, residual);
}

double HeDataFit::solve_filtered(const std::vector<double>& f,
                                 std::vector<double>* residual) const {
  // Regressors: B's taps (x through 1/A, delayed), then the fixed ones, then y.
  Columns taps;
  for (int j = 0; j < nb_; ++j) taps.add(f, identity_ ? 0 : static_cast<std::size_t>(nk_ + j + 1));
  Columns all = taps;
  const Columns fixed = fixed_columns();
  for (int k = 0; k < fixed.n; ++k)
    all.c[static_cast<std::size_t>(all.n++)] = fixed.c[static_cast<std::size_t>(k)];
  products_.resize(taps.n, all.n);
  if (plain_sums_) {
    scored_dots(taps, all, products_);
  } else {
    tap_gram(taps, products_);
    scored_dots(taps, fixed, fixed_products_);
    products_.rightCols(fixed.n) = fixed_products_;
  }
  const Eigen::Index nf = fixed.n - 1;
  const int p = nb_ + static_cast<int>(nf);
  Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, kMaxColumns, kMaxColumns> G(p, p);
  Eigen::Matrix<double, Eigen::Dynamic, 1, 0, kMaxColumns, 1> r(p);
  G.topRows(nb_) = products_.leftCols(p);
  G.bottomLeftCorner(nf, nb_) = products_.middleCols(nb_, nf).transpose();
  G.bottomRightCorner(nf, nf) = fixed_gram_.topLeftCorner(nf, nf);
  r.head(nb_) = products_.col(p);
  r.tail(nf) = fixed_gram_.col(nf).head(nf);
  const double yy = fixed_gram_(nf, nf);
  // Scaled, with a tiny ridge: the constant and a slow free response are nearly collinear.
  const Eigen::Matrix<double, Eigen::Dynamic, 1, 0, kMaxColumns, 1> sc =
      G.diagonal().cwiseMax(1e-300).cwiseSqrt().cwiseInverse();
  Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, kMaxColumns, kMaxColumns> Gs =
      sc.asDiagonal() * G * sc.asDiagonal();
  Gs.diagonal().array() += 1e-10;
  const Eigen::Matrix<double, Eigen::Dynamic, 1, 0, kMaxColumns, 1> rs = sc.asDiagonal() * r;
  const Eigen::Matrix<double, Eigen::Dynamic, 1, 0, kMaxColumns, 1> th = Gs.ldlt().solve(rs);
  if (residual) {
    const Eigen::Matrix<double, Eigen::Dynamic, 1, 0, kMaxColumns, 1> theta = sc.cwiseProduct(th);
    residual->resize(u_.size() - t0_);
    for (std::size_t t = t0_; t < u_.size(); ++t) {
      double e = y_[t];
      for (int k = 0; k < p; ++k) {
        const Column& c = all.c[static_cast<std::size_t>(k)];
        e -= theta(k) * c.v[t - c.lag];
      }
      (*residual)[t - t0_] = e;
    }
  }
  return std::max(0.0, yy - th.dot(rs));
}

// `in` less m through 1/A (coefficients a) from rest into out. The common orders keep the past
// outputs in registers (see filter_n); the same operations in the same order as the plain loop.
void HeDataFit::through(const std::vector<double>& in, double m, const std::vector<double>& a,
                        std::vector<double>& out) {
  switch (a.size()) {
    case 1:
      return through_n<1>(in, m, a, out);
    case 2:
      return through_n<2>(in, m, a, out);
    case 3:
      return through_n<3>(in, m, a, out);
    default:
      return through_n<-1>(in, m, a, out);
  }
}

template <int NA>
void HeDataFit::through_n(const std::vector<double>& in, double m, const std::vector<double>& a,
                          std::vector<double>& out) {
  const std::size_t N = in.size();
  out.resize(N);
  if constexpr (NA < 0) {
    for (std::size_t t = 0; t < N; ++t) {
      double v = in[t] - m;
      for (std::size_t i = 1; i <= a.size() && i <= t; ++i) v -= a[i - 1] * out[t - i];
      out[t] = v;
    }
  } else {
    constexpr std::size_t na = NA;
    std::array<double, na> c{}, p{};  // p[i - 1] = out[t - i]
    for (std::size_t i = 0; i < na; ++i) c[i] = a[i];
    for (std::size_t t = 0; t < N; ++t) {
      double v = in[t] - m;
      const std::size_t k = t < na ? t : na;
      for (std::size_t i = 0; i < k; ++i) v -= c[i] * p[i];
      for (std::size_t i = na - 1; i > 0; --i) p[i] = p[i - 1];
      p[0] = v;
      out[t] = v;
    }
  }
}

// Equation-error least squares of y(t) on [-y(t-1) .. -y(t-na), x's taps, 1] from the products
// P of the columns [y(t), y(t-1) .. y(t-na), x's taps, 1]: A's coefficients, or empty when A
// comes out unstable.
std::vector<double> HeDataFit::arx_poles(const Eigen::MatrixXd& P, int na) {
  const Eigen::Index p = P.rows() - 1;
  auto sign = [na](Eigen::Index k) { return k >= 1 && k <= na ? -1.0 : 1.0; };
  Eigen::MatrixXd M(p, p);
  Eigen::VectorXd r(p);
  for (Eigen::Index i = 1; i <= p; ++i) {
    for (Eigen::Index k = 1; k <= p; ++k) M(i - 1, k - 1) = sign(i) * sign(k) * P(i, k);
    r(i - 1) = sign(i) * P(0, i);
  }
  M.diagonal().array() += 1e-10 * M.diagonal().cwiseAbs().maxCoeff() + 1e-300;
  const Eigen::VectorXd th = M.ldlt().solve(r);
  std::vector<double> a(th.data(), th.data() + na);
  if (!th.allFinite() || !is_stable(a, 1e-6)) return {};
  return a;
}

// The constant and the free responses through 1/A, then y.
HeDataFit::Columns HeDataFit::fixed_columns() const {
  Columns c;
  c.add(step_, 0);
  for (std::size_t k = 0; k < a_.size(); ++k) c.add(impulse_, k);
  c.add(y_, 0);
  return c;
}

// Sums over the scored rows t0 <= t < N of the products of left's and right's columns into
// out. A block of rows at a time, so that a column's block is read from memory once and every
// product is a vectorised dot product in cache.
// A product whose mirror (the same two columns the other way round) comes earlier is copied
// from it, not summed again: a Gram matrix costs its upper triangle.
void HeDataFit::scored_dots(const Columns& left, const Columns& right, Eigen::MatrixXd& out) const {
  constexpr std::size_t kBlock = 512;
  out.setZero(left.n, right.n);
  auto same = [](const Column& a, const Column& b) { return a.v == b.v && a.lag == b.lag; };
  // mirror[i][j] = i' * kMaxColumns + j' of an earlier product of the same pair, or -1.
  std::array<std::array<int, kMaxColumns>, kMaxColumns> mirror;
  for (int i = 0; i < left.n; ++i)
    for (int j = 0; j < right.n; ++j) {
      mirror[i][j] = -1;
      for (int i2 = 0; i2 < i && mirror[i][j] < 0; ++i2)
        for (int j2 = 0; j2 < right.n; ++j2)
          if (same(left.c[i2], right.c[j]) && same(right.c[j2], left.c[i])) {
            mirror[i][j] = i2 * kMaxColumns + j2;
            break;
          }
    }
  for (std::size_t t = t0_; t < u_.size(); t += kBlock) {
    const std::size_t len = std::min(kBlock, u_.size() - t);
    auto block = [&](const Column& c) { return c.v + (t - c.lag); };
    for (int i = 0; i < left.n; ++i) {
      std::array<const double*, kMaxColumns> r;
      std::array<int, kMaxColumns> at;
      std::array<double, kMaxColumns> d;
      std::size_t m = 0;
      for (int j = 0; j < right.n; ++j)
        if (mirror[i][j] < 0) {
          r[m] = block(right.c[static_cast<std::size_t>(j)]);
          at[m++] = j;
        }
      dots(block(left.c[static_cast<std::size_t>(i)]), r.data(), m, len, d.data());
      for (std::size_t k = 0; k < m; ++k) out(i, at[k]) += d[k];
    }
  }
  for (int i = 0; i < left.n; ++i)
    for (int j = 0; j < right.n; ++j)
      if (mirror[i][j] >= 0)
        out(i, j) = out(mirror[i][j] / kMaxColumns, mirror[i][j] % kMaxColumns);
}

// The taps' products with each other into out's left block. The taps are one series at lags
// l_0 < l_1 < ..., so the product of lags l_i <= l_j is the series against itself d = l_j - l_i
// back, summed over the scored rows moved back by l_i: one dot product per d, over the rows of
// l_0, and the few rows at the two ends where the others' differ.
void HeDataFit::tap_gram(const Columns& taps, Eigen::MatrixXd& out) const {
  const double* v = taps.c[0].v;
  const std::size_t l0 = taps.c[0].lag, N = u_.size();
  std::array<double, kMaxColumns> base{};
  std::array<const double*, kMaxColumns> back{};
  for (int d = 0; d < taps.n; ++d) back[static_cast<std::size_t>(d)] = v + (t0_ - l0 - d);
  dots(v + (t0_ - l0), back.data(), static_cast<std::size_t>(taps.n), N - t0_, base.data());
  for (int i = 0; i < taps.n; ++i)
    for (int j = i; j < taps.n; ++j) {
      const std::size_t li = taps.c[static_cast<std::size_t>(i)].lag,
                        d = taps.c[static_cast<std::size_t>(j)].lag - li;
      double sum = base[d];
      // Rows s of the series: l_0's are t0 - l0 .. N - 1 - l0, l_i's e = li - l0 earlier.
      for (std::size_t s = t0_ - li; s < t0_ - l0; ++s) sum += v[s] * v[s - d];
      for (std::size_t s = N - li; s < N - l0; ++s) sum -= v[s] * v[s - d];
      out(i, j) = out(j, i) = sum;
    }
}

// x through 1/A from rest into f_ and, when the poles changed, the fixed regressors (the
// constant and the free responses through 1/A) and their sums of products with each other and
// y, which do not depend on the valve. The free response of initial state k is the impulse
// response delayed by k, and the constant's response the impulse response's running sum.
void HeDataFit::filter(const std::vector<double>& x) const {
  const bool fixed = !fixed_ready_;
  switch (a_.size()) {  // the common orders unrolled: the recursion is the inner loop
    case 0:
      fixed ? filter_n<0, true>(x) : filter_n<0, false>(x);
      break;
    case 1:
      fixed ? filter_n<1, true>(x) : filter_n<1, false>(x);
      break;
    case 2:
      fixed ? filter_n<2, true>(x) : filter_n<2, false>(x);
      break;
    case 3:
      fixed ? filter_n<3, true>(x) : filter_n<3, false>(x);
      break;
    default:
      fixed ? filter_n<-1, true>(x) : filter_n<-1, false>(x);
  }
  if (fixed) {
    const Columns c = fixed_columns();
    fixed_gram_.resize(c.n, c.n);
    scored_dots(c, c, fixed_gram_);
    fixed_ready_ = true;
  }
}

// The recursions of x and of the impulse response in one loop: their latencies overlap. For the
// unrolled orders the past outputs stay in registers: loading f[t - 1] back from memory put a
// store-forwarding delay on the chain, the filter's critical path. Same arithmetic, same order.
template <int NA, bool kFixed>
void HeDataFit::filter_n(const std::vector<double>& x) const {
  const std::size_t N = x.size();
  const std::size_t na = NA >= 0 ? static_cast<std::size_t>(NA) : a_.size();
  const double* a = a_.data();
  f_.resize(N);
  if (kFixed) {
    impulse_.resize(N);
    step_.resize(N);
  }
  double* f = f_.data();
  double* h = impulse_.data();
  double* st = step_.data();
  double sum = 0.0;
  const std::size_t head = NA >= 0 ? std::min(na, N) : N;
  for (std::size_t t = 0; t < head; ++t) {
    double v = x[t], g = t == 0 ? 1.0 : 0.0;
    const std::size_t k = t >= na ? na : t;
    for (std::size_t i = 1; i <= k; ++i) {
      v -= a[i - 1] * f[t - i];
      if (kFixed) g -= a[i - 1] * h[t - i];
    }
    f[t] = v;
    if (kFixed) {
      h[t] = g;
      st[t] = sum += g;
    }
  }
  if constexpr (NA >= 0) {
    // fp[i - 1] = f[t - i], hp[i - 1] = h[t - i].
    std::array<double, NA + 1> c{}, fp{}, hp{};
    for (std::size_t i = 0; i < na; ++i) {
      c[i] = a[i];
      fp[i] = f[head - 1 - i];
      if (kFixed) hp[i] = h[head - 1 - i];
    }
    for (std::size_t t = head; t < N; ++t) {
      double v = x[t], g = 0.0;
      for (std::size_t i = 0; i < na; ++i) {
        v -= c[i] * fp[i];
        if (kFixed) g -= c[i] * hp[i];
      }
      for (std::size_t i = na; i-- > 1;) {
        fp[i] = fp[i - 1];
        if (kFixed) hp[i] = hp[i - 1];
      }
      if (na > 0) {
        fp[0] = v;
        if (kFixed) hp[0] = g;
      }
      f[t] = v;
      if (kFixed) {
        h[t] = g;
        st[t] = sum += g;
      }
    }
  }
}

// He's flowchart as the simulator and a PLC-driven valve see it: the OP is held between
// samples (zero-order hold), so the valve takes each sample's OP change as one step and slips
// at most once per sample (the probe's He, stiction_probe_fit.cpp, mimics the Preisach model's
// input instead). With several bands, the band of the region the valve is held in applies, as
// PositionDependentStiction in src/sim has it.
// Returns a fingerprint of the position: a hash of the start and of every slip (sample, new
// position). Equal fingerprints mean equal positions (two of 10^4 positions collide with a
// chance of 10^-11), so a cost is not computed twice for the same position.
std::uint64_t HeDataFit::valve_into(const std::vector<Band>& bands, std::vector<double>& x) const {
  const int R = static_cast<int>(bands.size());
  double u_prev = u_.front(), xv = u_prev, u_r = 0.0;
  std::uint64_t key = mix(std::bit_cast<std::uint64_t>(xv));
  x.resize(u_.size());
  for (std::size_t t = 0; t < u_.size(); ++t) {
    const Band& b =
        R == 1
            ? bands.front()
            : bands[static_cast<std::size_t>(std::clamp(
                  static_cast<int>(std::floor((xv - region_lo_) / region_width_ * R)), 0, R - 1))];
    const double u_cum = u_r + (u_[t] - u_prev);
    u_prev = u_[t];
    if (std::abs(u_cum) > b.fs) {
      u_r = u_cum > 0 ? b.fd : -b.fd;
      xv = u_[t] - u_r;
      key = mix(mix(key ^ t) ^ std::bit_cast<std::uint64_t>(xv));
    } else {
      u_r = u_cum;
    }
    x[t] = xv;
  }
  return key;
}

// splitmix64's finaliser.
std::uint64_t HeDataFit::mix(std::uint64_t z) {
  z += 0x9e3779b97f4a7c15u;
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9u;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebu;
  return z ^ (z >> 31);
}

double refine_poles(HeDataFit& fit, const std::vector<double>& x) {
  std::vector<double> a = fit.poles();
  double best = fit.cost(x);
  if (a.empty()) return best;
  struct Ctx {
    HeDataFit* fit;
    const std::vector<double>* x;
  } ctx{&fit, &x};
  auto f = [](unsigned n, const double* z, double*, void* data) {
    auto* c = static_cast<Ctx*>(data);
    std::vector<double> av(z, z + n);
    if (!is_stable(av, 1e-6)) return 1e300;
    c->fit->set_poles(av);
    return c->fit->cost(*c->x);
  };
  const unsigned n = static_cast<unsigned>(a.size());
  nlopt_opt o = nlopt_create(NLOPT_LN_NELDERMEAD, n);
  nlopt_set_min_objective(o, f, &ctx);
  // Steps small against the distance to the unit circle: a slow pole sits within 1e-3 of it.
  const double margin = std::max(1e-4, 1.0 - spectral_radius(a));
  std::vector<double> dx(n, 0.3 * margin);
  nlopt_set_initial_step(o, dx.data());
  nlopt_set_xtol_abs1(o, 1e-3 * margin);
  nlopt_set_maxeval(o, 150);
  std::vector<double> z = a;
  double fz = best;
  const nlopt_result res = nlopt_optimize(o, z.data(), &fz);
  nlopt_destroy(o);
  if (res > 0 && fz < best) {
    best = fz;
    a = z;
  }
  fit.set_poles(a);
  return best;
}

}  // namespace valvediag::detail
