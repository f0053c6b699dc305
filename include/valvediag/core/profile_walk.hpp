#pragma once
// The range of one parameter that the data fit as well as its best value (a profile-likelihood
// interval), found by walking out from the best value on each side. Used where the profiled cost
// is rugged (stick-slip bands): one point outside does not end a side.

#include <functional>

namespace valvediag {

struct ProfileWalk {
  double lower = 0.0, upper = 1.0;  // the parameter's limits
  double step = 0.01;               // the first step out; it doubles after `double_after` points
  int double_after = 10;            // in a row inside
  int max_steps = 60;               // per side
  int misses = 3;                   // points in a row outside that end a side
};

struct ProfileRange {
  double lo = 0.0, hi = 0.0;  // each end bracketed by the next point out (or the limit)
  bool capped = false;        // a side reached max_steps still inside: the range is wider
  bool open_above = false;    // the highest point inside is `upper`: not bounded from above
};

// `cost(v, restart)`: the profiled cost at v (the other parameters re-fitted); `restart` is true on
// each side's first point, when a fit that starts from the previous point's should start from the
// best's again. `inside(c)`: whether a cost is within the threshold. v0 (cost c0) is the best.
ProfileRange walk_profile(double v0, double c0, const ProfileWalk& walk,
                          const std::function<double(double v, bool restart)>& cost,
                          const std::function<bool(double c)>& inside);

}  // namespace valvediag
