// Ranking by a pairwise rule that need not be transitive.
//
// Why: the diagnosis ranks its findings by a rule of several clauses (clearly more gain on both
// parts, then fewer parameters, then score), and such a rule can form a cycle (a over b, b over
// c, c over a). std::sort and std::stable_sort are undefined for a comparator that is not a
// strict weak order. Counting, for each item, how many others the rule puts it above (a
// Copeland count) and sorting by that count is defined for any rule; where the rule is a strict
// weak order it gives the same order as std::stable_sort with it. Standard library only.
#pragma once

#include <algorithm>
#include <cstddef>
#include <utility>
#include <vector>

namespace valvediag {

// Reorders v: most wins first, ties in their order in v. above(a, b): a ranks above b.
// O(n^2) calls of the rule: meant for the handful of effects a diagnosis tries.
template <class T, class Rule>
void rank_by_wins(std::vector<T>& v, Rule above) {
  const std::size_t n = v.size();
  std::vector<std::size_t> wins(n, 0), order(n);
  for (std::size_t i = 0; i < n; ++i)
    for (std::size_t j = 0; j < n; ++j)
      if (i != j && above(v[i], v[j])) ++wins[i];
  for (std::size_t i = 0; i < n; ++i) order[i] = i;
  std::stable_sort(order.begin(), order.end(),
                   [&wins](std::size_t i, std::size_t j) { return wins[i] > wins[j]; });
  std::vector<T> ranked;
  ranked.reserve(n);
  for (std::size_t i : order) ranked.push_back(std::move(v[i]));
  v = std::move(ranked);
}

}  // namespace valvediag
