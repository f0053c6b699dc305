// One-step prediction error benchmark (a benchmark, not a test): the prediction refit scores
// thousands of valve positions on the same PV (prediction_refit.hpp). PredictionErrorSearch sums
// PV's columns once and the valve position's by sliding lagged sums; arx_prediction_error forms
// the normal equations row by row and scores every sample again. Both on the same valve
// positions (a friction of growing band on a simulated paper-ex1 loop, as a refit's grid
// visits). Prints medians of repeated runs, the ratio, and the largest relative difference of
// the two variances.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <vector>

#include "bench_timing.hpp"
#include "valvediag/diagnose/prediction_error.hpp"
#include "valvediag/sim/scenarios.hpp"
#include "valvediag/sim/valve_effects.hpp"

using namespace valvediag;
using Clock = std::chrono::steady_clock;

int main(int argc, char** argv) {
  const int reps = argc > 1 ? std::atoi(argv[1]) : 5;
  for (std::size_t N : {4000u, 25000u}) {
    const LoopData d = run_scenario(scenario_by_name("paper-ex1"), 1, N);
    std::vector<std::vector<double>> xs;
    for (int k = 0; k < 40; ++k) {
      ValveChain chain({HeStiction(0.25 * (k + 1), 0.1 * (k + 1), 0.0)});
      std::vector<double> x(d.size());
      chain.reset(d.op[0]);
      chain.steps(d.op.data(), x.data(), d.size());
      xs.push_back(std::move(x));
    }
    const std::size_t order = 12, nk = 1, from = 40, end = d.size() * 7 / 10;
    const PredictionErrorSearch search(d.pv, order, from, end);
    std::vector<double> direct_s, search_s;
    double worst = 0.0;
    for (int rep = 0; rep < reps; ++rep) {
      std::vector<double> a, b;
      auto t0 = Clock::now();
      for (const auto& x : xs)
        a.push_back(arx_prediction_error(d.pv, x, nk, order, from, end).estimation_variance);
      auto t1 = Clock::now();
      for (const auto& x : xs) b.push_back(search.estimation_variance(x, nk));
      auto t2 = Clock::now();
      direct_s.push_back(std::chrono::duration<double>(t1 - t0).count());
      search_s.push_back(std::chrono::duration<double>(t2 - t1).count());
      for (std::size_t i = 0; i < xs.size(); ++i)
        worst = std::max(worst, std::abs(a[i] - b[i]) / a[i]);
    }
    const double n = static_cast<double>(xs.size());
    const double p = bench::median(direct_s) / n * 1e3, s = bench::median(search_s) / n * 1e3;
    std::printf(
        "one-step prediction, order %zu, N = %5zu (70 %% estimation), %zu valve positions: "
        "direct %.3f ms, search %.3f ms per position (%.1fx), largest relative difference "
        "%.1e (medians of %d runs)\n",
        order, d.size(), xs.size(), p, s, p / s, worst, reps);
  }
  return 0;
}
