#include <doctest/doctest.h>

#include <cmath>

#include "valvediag/core/profile_walk.hpp"

using namespace valvediag;

// A parabola's threshold crossing is bracketed by the walk's points; a flat side runs to the
// limit (open above) or out of steps (capped); a rugged side is not ended by one point outside.
TEST_CASE("walk_profile brackets the range, and says when a side is open or capped") {
  const auto inside = [](double c) { return c <= 1.0; };
  int restarts = 0;
  const auto parabola = [&](double v, bool restart) {
    restarts += restart;
    return (v - 0.5) * (v - 0.5) / 0.01;  // inside for |v - 0.5| <= 0.1
  };
  const ProfileRange a = walk_profile(0.5, 0.0, {0.0, 1.0, 0.01}, parabola, inside);
  CHECK(restarts == 2);  // once per side
  CHECK(a.lo <= 0.4);
  CHECK(a.lo >= 0.4 - 0.01 - 1e-12);
  CHECK(a.hi >= 0.6);
  CHECK(a.hi <= 0.6 + 0.01 + 1e-12);
  CHECK_FALSE(a.open_above);
  CHECK_FALSE(a.capped);

  const auto flat_above = [](double v, bool) { return v < 0.3 ? 2.0 : 0.5; };
  const ProfileRange b = walk_profile(0.5, 0.5, {0.0, 1.0, 0.05}, flat_above, inside);
  CHECK(b.open_above);
  CHECK(b.hi == 1.0);
  CHECK(b.lo < 0.3);

  ProfileWalk short_walk{0.0, 100.0, 0.01};
  short_walk.max_steps = 5;
  const ProfileRange c = walk_profile(
      50.0, 0.0, short_walk, [](double, bool) { return 0.0; }, inside);
  CHECK(c.capped);
  CHECK_FALSE(c.open_above);

  // One point outside between inside ones: the side goes on past it.
  const auto rugged = [](double v, bool) { return std::abs(v - 0.6) < 1e-9 ? 5.0 : 0.0; };
  const ProfileRange d = walk_profile(0.5, 0.0, {0.0, 0.8, 0.1}, rugged, inside);
  CHECK(d.hi == doctest::Approx(0.8));
  CHECK(d.open_above);
}
