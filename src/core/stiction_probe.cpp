#include "stiction_probe.hpp"

#include <algorithm>
#include <cmath>
#include <cstddef>

namespace valvediag::detail {

Probe forc_probe(const HammersteinModel& m, int lo, int hi) {
  const PreisachGrid& g = m.grid;
  auto at = [&](int k) { return g.umin + k * g.delta(); };
  Probe p;
  PreisachModel valve(g, m.mu, 0.0);
  valve.reset({0, hi});
  int k = hi;
  int current = -1;
  bool scored = false;
  auto go_to = [&](int target) {
    const int dir = target > k ? 1 : -1;
    while (k != target) {
      k += dir;
      p.u.push_back(at(k));
      p.x.push_back(valve.step(at(k)));
      p.reversal.push_back(current);
      p.since.push_back(
          current >= 0 ? std::abs(at(k) - p.reversal_u[static_cast<std::size_t>(current)]) : 0.0);
      p.scored.push_back(scored);
    }
  };
  auto reverse_here = [&] {
    p.reversal_u.push_back(at(k));
    current = static_cast<int>(p.reversal_u.size()) - 1;
  };
  go_to(lo);  // sets the memory, not scored
  scored = true;
  go_to(hi);
  go_to(lo);
  for (int v = lo + 1; v <= hi; ++v) {
    current = -1;
    go_to(v);
    reverse_here();
    go_to(lo);
  }
  current = -1;
  go_to(hi);
  for (int v = hi - 1; v >= lo; --v) {
    current = -1;
    go_to(v);
    reverse_here();
    go_to(hi);
  }
  p.longest_sweep = (hi - lo) * g.delta();
  return p;
}

Probe data_probe(const HammersteinModel& m, const std::vector<double>& op, double width) {
  Probe p;
  for (double u : op)
    if (std::isfinite(u)) p.u.push_back(u);
  p.x = simulate_valve(m, p.u);
  const std::size_t N = p.u.size();
  const double hyst = m.grid.delta() / 2;
  std::vector<std::size_t> turns;  // sample indices of turning points
  std::size_t ext = 0;
  int dir = 0;
  for (std::size_t t = 1; t < N; ++t) {
    const double d = p.u[t] - p.u[ext];
    if (dir >= 0 && p.u[t] > p.u[ext]) {
      ext = t;
      dir = 1;
    } else if (dir <= 0 && p.u[t] < p.u[ext]) {
      ext = t;
      dir = -1;
    } else if (dir != 0 && -dir * d > hyst) {
      turns.push_back(ext);
      ext = t;
      dir = -dir;
    }
  }
  p.reversal.assign(N, -1);
  p.since.assign(N, 0.0);
  std::size_t next = 0;
  int current = -1;
  for (std::size_t t = 0; t < N; ++t) {
    if (next < turns.size() && turns[next] == t) {
      p.reversal_u.push_back(p.u[t]);
      current = static_cast<int>(next++);
    }
    p.reversal[t] = current;
    if (current >= 0)
      p.since[t] = std::abs(p.u[t] - p.reversal_u[static_cast<std::size_t>(current)]);
  }
  // Longest sweep: between consecutive turning points, and from the start / to the end.
  std::vector<std::size_t> ends{0};
  ends.insert(ends.end(), turns.begin(), turns.end());
  if (N > 0) ends.push_back(N - 1);
  for (std::size_t i = 1; i < ends.size(); ++i)
    p.longest_sweep = std::max(p.longest_sweep, std::abs(p.u[ends[i]] - p.u[ends[i - 1]]));
  p.scored.assign(N, 0);
  double travel = 0.0;
  for (std::size_t t = 1; t < N; ++t) {
    travel += std::abs(p.u[t] - p.u[t - 1]);
    p.scored[t] = travel >= width;
  }
  return p;
}

}  // namespace valvediag::detail
