// Benchmark of the identification (not a test): full default grid at N = 1,500 and 25,000 on the
// paper's Example 1 loop, beside a straightforward baseline built from the same code: a dense
// N x K relay matrix per L and a cold NNLS on W'W for every solve. Each case runs in a child
// process so that its peak RSS is its own. Prints medians of repeated runs and the ratio.
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "bench_timing.hpp"
#include "valvediag/core/identification.hpp"
#include "valvediag/core/nnls.hpp"
#include "valvediag/sim/scenarios.hpp"

using namespace valvediag;
using Clock = std::chrono::steady_clock;

namespace {

// Baseline: one configuration with nb = 1 (both gain signs), dense matrices, cold NNLS, then
// the same BIC budget choice and simulated-output fitness.
double baseline_config(const Eigen::MatrixXd& G, const std::vector<double>& y, int na, int nk,
                       std::size_t t0) {
  const std::size_t N = y.size();
  const auto K = G.cols();
  const auto rows = static_cast<Eigen::Index>(N - t0);
  double best = -1e300;
  for (double sgn : {1.0, -1.0}) {
    Eigen::MatrixXd W(rows, na + 1 + K);
    Eigen::VectorXd Y(rows);
    for (std::size_t t = t0; t < N; ++t) {
      const auto r = static_cast<Eigen::Index>(t - t0);
      for (int i = 0; i < na; ++i) W(r, i) = -y[t - static_cast<std::size_t>(i + 1)];
      W(r, na) = 1.0;
      W.row(r).tail(K) =
          sgn * G.row(static_cast<Eigen::Index>(t - static_cast<std::size_t>(nk + 1)));
      Y[r] = y[t];
    }
    Eigen::MatrixXd H = W.transpose() * W;
    Eigen::VectorXd f = W.transpose() * Y;
    H.diagonal().array() += 1e-9 * H.diagonal().maxCoeff();  // constant relays are collinear with c
    NonnegativeQp qp(H, f, na + 1);
    auto r = qp.solve();
    const double total = r.x.tail(K).sum();
    auto path = qp.solve_budgets(
        r, {total, 0.99 * total, 0.98 * total, 0.97 * total, 0.96 * total, 0.95 * total});
    for (const auto& p : path) {
      Eigen::VectorXd x = G * p.x.tail(K) * sgn;
      std::vector<double> ys(N);
      double sse = 0, mean = 0, den = 0;
      for (std::size_t t = 0; t < N; ++t) mean += y[t];
      mean /= static_cast<double>(N);
      for (std::size_t t = 0; t < N; ++t) {
        if (t < t0) {
          ys[t] = y[t];
          continue;
        }
        double v = p.x[na];
        for (int i = 0; i < na; ++i) v -= p.x[i] * ys[t - static_cast<std::size_t>(i + 1)];
        v += x[static_cast<Eigen::Index>(t - static_cast<std::size_t>(nk + 1))];
        ys[t] = v;
        sse += (v - y[t]) * (v - y[t]);
        den += (y[t] - mean) * (y[t] - mean);
      }
      best = std::max(best, 100 * (1 - std::sqrt(sse / den)));
    }
  }
  return best;
}

struct Figures {
  double seconds = 0, configs = 0, fitness = 0;
  long rss_kb = 0;
};

// Runs one case in a child process; the child writes its figures into a pipe.
template <class F>
Figures in_child(F&& body) {
  std::fflush(stdout);  // the child must not inherit unflushed output
  int fd[2];
  if (pipe(fd) != 0) std::abort();
  const pid_t pid = fork();
  if (pid == 0) {
    close(fd[0]);
    Figures f = body();
    if (write(fd[1], &f, sizeof f) != static_cast<ssize_t>(sizeof f)) _exit(1);
    _exit(0);
  }
  close(fd[1]);
  Figures f;
  if (read(fd[0], &f, sizeof f) != static_cast<ssize_t>(sizeof f))
    std::fprintf(stderr, "child failed\n");
  close(fd[0]);
  int status = 0;
  struct rusage ru {};
  wait4(pid, &status, 0, &ru);
  f.rss_kb = ru.ru_maxrss;
  return f;
}

}  // namespace

int main(int argc, char** argv) {
  int repeats = 3;
  bool big = true;
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--repeats") && i + 1 < argc) repeats = std::atoi(argv[++i]);
    if (!std::strcmp(argv[i], "--quick")) big = false;
  }
  const Scenario sc = scenario_by_name("paper-ex1");
  std::printf(
      "valvediag identification benchmark: paper-ex1 loop, default grid (na<=3, nb<=3, nk<=10, "
      "L=2..20)\n");
  std::printf("machine: %ld cores; medians of %d runs; each case in its own process (peak RSS)\n\n",
              sysconf(_SC_NPROCESSORS_ONLN), repeats);
  std::printf("%-9s %-10s %8s %10s %12s %10s %9s\n", "N", "method", "configs", "wall s",
              "configs/s", "RSS MB", "fitness");
  std::vector<std::size_t> sizes{1500, 25000};
  for (std::size_t N : sizes) {
    const LoopData d = run_scenario(sc, 1, N);
    std::vector<double> secs;
    Figures fast;
    for (int r = 0; r < repeats; ++r) {
      fast = in_child([&] {
        const auto t0 = Clock::now();
        auto res = identify(d.op, d.pv, FitOptions{});
        Figures f;
        f.seconds = std::chrono::duration<double>(Clock::now() - t0).count();
        f.configs = static_cast<double>(res.configurations.size());
        f.fitness = res.fitness_percent;
        return f;
      });
      secs.push_back(fast.seconds);
    }
    const double fast_s = bench::median(secs);
    std::printf("%-9zu %-10s %8.0f %10.3f %12.0f %10.1f %8.2f%%\n", N, "valvediag", fast.configs,
                fast_s, fast.configs / fast_s, fast.rss_kb / 1024.0, fast.fitness);
    // Baseline on a subset of the grid (nb = 1, na 1..3, nk in {0, 5, 10}, every L): the full
    // grid would take hours at N = 25,000. nb = 1 is the cheapest kind, so the ratio is
    // conservative.
    Figures base = in_child([&] {
      const auto t0 = Clock::now();
      const std::size_t start = 13;
      double count = 0, best = -1e300;
      const auto [lo, hi] = std::minmax_element(d.op.begin(), d.op.end());
      for (int L = 2; L <= 20; ++L) {
        PreisachGrid g{*lo, *hi, L};
        PreisachState st(g);
        Eigen::MatrixXd G(static_cast<Eigen::Index>(N), g.relay_count());
        for (std::size_t t = 0; t < N; ++t) {
          st.move_to(g.level(d.op[t]));
          for (int k = 0; k < g.relay_count(); ++k)
            G(static_cast<Eigen::Index>(t), k) = st.relay(k);
        }
        for (int nk : {0, 5, 10})
          for (int na = 1; na <= 3; ++na) {
            best = std::max(best, baseline_config(G, d.pv, na, nk, start));
            ++count;
          }
      }
      Figures f;
      f.seconds = std::chrono::duration<double>(Clock::now() - t0).count();
      f.configs = count;
      f.fitness = best;
      return f;
    });
    std::printf("%-9zu %-10s %8.0f %10.3f %12.1f %10.1f %8.2f%%   (subset, nb = 1)\n", N,
                "baseline", base.configs, base.seconds, base.configs / base.seconds,
                base.rss_kb / 1024.0, base.fitness);
    std::printf("%-9s speed-up in configurations per second: %.0fx\n\n", "",
                (fast.configs / fast_s) / (base.configs / base.seconds));
  }
  if (big) {
    const std::size_t N = 1000000;
    const LoopData d = run_scenario(sc, 1, N);
    Figures f = in_child([&] {
      const auto t0 = Clock::now();
      auto res = identify(d.op, d.pv, FitOptions{});
      Figures r;
      r.seconds = std::chrono::duration<double>(Clock::now() - t0).count();
      r.configs = static_cast<double>(res.configurations.size());
      r.fitness = res.fitness_percent;
      return r;
    });
    std::printf(
        "%-9zu %-10s %8.0f %10.3f %12.0f %10.1f %8.2f%%   (one run; includes the data in memory)\n",
        N, "valvediag", f.configs, f.seconds, f.configs / f.seconds, f.rss_kb / 1024.0, f.fitness);
  }
  std::printf(
      "\npaper: about 0.15 s for one configuration at L = 20 (i5-2450); goals: 1,881 "
      "configurations\n"
      "in < 1 s at N = 1,500 and < 3 s at N = 25,000; peak RSS < 200 MB at N = 10^6.\n");
  return 0;
}
