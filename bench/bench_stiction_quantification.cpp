// Stiction quantification benchmark (a benchmark, not a test): quantify_stiction(model, op, pv)
// on the paper's Example 1 loop at several record lengths, beside the baseline that computes
// every valve path on one core (StictionQuantificationOptions::reuse_costs = false: the probe
// scored sample by sample, every candidate's cost computed even when its valve slips on the same
// samples as one already scored; threads = 1), then valvediag on one core and on all cores. The
// model is identified once per length with fit's defaults. Prints medians of repeated runs, the
// ratios, and whether all three report the same figures.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <thread>
#include <vector>

#include "bench_timing.hpp"
#include "valvediag/core/identification.hpp"
#include "valvediag/core/stiction_quantification.hpp"
#include "valvediag/sim/scenarios.hpp"

using namespace valvediag;
using Clock = std::chrono::steady_clock;

int main(int argc, char** argv) {
  const int reps = argc > 1 ? std::max(1, std::atoi(argv[1])) : 3;
  const unsigned cores = std::max(1u, std::thread::hardware_concurrency());
  std::printf(
      "stiction quantification: paper-ex1 seed 1 (truth fs 8.40, fd 3.52), fit's default orders; "
      "medians of %d runs; %u cores\n",
      reps, cores);
  std::printf("%-7s %11s %14s %8s %14s %8s  %-12s %s\n", "N", "baseline s", "1 thread s",
              "speed-up", "all cores s", "speed-up", "fs, fd", "same");
  for (const std::size_t N : {std::size_t{3000}, std::size_t{12000}, std::size_t{48000}}) {
    const LoopData d = run_scenario(scenario_by_name("paper-ex1"), 1, N);
    const IdentificationResult r = identify(d.op, d.pv, FitOptions{});
    StictionQuantificationOptions every, one, all;
    every.reuse_costs = false;
    every.threads = one.threads = 1;
    all.threads = static_cast<int>(cores);
    std::vector<double> base_s, one_s, all_s;
    StictionQuantification a, b, c;
    auto seconds = [](Clock::time_point from, Clock::time_point to) {
      return std::chrono::duration<double>(to - from).count();
    };
    for (int rep = 0; rep < reps; ++rep) {
      const auto t0 = Clock::now();
      a = quantify_stiction(r.model, d.op, d.pv, every);
      const auto t1 = Clock::now();
      b = quantify_stiction(r.model, d.op, d.pv, one);
      const auto t2 = Clock::now();
      c = quantify_stiction(r.model, d.op, d.pv, all);
      const auto t3 = Clock::now();
      base_s.push_back(seconds(t0, t1));
      one_s.push_back(seconds(t1, t2));
      all_s.push_back(seconds(t2, t3));
    }
    auto same_as_b = [&](const StictionQuantification& q) {
      return q.overall.fs_percent == b.overall.fs_percent &&
             q.overall.fd_percent == b.overall.fd_percent;
    };
    char figures[64];
    std::snprintf(figures, sizeof figures, "%.2f, %.2f", b.overall.fs_percent,
                  b.overall.fd_percent);
    const double base = bench::median(base_s), fast1 = bench::median(one_s),
                 fastn = bench::median(all_s);
    std::printf("%-7zu %11.2f %14.2f %7.1fx %14.2f %7.1fx  %-12s %s\n", N, base, fast1,
                base / fast1, fastn, base / fastn, figures,
                same_as_b(a) && same_as_b(c) ? "yes" : "NO");
  }
  return 0;
}
