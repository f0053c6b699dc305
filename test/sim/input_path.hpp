// A valve-input test signal for the hysteresis tests.
#pragma once

#include <cmath>
#include <cstddef>
#include <vector>

namespace valvediag::test {

// Piecewise-linear input through the given turning points in steps of at most du.
inline std::vector<double> path(const std::vector<double>& turns, double du) {
  std::vector<double> u{turns.front()};
  for (std::size_t i = 1; i < turns.size(); ++i) {
    const double a = turns[i - 1], b = turns[i];
    const int n = static_cast<int>(std::ceil(std::abs(b - a) / du));
    for (int k = 1; k <= n; ++k) u.push_back(a + (b - a) * k / n);
  }
  return u;
}

}  // namespace valvediag::test
