#pragma once
// What the benchmarks share: the median of repeated timings (robust to a run disturbed by
// another process).
#include <algorithm>
#include <vector>

namespace valvediag::bench {

inline double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

}  // namespace valvediag::bench
