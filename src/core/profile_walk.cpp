#include "valvediag/core/profile_walk.hpp"

#include <algorithm>
#include <utility>
#include <vector>

namespace valvediag {

ProfileRange walk_profile(double v0, double c0, const ProfileWalk& walk,
                          const std::function<double(double, bool)>& cost,
                          const std::function<bool(double)>& inside) {
  std::vector<std::pair<double, double>> pts{{v0, c0}};  // (v, cost)
  ProfileRange out;
  for (const double dir : {-1.0, 1.0}) {
    double v = v0, step = walk.step;
    int misses = 0, run = 0, n = 0;
    for (; n < walk.max_steps && misses < walk.misses; ++n) {
      const double next = std::clamp(v + dir * step, walk.lower, walk.upper);
      if (next == v) break;  // the limit
      v = next;
      const double c = cost(v, n == 0);
      pts.push_back({v, c});
      if (inside(c)) {
        misses = 0;
        if (++run % walk.double_after == 0) step *= 2;
      } else {
        ++misses;
        run = 0;
      }
    }
    out.capped = out.capped || (n == walk.max_steps && misses < walk.misses);
  }
  std::sort(pts.begin(), pts.end());
  std::size_t first = pts.size(), last = 0;
  for (std::size_t k = 0; k < pts.size(); ++k)
    if (inside(pts[k].second)) {
      first = std::min(first, k);
      last = k;
    }
  if (first == pts.size()) {  // not even the best inside (a NaN cost): the best alone
    out.lo = out.hi = v0;
    return out;
  }
  out.lo = pts[first > 0 ? first - 1 : first].first;
  out.hi = pts[last + 1 < pts.size() ? last + 1 : last].first;
  out.open_above = pts[last].first >= walk.upper;
  return out;
}

}  // namespace valvediag
