// Discretized Preisach model (paper eqs 9-15, 23), read as ../shared/design/method-notes.md fixes
// it.
//
// Thresholds u_i = umin + (i-1) delta, i = 1..L+1. The virtual input level v in 0..L is the index
// of the threshold nearest to u (eq 23). Relay (i, j), 1 <= i <= j <= L:
//   +1 when v >= j (u above (u_j + u_{j+1})/2), -1 when v < i (u below (u_i + u_{i+1})/2),
//   otherwise it holds its previous value. Diagonal relays are a static staircase.
// Relays are stored in the paper's order (eq 14): (1,1), (1,2), ..., (1,L), (2,2), ..., (L,L).
#pragma once

#include <cstdint>
#include <vector>

namespace valvediag {

struct PreisachGrid {
  double umin = 0.0;
  double umax = 100.0;
  int L = 10;  // discretization level, >= 1

  double delta() const { return (umax - umin) / L; }
  double threshold(int i) const { return umin + (i - 1) * delta(); }  // 1-based, i = 1..L+1
  int relay_count() const { return L * (L + 1) / 2; }
  // Index of relay (i, j) in the paper's order, 1 <= i <= j <= L.
  int relay_index(int i, int j) const { return (i - 1) * L - (i - 1) * (i - 2) / 2 + (j - i); }
  // Virtual input level (eq 23): nearest threshold index minus one, clamped to 0..L.
  int level(double u) const;
};

// The relay states of a Preisach model, updated level by level. Only the relays whose
// thresholds are crossed flip, so one update costs O(L * levels crossed), not O(K).
class PreisachState {
 public:
  explicit PreisachState(const PreisachGrid& grid);  // all relays -1, level 0 (u at umin)
  const PreisachGrid& grid() const { return grid_; }
  int level() const { return level_; }
  // Moves the virtual input to level v (0..L), flipping the relays it crosses. With weights,
  // returns the change of gamma' mu (so an output can be kept up to date in O(flips)).
  double move_to(int v, const std::vector<double>* mu = nullptr);
  // Drives the state through a sequence of levels (e.g. an assumed history before the data).
  void apply_history(const std::vector<int>& levels);
  std::int8_t relay(int k) const { return gamma_[static_cast<std::size_t>(k)]; }
  const std::vector<std::int8_t>& relays() const { return gamma_; }
  double output(const std::vector<double>& mu) const;  // gamma' mu

 private:
  PreisachGrid grid_;
  int level_ = 0;
  std::vector<std::int8_t> gamma_;
};

// A Preisach model with weights: x = gamma(u)' mu. Used as a valve block in the simulator and
// for simulating identified models.
class PreisachModel {
 public:
  PreisachModel(PreisachGrid grid, std::vector<double> mu, double offset = 0.0);
  // Resets the memory to the state reached by the given level history (default: {0}, i.e. the
  // input came up from umin).
  void reset(const std::vector<int>& history = {0});
  double step(double u);  // one sample: updates the memory, returns the output
  std::vector<double> simulate(const std::vector<double>& u, const std::vector<int>& history = {0});
  const PreisachGrid& grid() const { return grid_; }
  const std::vector<double>& weights() const { return mu_; }
  double offset() const { return offset_; }

 private:
  PreisachGrid grid_;
  std::vector<double> mu_;
  double offset_;
  PreisachState state_;
  double x_ = 0.0;  // gamma' mu of the current state
};

// Weights that reproduce He's stiction model (fs, fd) on a grid (paper eqs 7-8, Proposition 1),
// placed on the nearest relays of the discretization. x = gamma' mu + offset; with all relays at
// -1 (history {0}) the valve rests at umin + fd, as a He valve that came down to umin.
struct PreisachWeights {
  std::vector<double> mu;
  double offset = 0.0;
};
PreisachWeights he_stiction_weights(const PreisachGrid& grid, double fs, double fd);

}  // namespace valvediag
