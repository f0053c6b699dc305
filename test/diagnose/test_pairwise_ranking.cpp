// rank_by_wins (pairwise_ranking.hpp) and the text/statistics helpers (text_stats.hpp).
#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "valvediag/diagnose/pairwise_ranking.hpp"
#include "valvediag/util/text_stats.hpp"

using valvediag::rank_by_wins;

namespace {
struct Item {
  int key;  // ranks by key, higher first; equal keys are ties
  int id;   // position before ranking
};
}  // namespace

TEST_CASE("rank_by_wins equals stable_sort for strict weak orders (seeded sweep)") {
  std::mt19937 rng(20261125);
  for (int trial = 0; trial < 500; ++trial) {
    const int n = std::uniform_int_distribution<int>(0, 12)(rng);
    const int keys = std::uniform_int_distribution<int>(1, 6)(rng);  // few keys: many ties
    std::vector<Item> v;
    for (int i = 0; i < n; ++i) v.push_back({std::uniform_int_distribution<int>(0, keys)(rng), i});
    auto above = [](const Item& a, const Item& b) { return a.key > b.key; };
    std::vector<Item> want = v;
    std::stable_sort(want.begin(), want.end(), above);
    rank_by_wins(v, above);
    REQUIRE(v.size() == want.size());
    for (std::size_t i = 0; i < v.size(); ++i) CHECK(v[i].id == want[i].id);
  }
}

TEST_CASE("rank_by_wins is defined for a cycle: its members tie, in their given order") {
  // Rock-paper-scissors over 0, 1, 2 (each beats the next), and 3 beaten by all of them.
  auto above = [](const Item& a, const Item& b) {
    if (a.key == 3 || b.key == 3) return b.key == 3 && a.key != 3;
    return (a.key + 1) % 3 == b.key;
  };
  for (const std::vector<int>& start : {std::vector<int>{3, 2, 1, 0}, {1, 3, 0, 2}, {0, 1, 2, 3}}) {
    std::vector<Item> v;
    for (int k : start) v.push_back({k, static_cast<int>(v.size())});
    rank_by_wins(v, above);
    std::vector<int> cycle;
    for (int k : start)
      if (k != 3) cycle.push_back(k);
    REQUIRE(v.size() == 4);
    for (std::size_t i = 0; i < 3; ++i) CHECK(v[i].key == cycle[i]);  // 2 wins each: a tie
    CHECK(v[3].key == 3);
  }
}

TEST_CASE("quantile and median: ranks, not interpolation; NaN when empty") {
  using valvediag::median;
  using valvediag::quantile;
  const std::vector<double> v{5, 1, 4, 2, 3};
  CHECK(quantile(v, 0.0) == 1);
  CHECK(quantile(v, 1.0) == 5);
  CHECK(median(v) == 3);
  CHECK(median({4, 1, 3, 2}) == 3);  // even count: the upper middle sample
  CHECK(quantile(v, 0.95) == 5);     // rank round(0.95 * 4) = 4
  CHECK(quantile(v, 0.3) == 2);      // rank round(1.2) = 1
  CHECK(quantile(v, 2.0) == 5);      // p clamped to [0, 1]
  CHECK(std::isnan(quantile({}, 0.5)));
  CHECK(std::isnan(median({})));
}

TEST_CASE("strprintf: exact length, no truncation of long sentences") {
  using valvediag::strprintf;
  CHECK(strprintf("%.1f %% of %s", 12.345, "travel") == "12.3 % of travel");
  CHECK(strprintf("plain") == "plain");
  const std::string long_word(600, 'x');  // the old private copies cut at 256 bytes
  const std::string s = strprintf("<%s>", long_word.c_str());
  CHECK(s.size() == 602);
  CHECK(s.back() == '>');
}
