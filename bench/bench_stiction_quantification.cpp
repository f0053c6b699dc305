// Stiction quantification benchmark (a benchmark, not a test): quantify_stiction(model, op, pv)
// on the paper's Example 1 loop at several record lengths, beside the baseline that computes
// every valve path (StictionQuantificationOptions::reuse_costs = false: the probe scored sample
// by sample, every candidate's cost computed even when its valve slips on the same samples as
// one already scored). The model is identified once per length with fit's defaults. Prints
// medians of repeated runs, the ratio, and whether both report the same figures.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <vector>

#include "valvediag/identification.hpp"
#include "valvediag/scenarios.hpp"
#include "valvediag/stiction_quantification.hpp"

using namespace valvediag;
using Clock = std::chrono::steady_clock;

namespace {

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

}  // namespace

int main(int argc, char** argv) {
  const int reps = argc > 1 ? std::max(1, std::atoi(argv[1])) : 3;
  std::printf(
      "stiction quantification: paper-ex1 seed 1 (truth fs 8.40, fd 3.52), fit's default orders; "
      "medians of %d runs\n",
      reps);
  std::printf("%-8s %12s %12s %8s  %-24s %s\n", "N", "baseline s", "valvediag s", "speed-up",
              "fs, fd (valvediag)", "same");
  for (const std::size_t N : {std::size_t{3000}, std::size_t{12000}, std::size_t{48000}}) {
    const LoopData d = run_scenario(scenario_by_name("paper-ex1"), 1, N);
    const IdentificationResult r = identify(d.op, d.pv, FitOptions{});
    StictionQuantificationOptions every;
    every.reuse_costs = false;
    std::vector<double> base_s, fast_s;
    StictionQuantification a, b;
    for (int rep = 0; rep < reps; ++rep) {
      auto t0 = Clock::now();
      a = quantify_stiction(r.model, d.op, d.pv, every);
      auto t1 = Clock::now();
      b = quantify_stiction(r.model, d.op, d.pv);
      auto t2 = Clock::now();
      base_s.push_back(std::chrono::duration<double>(t1 - t0).count());
      fast_s.push_back(std::chrono::duration<double>(t2 - t1).count());
    }
    const bool same = a.overall.fs_percent == b.overall.fs_percent &&
                      a.overall.fd_percent == b.overall.fd_percent;
    char figures[64];
    std::snprintf(figures, sizeof figures, "%.2f, %.2f", b.overall.fs_percent,
                  b.overall.fd_percent);
    std::printf("%-8zu %12.2f %12.2f %7.1fx  %-24s %s\n", N, median(base_s), median(fast_s),
                median(base_s) / median(fast_s), figures, same ? "yes" : "NO");
  }
  return 0;
}
