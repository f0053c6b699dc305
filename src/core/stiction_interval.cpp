#include "stiction_interval.hpp"

#include <algorithm>
#include <cmath>
#include <map>

#include "valvediag/core/autocorrelation.hpp"
#include "valvediag/core/parallel_for.hpp"
#include "valvediag/core/profile_walk.hpp"

namespace valvediag::detail {

StictionInterval profile_interval(const HeDataFit& fit, Candidate best, const OwnPoles& own_poles,
                                  const std::vector<Candidate>& valleys, const Lattice& lattice,
                                  const StictionQuantificationOptions& opt) {
  const double bfs = best.fs, bfd = best.fd, h = lattice.step, half = lattice.half,
               width = lattice.width;
  StictionInterval iv;
  iv.chi2 = opt.interval_chi2;
  iv.step_percent = h;
  iv.effective_samples = effective_sample_size(fit.residuals(fit.valve(bfs, bfd)));
  iv.cost_ratio = std::exp(iv.chi2 / iv.effective_samples);
  const double eps = 1e-9;
  const int m = std::max(1, static_cast<int>(std::lround(half / h)));
  const int i_min = -static_cast<int>(std::floor((bfs + eps) / h));
  const int i_max = static_cast<int>(std::floor((width - bfs + eps) / h));
  const int j_min = -static_cast<int>(std::floor((bfd + eps) / h));
  auto fs_of = [&](int i) { return bfs + i * h; };
  auto fd_of = [&](int j) { return bfd + j * h; };
  auto valid = [&](int i, int j) {
    return i >= i_min && i <= i_max && j >= j_min && fd_of(j) <= fs_of(i) + eps;
  };
  std::map<std::pair<int, int>, double> cost;
  int ilo = std::max(-m, i_min), ihi = std::min(m, i_max), jlo = std::max(-m, j_min), jhi = m;
  for (;;) {
    std::vector<std::pair<int, int>> todo;
    for (int i = ilo; i <= ihi; ++i)
      for (int j = jlo; j <= jhi; ++j)
        if (valid(i, j) && !cost.contains({i, j})) todo.push_back({i, j});
    if (cost.size() + todo.size() > opt.interval_max_points && !cost.empty()) {
      iv.capped = true;
      break;
    }
    const unsigned workers = worker_count(opt.threads, todo.size());
    std::vector<HeDataFit> same(workers, fit);
    std::vector<HeDataFit> own(own_poles.delay >= 0 ? workers : 0, fit);
    for (HeDataFit& f : own) f.set_delay(own_poles.delay);
    std::vector<std::vector<double>> xs(workers);
    std::vector<double> c(todo.size());
    parallel_for(todo.size(), workers, [&](unsigned w, std::size_t k) {
      const double fs = fs_of(todo[k].first), fd = fd_of(todo[k].second);
      c[k] = same[w].cost(fs, fd);
      if (own.empty()) return;
      HeDataFit& f = own[w];
      const std::uint64_t key = f.valve(fs, fd, xs[w]);
      const auto known = opt.reuse_costs ? own_poles.known.find(key) : own_poles.known.end();
      if (known != own_poles.known.end()) {
        c[k] = std::min(c[k], known->second);
        return;
      }
      const std::vector<double> a = f.ls_poles(xs[w]);
      f.set_poles(a.empty() ? own_poles.fallback : a);
      c[k] = std::min(c[k], f.cost(xs[w]));
    });
    for (std::size_t k = 0; k < todo.size(); ++k) {
      cost[todo[k]] = c[k];
      best.cost = std::min(best.cost, c[k]);
    }
    const double limit = best.cost * iv.cost_ratio;
    auto inside_at = [&](bool row, int at) {
      for (const auto& [ij, v] : cost)
        if ((row ? ij.first : ij.second) == at && v <= limit) return true;
      return false;
    };
    bool grow = false;
    auto widen = [&](int& side, bool row, int step, int bound) {
      if (side == bound || !inside_at(row, side)) return;
      side = step < 0 ? std::max(side + step, bound) : std::min(side + step, bound);
      grow = true;
    };
    widen(ilo, true, -m, i_min);
    widen(ihi, true, m, i_max);
    widen(jlo, false, -m, j_min);
    // fd's side is bounded by fd <= fs at the box's largest fs.
    widen(jhi, false, m, static_cast<int>(std::floor((fs_of(ihi) - bfd + eps) / h)));
    if (!grow) break;
  }
  const double limit = best.cost * iv.cost_ratio;
  iv.fs_lo = iv.fs_hi = bfs;
  iv.fd_lo = iv.fd_hi = bfd;
  std::vector<Candidate> inside = valleys;
  for (const auto& [ij, v] : cost) inside.push_back({v, fs_of(ij.first), fd_of(ij.second)});
  for (const Candidate& c : inside) {
    if (c.cost > limit) continue;
    iv.fs_lo = std::min(iv.fs_lo, c.fs);
    iv.fs_hi = std::max(iv.fs_hi, c.fs);
    iv.fd_lo = std::min(iv.fd_lo, c.fd);
    iv.fd_hi = std::max(iv.fd_hi, c.fd);
  }
  // Between lattice points the cost is not known (on simulated loops its valleys are narrower
  // than a step): the ends are bracketed by the next points out.
  iv.fs_lo = std::max(0.0, iv.fs_lo - h);
  iv.fs_open_above = iv.fs_hi + h >= width - eps;
  iv.fs_hi = std::min(width, iv.fs_hi + h);
  iv.fd_lo = std::max(0.0, iv.fd_lo - h);
  iv.fd_hi = std::min(iv.fs_hi, iv.fd_hi + h);
  iv.points = cost.size();
  iv.valid = true;
  return iv;
}

std::pair<double, double> region_interval(const HeDataFit& fit, const std::vector<Band>& bands,
                                          int r, double best, double limit, double h, double width,
                                          const StictionQuantificationOptions& opt) {
  constexpr int kFd = 4;
  const Band b0 = bands[static_cast<std::size_t>(r)];
  const unsigned workers = worker_count(opt.threads, 2 * kFd + 1);
  std::vector<HeDataFit> fits(workers, fit);
  double fd = b0.fd;
  auto cost = [&](double fs, bool restart) {
    if (restart) fd = b0.fd;
    std::vector<std::vector<Band>> sets;
    for (int k = -kFd; k <= kFd; ++k) {
      const double d = std::clamp(fd + k * h, 0.0, fs);
      if (!sets.empty() && sets.back()[static_cast<std::size_t>(r)].fd == d) continue;
      sets.push_back(bands);
      sets.back()[static_cast<std::size_t>(r)] = {fs, d};
    }
    std::vector<double> costs(sets.size());
    parallel_for(sets.size(), workers,
                 [&](unsigned w, std::size_t i) { costs[i] = fits[w].cost(sets[i]); });
    const std::size_t k =
        static_cast<std::size_t>(std::min_element(costs.begin(), costs.end()) - costs.begin());
    fd = sets[k][static_cast<std::size_t>(r)].fd;
    return costs[k];
  };
  const ProfileRange range =
      walk_profile(b0.fs, best, {0.0, width, h}, cost, [limit](double c) { return c <= limit; });
  return {range.lo, range.hi};
}

}  // namespace valvediag::detail
