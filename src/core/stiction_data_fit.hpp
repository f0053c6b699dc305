// He's valve inside the Hammerstein structure, scored on the data (op, pv): the cost the
// refinement (stiction_refinement.cpp) and the intervals (stiction_interval.hpp) search over.
// Private to src/core.
#pragma once

#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
#include <unordered_map>
#include <vector>

#include "valvediag/core/hammerstein.hpp"

namespace valvediag::detail {

// He's bands (fs, fd) of one OP region.
struct Band {
  double fs, fd;
};

// He's valve inside the Hammerstein structure, fitted to the data (op, pv): for a candidate
// (fs, fd) the valve position x is simulated, and the linear part's simulated output
//   y(t) = B(q) / A(q) x(t) + c + free response of 1/A (unknown initial state)
// is linear in (b, c, initial state) for given poles A and delay nk: solved by least squares. The
// cost is the simulated-output error (eq 20), not the equation error, which measurement noise
// biases (and which a slow pole makes blind to the valve). Scored from `t0` on: after the OP has
// travelled its visited range, so He's unknown initial state (his memory before the first slip)
// is gone, as in the probe.
class HeDataFit {
 public:
  HeDataFit(const HammersteinModel& m, const std::vector<double>& op, const std::vector<double>& y,
            double width, int max_delay, bool remember, bool plain_sums);
  bool usable() const {
    return t0_ + 20 < u_.size() && var_y_ > 0 &&
           nb_ + 1 + static_cast<int>(a_.size()) <= static_cast<int>(kMaxColumns) - 1;
  }
  bool identity() const { return identity_; }
  double var_y() const { return var_y_; }
  // Equation-error least squares of A y = B x + c for the valve position x, with the current
  // delay and orders: the poles, or empty when A comes out unstable. y's sums come from the
  // constructor; x's enter by products.
  std::vector<double> ls_poles(const std::vector<double>& x) const;
  // Steiglitz-McBride: the output error's poles for the valve position x, approached by the
  // equation error of y and x filtered by 1/A of the previous pass (so its noise is nearly white
  // and does not bias A), from the current poles, `passes` times. Empty when A comes out unstable.
  std::vector<double> sm_poles(const std::vector<double>& x, int passes) const;
  const std::vector<double>& poles() const { return a_; }
  int delay() const { return nk_; }
  // At most what the scored rows leave room for (t0_ - dj >= 0 for every tap of B).
  void set_delay(int nk) {
    nk_ = std::clamp(nk, 0, std::max(0, static_cast<int>(t0_) - nb_ - 1));
    costs_.clear();
  }
  // A's coefficients. The fixed regressors that go with them are made by the next cost().
  void set_poles(const std::vector<double>& a) {
    a_ = a;
    costs_.clear();
    fixed_ready_ = false;
  }

  // Regions for several bands: R equal parts of [lo, lo + width].
  void set_regions(double lo, double width) {
    region_lo_ = lo;
    region_width_ = width > 0 ? width : 1.0;
  }
  std::vector<double> valve(const std::vector<Band>& bands) const {
    std::vector<double> x;
    valve_into(bands, x);
    return x;
  }
  std::vector<double> valve(double fs, double fd) const { return valve({{fs, fd}}); }
  // Returns the position's fingerprint (see valve_into).
  std::uint64_t valve(double fs, double fd, std::vector<double>& x) const {
    return valve_into({{fs, fd}}, x);
  }
  double cost(double fs, double fd) const { return cost(std::vector<Band>{{fs, fd}}); }
  // The cost of the position x whose fingerprint is key (from valve()): remembered as cost(bands)
  // remembers it, without simulating the valve again.
  double cost(std::uint64_t key, const std::vector<double>& x) const;
  // Up to kLanes single bands at once, each cost as cost(fs, fd) gives it: the valve's and the
  // filter's recursions are chains of dependent adds that leave the core waiting, and the lanes'
  // chains interleave.
  static constexpr std::size_t kLanes = 4;
  void costs(const Band* bands, std::size_t n, double* out) const;
  // Remembered per valve position while the linear part stays: neighbouring bands often slip on
  // the same samples.
  double cost(const std::vector<Band>& bands) const;
  // Residual sum of squares of the simulated output for the valve position x.
  double cost(const std::vector<double>& x) const { return solve(x, nullptr); }
  // The residual itself, over the scored rows.
  std::vector<double> residuals(const std::vector<double>& x) const {
    std::vector<double> r;
    solve(x, &r);
    return r;
  }

 private:
  static constexpr int kMaxColumns = 10;
  // Regressor columns as lagged series: column k holds v[t - lag] in row t.
  struct Column {
    const double* v;
    std::size_t lag;
  };
  struct Columns {
    std::array<Column, kMaxColumns> c{};
    int n = 0;
    void add(const std::vector<double>& v, std::size_t lag) {
      c[static_cast<std::size_t>(n++)] = {v.data(), lag};
    }
  };
  double solve(const std::vector<double>& x, std::vector<double>* residual) const;
  // solve() after the filter: f is x through 1/A (the fixed regressors ready).
  double solve_filtered(const std::vector<double>& f, std::vector<double>* residual) const;
  template <int NA>
  void filter_lanes(const std::array<const double*, kLanes>& x, std::size_t n) const;
  static void through(const std::vector<double>& in, double m, const std::vector<double>& a,
                      std::vector<double>& out);
  template <int NA>
  static void through_n(const std::vector<double>& in, double m, const std::vector<double>& a,
                        std::vector<double>& out);
  static std::vector<double> arx_poles(const Eigen::MatrixXd& P, int na);
  Columns fixed_columns() const;
  void scored_dots(const Columns& left, const Columns& right, Eigen::MatrixXd& out) const;
  void tap_gram(const Columns& taps, Eigen::MatrixXd& out) const;
  void filter(const std::vector<double>& x) const;
  template <int NA, bool kFixed>
  void filter_n(const std::vector<double>& x) const;
  std::uint64_t valve_into(const std::vector<Band>& bands, std::vector<double>& x) const;
  static std::uint64_t mix(std::uint64_t z);
  const std::vector<double>& u_;
  const std::vector<double>& y_;
  bool identity_ = false;
  std::vector<double> a_;
  int nb_ = 1, nk_ = 0;
  std::size_t t0_ = 0;
  const std::vector<double> ones_;  // the constant column of ls_poles
  // For the poles in a_ once fixed_ready_: 1/A's responses from rest (the fixed regressors) and
  // the products of the fixed regressors and y.
  mutable std::vector<double> impulse_, step_;
  mutable Eigen::MatrixXd fixed_gram_;
  mutable bool fixed_ready_ = false;
  Eigen::MatrixXd y_lags_;                  // products of y's lags and 1 (ls_poles)
  mutable Eigen::MatrixXd products_;        // scratch: B's taps against every column
  mutable Eigen::MatrixXd fixed_products_;  // scratch: B's taps against the fixed columns
  const bool remember_;                     // costs_ in use
  const bool plain_sums_;                   // the taps' products summed one by one (not tap_gram)
  mutable std::unordered_map<std::uint64_t, double> costs_;  // by position fingerprint
  double var_y_ = 0.0;
  double region_lo_ = 0.0, region_width_ = 1.0;
  mutable std::vector<double> x_, f_;                                // scratch
  mutable std::array<std::vector<double>, kLanes> lane_x_, lane_f_;  // scratch of costs()
  mutable std::vector<double> sm_y_, sm_x_;                          // scratch of sm_poles
  // sm_poles' first pass: y through sm_y0_poles_.
  mutable std::vector<double> sm_y0_, sm_y0_poles_;
  mutable bool sm_y0_valid_ = false;
};

// The poles for a fixed valve position x: Nelder-Mead over A's coefficients (unstable A rejected),
// b, c and the initial state by least squares inside. Returns the cost; fit keeps the best poles.
double refine_poles(HeDataFit& fit, const std::vector<double>& x);

}  // namespace valvediag::detail
