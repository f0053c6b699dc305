#include "valvediag/core/relay_design.hpp"

#include <algorithm>
#include <stdexcept>
#include <string>
#include <unordered_map>

namespace valvediag {

namespace {

struct BitsHash {
  std::size_t operator()(const std::vector<std::uint64_t>& v) const noexcept {
    std::size_t h = 1469598103934665603ull;
    for (auto w : v) h = (h ^ w) * 1099511628211ull + (h >> 17);
    return h;
  }
};

std::vector<std::uint64_t> pack(const std::vector<std::int8_t>& gamma) {
  std::vector<std::uint64_t> bits((gamma.size() + 63) / 64, 0);
  for (std::size_t k = 0; k < gamma.size(); ++k)
    if (gamma[k] > 0) bits[k / 64] |= std::uint64_t{1} << (k % 64);
  return bits;
}

}  // namespace

RelayDesign::RelayDesign(const PreisachGrid& grid, const std::vector<double>& u,
                         const std::vector<double>& y, const std::vector<int>& history,
                         const RelayDesignOptions& opt)
    : grid_(grid), history_(history), max_lag_(opt.max_lag) {
  if (y.size() != u.size()) throw std::invalid_argument("RelayDesign: u and y differ in length");
  start_ = opt.start;
  end_ = opt.end == 0 ? u.size() : std::min(opt.end, u.size());
  // Only the estimation window's past shapes the columns: validation samples must not.
  const std::size_t N = end_;
  if (start_ < static_cast<std::size_t>(std::max(opt.max_lag, opt.max_na)) || start_ >= end_) {
    throw std::invalid_argument("RelayDesign: equation window must start after the largest lag");
  }
  const int K = grid.relay_count();

  // One pass: state index per sample, the distinct relay vectors as rows.
  PreisachState st(grid);
  st.apply_history(history);
  std::unordered_map<std::vector<std::uint64_t>, int, BitsHash> index;
  std::vector<std::vector<std::int8_t>> rows;
  state_.resize(N);
  int current = -1;
  int last_level = -1;
  for (std::size_t t = 0; t < N; ++t) {
    const int v = grid.level(u[t]);
    if (v != last_level || current < 0) {
      st.move_to(v);
      last_level = v;
      auto key = pack(st.relays());
      auto [it, inserted] = index.emplace(std::move(key), static_cast<int>(rows.size()));
      if (inserted) rows.push_back(st.relays());
      current = it->second;
    }
    state_[t] = current;
  }
  const int D = static_cast<int>(rows.size());

  // Merge relays whose columns (histories over the visited states) are identical; drop constants.
  column_of_relay_.assign(static_cast<std::size_t>(K), -1);
  std::unordered_map<std::vector<std::uint64_t>, int, BitsHash> col_index;
  std::vector<int> representative;
  for (int k = 0; k < K; ++k) {
    std::vector<std::int8_t> col(static_cast<std::size_t>(D));
    bool varies = false;
    for (int s = 0; s < D; ++s) {
      col[static_cast<std::size_t>(s)] =
          rows[static_cast<std::size_t>(s)][static_cast<std::size_t>(k)];
      if (col[static_cast<std::size_t>(s)] != col[0]) varies = true;
    }
    if (!varies) continue;
    if (!opt.merge_identical) {
      column_of_relay_[static_cast<std::size_t>(k)] = static_cast<int>(representative.size());
      representative.push_back(k);
      continue;
    }
    auto [it, inserted] = col_index.emplace(pack(col), static_cast<int>(representative.size()));
    if (inserted) representative.push_back(k);
    column_of_relay_[static_cast<std::size_t>(k)] = it->second;
  }
  const int Kp = static_cast<int>(representative.size());
  column_size_.assign(static_cast<std::size_t>(Kp), 0);
  for (int k = 0; k < K; ++k)
    if (column_of_relay_[static_cast<std::size_t>(k)] >= 0)
      ++column_size_[static_cast<std::size_t>(column_of_relay_[static_cast<std::size_t>(k)])];
  gamma_.resize(D, Kp);
  for (int s = 0; s < D; ++s)
    for (int c = 0; c < Kp; ++c)
      gamma_(s, c) = rows[static_cast<std::size_t>(s)]
                         [static_cast<std::size_t>(representative[static_cast<std::size_t>(c)])];

  // State-space sums over the equation window, then relay space.
  const int dmax = opt.max_lag;
  const int na = opt.max_na;
  n_.assign(static_cast<std::size_t>(dmax + 1), Eigen::VectorXd::Zero(D));
  h_.assign(
      static_cast<std::size_t>(dmax + 1),
      std::vector<Eigen::VectorXd>(static_cast<std::size_t>(na + 1), Eigen::VectorXd::Zero(D)));
  for (int d = 0; d <= dmax; ++d) {
    auto& nd = n_[static_cast<std::size_t>(d)];
    auto& hd = h_[static_cast<std::size_t>(d)];
    for (std::size_t t = start_; t < end_; ++t) {
      const int s = state_[t - static_cast<std::size_t>(d)];
      nd[s] += 1.0;
      for (int i = 0; i <= na; ++i)
        hd[static_cast<std::size_t>(i)][s] += y[t - static_cast<std::size_t>(i)];
    }
  }
  g_.assign(static_cast<std::size_t>(dmax + 1), Eigen::VectorXd());
  r_.assign(static_cast<std::size_t>(dmax + 1),
            std::vector<Eigen::VectorXd>(static_cast<std::size_t>(na + 1)));
  for (int d = 0; d <= dmax; ++d) {
    g_[static_cast<std::size_t>(d)] = gamma_.transpose() * n_[static_cast<std::size_t>(d)];
    for (int i = 0; i <= na; ++i)
      r_[static_cast<std::size_t>(d)][static_cast<std::size_t>(i)] =
          gamma_.transpose() * h_[static_cast<std::size_t>(d)][static_cast<std::size_t>(i)];
  }
}

const RelayDesign::PairCounts& RelayDesign::pairs(int d, int dp) const {
  auto key = std::make_pair(d, dp);
  auto it = pairs_.find(key);
  if (it != pairs_.end()) return it->second;
  const std::int64_t D = states();
  std::unordered_map<std::int64_t, double> counts;
  for (std::size_t t = start_; t < end_; ++t) {
    const std::int64_t s = state_[t - static_cast<std::size_t>(d)];
    const std::int64_t sp = state_[t - static_cast<std::size_t>(dp)];
    counts[s * D + sp] += 1.0;
  }
  PairCounts pc(counts.begin(), counts.end());
  std::sort(pc.begin(), pc.end());
  return pairs_.emplace(key, std::move(pc)).first->second;
}

const Eigen::MatrixXd& RelayDesign::Q(int d, int dp) const {
  if (d < 0 || dp < 0 || d > max_lag_ || dp > max_lag_) {
    throw std::out_of_range("RelayDesign::Q: lag out of range");
  }
  auto key = std::make_pair(d, dp);
  auto it = Q_.find(key);
  if (it != Q_.end()) return it->second;
  Eigen::MatrixXd q;
  if (d == dp) {
    q = gamma_.transpose() * n_[static_cast<std::size_t>(d)].asDiagonal() * gamma_;
  } else {
    // Gamma' C Gamma with C the sparse pair counts: accumulate C Gamma row by row.
    const auto& pc = pairs(d, dp);
    const std::int64_t D = states();
    Eigen::MatrixXd CG = Eigen::MatrixXd::Zero(D, columns());
    for (const auto& [key2, c] : pc) CG.row(key2 / D) += c * gamma_.row(key2 % D);
    q = gamma_.transpose() * CG;
  }
  return Q_.emplace(key, std::move(q)).first->second;
}

double RelayDesign::cross(int d, int dp, const Eigen::VectorXd& w) const {
  if (d == dp) return n_[static_cast<std::size_t>(d)].dot(w.cwiseProduct(w));
  const std::int64_t D = states();
  double s = 0.0;
  for (const auto& [key, c] : pairs(d, dp)) s += c * w[key / D] * w[key % D];
  return s;
}

std::vector<double> RelayDesign::expand(const Eigen::VectorXd& cw) const {
  std::vector<double> mu(column_of_relay_.size(), 0.0);
  for (std::size_t k = 0; k < mu.size(); ++k) {
    const int c = column_of_relay_[k];
    if (c >= 0) mu[k] = cw[c] / column_size_[static_cast<std::size_t>(c)];
  }
  return mu;
}

}  // namespace valvediag
