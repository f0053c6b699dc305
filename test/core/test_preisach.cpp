#include <doctest/doctest.h>

#include <algorithm>
#include <random>

#include "valvediag/core/preisach.hpp"

using namespace valvediag;

TEST_CASE("virtual input rounds to the nearest threshold (eq 23)") {
  PreisachGrid g{0.0, 10.0, 10};
  CHECK(g.level(-5) == 0);
  CHECK(g.level(0.49) == 0);
  CHECK(g.level(0.5) == 0);  // ties go down as in eq 23
  CHECK(g.level(0.51) == 1);
  CHECK(g.level(7.2) == 7);
  CHECK(g.level(9.6) == 10);
  CHECK(g.level(50) == 10);
  CHECK(g.relay_index(1, 1) == 0);
  CHECK(g.relay_index(1, 10) == 9);
  CHECK(g.relay_index(2, 2) == 10);
  CHECK(g.relay_index(10, 10) == g.relay_count() - 1);
}

TEST_CASE("diagonal weights give a static staircase") {
  PreisachGrid g{0.0, 10.0, 10};
  std::vector<double> mu(static_cast<std::size_t>(g.relay_count()), 0.0);
  for (int i = 1; i <= g.L; ++i) mu[static_cast<std::size_t>(g.relay_index(i, i))] = 0.5;
  PreisachModel m(g, mu);
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> U(-1, 11);
  for (int t = 0; t < 2000; ++t) {
    const double u = U(rng);
    // Output depends on the level only: -sum + 2 * 0.5 * (number of diagonal relays on).
    const double expected = -5.0 + 1.0 * g.level(u);
    CHECK(m.step(u) == doctest::Approx(expected).epsilon(1e-12));
  }
}

TEST_CASE("one off-diagonal relay gives a backlash loop") {
  PreisachGrid g{0.0, 10.0, 10};
  std::vector<double> mu(static_cast<std::size_t>(g.relay_count()), 0.0);
  mu[static_cast<std::size_t>(g.relay_index(3, 7))] = 1.0;  // down below 2.5, up above 6.5
  PreisachModel m(g, mu);
  std::vector<double> up, down;
  for (double u = 0; u <= 10; u += 0.25) up.push_back(m.step(u));
  for (double u = 10; u >= 0; u -= 0.25) down.push_back(m.step(u));
  // Rising: -1 until u passes 6.5, then +1. Falling: +1 until u drops below 2.5.
  CHECK(up[static_cast<std::size_t>(6.5 / 0.25)] == -1.0);
  CHECK(up[static_cast<std::size_t>(6.75 / 0.25)] == 1.0);
  CHECK(down[static_cast<std::size_t>((10 - 2.75) / 0.25)] == 1.0);
  CHECK(down[static_cast<std::size_t>((10 - 2.25) / 0.25)] == -1.0);
  // The hold band is 4 units wide: at u = 5 the output depends on the direction of travel.
  CHECK(up[static_cast<std::size_t>(5 / 0.25)] == -1.0);
  CHECK(down[static_cast<std::size_t>((10 - 5) / 0.25)] == 1.0);
}

namespace {
// The alternating dominant extrema of a level sequence (paper eqs 5-6): the global maximum, the
// minimum after it, the maximum after that, ... and the final value.
std::vector<int> memory_sequence(const std::vector<int>& levels) {
  std::vector<int> out{levels.front()};
  std::size_t pos = 0;
  bool want_max = true;
  while (pos + 1 < levels.size()) {
    std::size_t best = pos + 1;
    for (std::size_t t = pos + 1; t < levels.size(); ++t)
      if (want_max ? levels[t] >= levels[best] : levels[t] <= levels[best]) best = t;  // last one
    out.push_back(levels[best]);
    pos = best;
    want_max = !want_max;
  }
  return out;
}
}  // namespace

TEST_CASE("wiping-out: the state depends only on the dominant extrema") {
  PreisachGrid g{0.0, 1.0, 12};
  std::mt19937_64 rng(11);
  std::uniform_int_distribution<int> step(-3, 3);
  for (int trial = 0; trial < 200; ++trial) {
    std::vector<int> levels{0};
    int v = 0;
    for (int t = 0; t < 60; ++t) {
      v = std::clamp(v + step(rng), 0, g.L);
      levels.push_back(v);
    }
    PreisachState full(g), reduced(g);
    full.apply_history(levels);
    reduced.apply_history(memory_sequence(levels));
    CHECK(full.relays() == reduced.relays());
  }
}

TEST_CASE("congruency: loops between the same extrema are translates of each other") {
  PreisachGrid g{0.0, 1.0, 16};
  std::mt19937_64 rng(3);
  std::vector<double> mu(static_cast<std::size_t>(g.relay_count()));
  std::uniform_real_distribution<double> U(0, 1);
  for (auto& w : mu) w = U(rng);
  std::uniform_int_distribution<int> lvl(0, g.L);
  for (int trial = 0; trial < 100; ++trial) {
    const int m = 5, M = 11;  // the loop's extrema
    std::vector<std::vector<double>> loops;
    for (int h = 0; h < 2; ++h) {
      PreisachState st(g);
      // A random past, then arrive at m from above M? No: any past that ends inside [m, M].
      for (int t = 0; t < 20; ++t) st.move_to(lvl(rng));
      st.move_to(m);
      std::vector<double> path;
      for (int k = 0; k < 2; ++k) {  // two cycles: m -> M -> m
        for (int v = m; v <= M; ++v) {
          st.move_to(v);
          path.push_back(st.output(mu));
        }
        for (int v = M; v >= m; --v) {
          st.move_to(v);
          path.push_back(st.output(mu));
        }
      }
      // Keep the second cycle (the first may still be settling onto the loop).
      loops.emplace_back(path.begin() + static_cast<long>(path.size() / 2), path.end());
    }
    const double shift = loops[1][0] - loops[0][0];
    for (std::size_t k = 0; k < loops[0].size(); ++k)
      CHECK(loops[1][k] - loops[0][k] == doctest::Approx(shift).epsilon(1e-9));
  }
}

TEST_CASE("incremental output equals the full sum") {
  PreisachGrid g{-3.0, 7.0, 20};
  std::mt19937_64 rng(5);
  std::vector<double> mu(static_cast<std::size_t>(g.relay_count()));
  std::uniform_real_distribution<double> U(0, 2), Uin(-4, 8);
  for (auto& w : mu) w = U(rng);
  PreisachModel m(g, mu, 1.5);
  PreisachState st(g);
  for (int t = 0; t < 5000; ++t) {
    const double u = Uin(rng);
    const double x = m.step(u);
    st.move_to(g.level(u));
    CHECK(x == doctest::Approx(st.output(mu) + 1.5).epsilon(1e-9));
  }
}
