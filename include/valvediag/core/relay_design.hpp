// The data seen through the relays of one discretization level L, compressed so that no N x K
// relay matrix is ever built.
//
// The Preisach state only changes when the virtual input changes level, and a record visits few
// distinct states. Each sample t gets the index s(t) of its state; the distinct states' relay
// vectors form the D x K' matrix `gamma` (relays with identical histories merged into one column,
// relays that never switch dropped: their effect is a constant, absorbed by c). Every sum the
// least-squares problems need is a D-vector or a sparse D x D count built in one pass over the
// data, then mapped to relay space once per L.
#pragma once

#include <Eigen/Dense>
#include <cstdint>
#include <map>
#include <utility>
#include <vector>

#include "valvediag/core/preisach.hpp"

namespace valvediag {

struct RelayDesignOptions {
  int max_lag = 13;       // largest d in s(t - d) needed: nk_max + nb_max
  int max_na = 3;         // largest output lag in the statistics
  int max_b_span = 3;     // nb_max: cross terms for |d - d'| < max_b_span
  std::size_t start = 0;  // first equation sample t0 (common to all configurations)
  std::size_t end = 0;    // one past the last equation sample (0: all)
  bool merge_identical = true;
};

class RelayDesign {
 public:
  // u and y of equal length. `history`: levels driven before the first sample (initial memory).
  RelayDesign(const PreisachGrid& grid, const std::vector<double>& u, const std::vector<double>& y,
              const std::vector<int>& history, const RelayDesignOptions& opt);

  const PreisachGrid& grid() const { return grid_; }
  int states() const { return static_cast<int>(gamma_.rows()); }
  int columns() const { return static_cast<int>(gamma_.cols()); }  // K' (merged, switching)
  const Eigen::MatrixXd& gamma() const { return gamma_; }          // D x K', entries +-1
  const std::vector<int>& state_of_sample() const { return state_; }
  // For each of the K relays: its merged column, or -1 if it never switched.
  const std::vector<int>& column_of_relay() const { return column_of_relay_; }
  const std::vector<int>& column_size() const { return column_size_; }
  const std::vector<int>& history() const { return history_; }
  std::size_t start() const { return start_; }
  std::size_t end() const { return end_; }

  // Relay-space statistics over the equation window [start, end):
  const Eigen::VectorXd& g(int d) const {
    return g_[static_cast<std::size_t>(d)];
  }                                               // sum gamma(t-d)
  const Eigen::VectorXd& r(int d, int i) const {  // sum gamma(t-d) y(t-i)
    return r_[static_cast<std::size_t>(d)][static_cast<std::size_t>(i)];
  }
  // sum gamma(t-d) gamma(t-d')' (cached, computed on first use).
  const Eigen::MatrixXd& Q(int d, int dp) const;
  // State-space statistics (D-vectors): counts and y cross sums, and pair counts.
  const Eigen::VectorXd& n(int d) const { return n_[static_cast<std::size_t>(d)]; }
  const Eigen::VectorXd& h(int d, int i) const {
    return h_[static_cast<std::size_t>(d)][static_cast<std::size_t>(i)];
  }
  // sum_t w[s(t-d)] w[s(t-d')] for a state-space vector w.
  double cross(int d, int dp, const Eigen::VectorXd& w) const;

  // Per-relay weights (K) from merged-column weights (K'): equal split inside a merged column.
  std::vector<double> expand(const Eigen::VectorXd& column_weights) const;

 private:
  using PairCounts = std::vector<std::pair<std::int64_t, double>>;  // (s * D + s', count)
  const PairCounts& pairs(int d, int dp) const;

  PreisachGrid grid_;
  std::vector<int> history_;
  std::size_t start_ = 0, end_ = 0;
  int max_lag_ = 0;
  std::vector<int> state_;
  Eigen::MatrixXd gamma_;
  std::vector<int> column_of_relay_;
  std::vector<int> column_size_;
  std::vector<Eigen::VectorXd> n_, g_;
  std::vector<std::vector<Eigen::VectorXd>> h_, r_;
  mutable std::map<std::pair<int, int>, PairCounts> pairs_;
  mutable std::map<std::pair<int, int>, Eigen::MatrixXd> Q_;
};

}  // namespace valvediag
