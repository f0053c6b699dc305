// Structure search benchmark (a benchmark, not a test): the ARX structure grid that every valve
// parameter a model fit tries pays for (ArxEstimator::fit), beside the plain scan
// (LinearOptions::plain_scan: the Gram blocks as dense matrix products, the same least squares,
// every structure simulated to the end, one after another, in a loop of general orders) on the
// same valve positions. The valve positions are a backlash of slowly growing width on a simulated
// paper-ex1 loop, as successive points of a search are. Prints medians of repeated runs, the
// ratio, and whether both chose the same structure with the same error (to 1e-6) at every
// point.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <vector>

#include "bench_timing.hpp"
#include "valvediag/model/effect_estimators.hpp"
#include "valvediag/sim/scenarios.hpp"

using namespace valvediag;
using Clock = std::chrono::steady_clock;

namespace {

std::vector<double> backlash(const std::vector<double>& u, double width) {
  std::vector<double> x(u.size());
  double pos = u.front();
  for (std::size_t t = 0; t < u.size(); ++t) {
    pos = std::clamp(pos, u[t] - width / 2, u[t] + width / 2);
    x[t] = pos;
  }
  return x;
}

}  // namespace

int main(int argc, char** argv) {
  const int reps = argc > 1 ? std::atoi(argv[1]) : 5;
  const LoopData d = run_scenario(scenario_by_name("paper-ex1"), 1, 3000);
  std::vector<std::vector<double>> xs;
  for (int k = 0; k < 40; ++k) xs.push_back(backlash(d.op, 0.2 * k));
  std::printf(
      "structure search: paper-ex1, N = %zu, 70 %% estimation, %zu valve positions; medians "
      "of %d runs\n",
      d.size(), xs.size(), reps);
  std::printf("%-32s %14s %14s %8s %6s\n", "grid", "plain ms/fit", "search ms/fit", "speed-up",
              "same");
  struct Grid {
    const char* name;
    StructureRange range;
    bool drift = false;
  };
  for (const Grid& g : {Grid{"na, nb 1..2, nk 0..10 (base)", {1, 2, 1, 2, 0, 10}},
                        Grid{"na, nb 1..2, nk 0..30 (delay)", {1, 2, 1, 2, 0, 30}},
                        Grid{"na, nb 1..4, nk 0..10 (order)", {1, 4, 1, 4, 0, 10}},
                        Grid{"base, with a load (disturbance)", {1, 2, 1, 2, 0, 10}, true}}) {
    LinearOptions opt;
    opt.range = g.range;
    opt.drift = g.drift;
    opt.end = d.size() * 7 / 10;
    const ArxEstimator est(d.pv, opt);
    LinearOptions plain_opt = opt;
    plain_opt.plain_scan = true;
    const ArxEstimator plain(d.pv, plain_opt);
    std::vector<double> plain_s, search_s;
    int same = 0;
    for (int rep = 0; rep < reps; ++rep) {
      std::vector<LinearFit> a, b;
      auto t0 = Clock::now();
      for (const auto& x : xs) a.push_back(plain.fit(x));
      auto t1 = Clock::now();
      for (const auto& x : xs) b.push_back(est.fit(x));
      auto t2 = Clock::now();
      plain_s.push_back(std::chrono::duration<double>(t1 - t0).count());
      search_s.push_back(std::chrono::duration<double>(t2 - t1).count());
      if (rep == 0)
        for (std::size_t i = 0; i < xs.size(); ++i)
          same += a[i].ok == b[i].ok && a[i].structure == b[i].structure &&
                  std::abs(a[i].sse - b[i].sse) <= 1e-6 * a[i].sse;
    }
    const double n = static_cast<double>(xs.size());
    const double p = bench::median(plain_s) / n * 1e3, s = bench::median(search_s) / n * 1e3;
    std::printf("%-32s %14.3f %14.3f %7.1fx %3d/%zu\n", g.name, p, s, p / s, same, xs.size());
  }
  return 0;
}
