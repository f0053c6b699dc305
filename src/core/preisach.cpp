#include "valvediag/core/preisach.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace valvediag {

int PreisachGrid::level(double u) const {
  // Nearest threshold u_{v+1}: v = round((u - umin) / delta), ties rounded down as in eq 23.
  const double r = (u - umin) / delta();
  if (!(r > 0.5)) return 0;  // also catches NaN
  if (r > L - 0.5) return L;
  return static_cast<int>(std::ceil(r - 0.5));
}

PreisachState::PreisachState(const PreisachGrid& grid)
    : grid_(grid), gamma_(static_cast<std::size_t>(grid.relay_count()), std::int8_t{-1}) {
  if (grid.L < 1 || !(grid.umax > grid.umin)) {
    throw std::invalid_argument("Preisach grid needs L >= 1 and umax > umin");
  }
}

double PreisachState::move_to(int v, const std::vector<double>* mu) {
  const int L = grid_.L;
  v = std::clamp(v, 0, L);
  double change = 0.0;
  auto set = [&](int i, int j, std::int8_t value) {
    const auto k = static_cast<std::size_t>(grid_.relay_index(i, j));
    if (gamma_[k] != value) {
      if (mu) change += 2.0 * value * (*mu)[k];
      gamma_[k] = value;
    }
  };
  if (v > level_) {
    // Up thresholds j in (level_, v] are crossed: relays (i, j), i <= j, switch to +1.
    for (int j = level_ + 1; j <= v; ++j)
      for (int i = 1; i <= j; ++i) set(i, j, 1);
  } else if (v < level_) {
    // Down thresholds i in (v, level_] are crossed: relays (i, j), j >= i, switch to -1.
    for (int i = v + 1; i <= level_; ++i)
      for (int j = i; j <= L; ++j) set(i, j, -1);
  }
  level_ = v;
  return change;
}

void PreisachState::apply_history(const std::vector<int>& levels) {
  for (int v : levels) move_to(v);
}

double PreisachState::output(const std::vector<double>& mu) const {
  double x = 0.0;
  for (std::size_t k = 0; k < gamma_.size(); ++k) x += gamma_[k] * mu[k];
  return x;
}

PreisachModel::PreisachModel(PreisachGrid grid, std::vector<double> mu, double offset)
    : grid_(grid), mu_(std::move(mu)), offset_(offset), state_(grid) {
  if (static_cast<int>(mu_.size()) != grid_.relay_count()) {
    throw std::invalid_argument("Preisach weights: expected L(L+1)/2 weights");
  }
  reset();
}

void PreisachModel::reset(const std::vector<int>& history) {
  state_ = PreisachState(grid_);
  state_.apply_history(history);
  x_ = state_.output(mu_);
}

double PreisachModel::step(double u) {
  x_ += state_.move_to(grid_.level(u), &mu_);
  return x_ + offset_;
}

std::vector<double> PreisachModel::simulate(const std::vector<double>& u,
                                            const std::vector<int>& history) {
  reset(history);
  std::vector<double> x(u.size());
  for (std::size_t t = 0; t < u.size(); ++t) x[t] = step(u[t]);
  return x;
}

PreisachWeights he_stiction_weights(const PreisachGrid& grid, double fs, double fd) {
  if (!(fs > fd) || fd < 0) throw std::invalid_argument("He stiction weights need fs > fd >= 0");
  PreisachWeights w;
  w.mu.assign(static_cast<std::size_t>(grid.relay_count()), 0.0);
  const double d = grid.delta();
  double total = 0.0;
  // The valve came down to umin (residual force -fd, x = umin + fd), as in the proof of
  // Proposition 1. It slips up by fs - fd each time u passes alpha_j = umin + fs + fd +
  // (j - 1)(fs - fd), and the slip is undone below beta_j = alpha_j - (fs + fd) (eq 8, shifted so
  // that every slip up to umax is represented and no beta falls below umin).
  for (int j = 1;; ++j) {
    const double alpha = grid.umin + fs + fd + (j - 1) * (fs - fd);
    if (alpha > grid.umax) break;
    const double beta = alpha - (fs + fd);
    // Up threshold (u_j + u_{j+1})/2 = umin + (j - 1/2) delta matched to alpha, likewise beta.
    const int jj =
        std::clamp(static_cast<int>(std::lround((alpha - grid.umin) / d + 0.5)), 1, grid.L);
    const int ii = std::clamp(static_cast<int>(std::lround((beta - grid.umin) / d + 0.5)), 1, jj);
    w.mu[static_cast<std::size_t>(grid.relay_index(ii, jj))] += (fs - fd) / 2;
    total += (fs - fd) / 2;
  }
  w.offset = grid.umin + fd + total;  // all relays -1: x = umin + fd
  return w;
}

}  // namespace valvediag
