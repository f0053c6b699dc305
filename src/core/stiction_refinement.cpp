// The refinement on the data (quantify_stiction with pv): He's valve fitted inside the Hammerstein
// structure to (op, pv) (stiction_data_fit.hpp), from the probe's figures and over a coarse
// lattice of every band; then the intervals (stiction_interval.hpp) and the regions' bands.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <mutex>
#include <unordered_map>
#include <vector>

#include "stiction_data_fit.hpp"
#include "stiction_interval.hpp"
#include "stiction_result.hpp"
#include "valvediag/core/autocorrelation.hpp"
#include "valvediag/core/parallel_for.hpp"
#include "valvediag/core/stiction_quantification.hpp"

namespace valvediag {

using detail::Band;
using detail::Candidate;
using detail::figures;
using detail::HeDataFit;
using detail::profile_interval;
using detail::refine_poles;
using detail::region_interval;
using detail::stiction_sentence;

StictionQuantification quantify_stiction(const HammersteinModel& model,
                                         const std::vector<double>& op,
                                         const std::vector<double>& pv,
                                         const StictionQuantificationOptions& opt) {
  StictionQuantification q = quantify_stiction(model, op, opt);
  q.preisach = q.overall;
  // A band below the probe's grid step is refined too: a lattice fitted by NNLS shortens bands, so
  // the probe can miss one a little over its step (a 2 % band at a step of 1.36 %).
  const bool resolved = q.stiction;
  if (!q.valid || !(q.scale > 0) || (!resolved && !opt.refine_unresolved) || !opt.refine_on_data ||
      pv.size() != op.size())
    return q;
  // The longest stretch where both are finite: the linear part needs consecutive samples.
  std::size_t best_from = 0, best_len = 0;
  for (std::size_t t = 0; t < op.size();) {
    std::size_t e = t;
    while (e < op.size() && std::isfinite(op[e]) && std::isfinite(pv[e])) ++e;
    if (e - t > best_len) {
      best_from = t;
      best_len = e - t;
    }
    t = e + 1;
  }
  const auto from = static_cast<std::ptrdiff_t>(best_from);
  const auto to = static_cast<std::ptrdiff_t>(best_from + best_len);
  const std::vector<double> u(op.begin() + from, op.begin() + to);
  const std::vector<double> y(pv.begin() + from, pv.begin() + to);
  HeDataFit fit(model, u, y, q.op_hi - q.op_lo, model.structure.nk + opt.refine_delay_range,
                opt.reuse_costs, opt.plain_sums);
  if (!fit.usable()) return q;

  const double delta = q.resolution_percent;
  const double width = q.op_hi - q.op_lo;
  const double fs0 = q.overall.fs_percent, fd0 = q.overall.fd_percent;
  // The linear part for a valve position x: delay (nk +- the range) and poles by output error.
  auto refine_linear = [&](HeDataFit& fit, const std::vector<double>& x) {
    const std::vector<double> a0 = fit.poles();
    const int nk0 = fit.delay();
    double best = std::numeric_limits<double>::infinity();
    std::vector<double> best_a = a0;
    int best_nk = nk0;
    for (int nk = std::max(0, nk0 - opt.refine_delay_range); nk <= nk0 + opt.refine_delay_range;
         ++nk) {
      fit.set_delay(nk);
      fit.set_poles(a0);
      const double c = refine_poles(fit, x);
      if (c < best) {
        best = c;
        best_a = fit.poles();
        best_nk = nk;
      }
    }
    fit.set_delay(best_nk);
    fit.set_poles(best_a);
    return best;
  };
  // The identified linear part came with the Preisach valve and from the equation error: re-fit
  // it by output error to the Preisach valve's own position first, so that the search for He's
  // figures starts from poles that do not depend on He's candidate.
  const bool arx = !fit.identity();
  if (arx) refine_linear(fit, simulate_valve(model, u));
  const std::vector<double> a_start = fit.poles();
  const int nk_start = fit.delay();

  // The cost is rugged: a candidate that moves one slip by a sample, or adds one to a sweep, costs
  // much more than the truth, so its valleys are a tenth of a % wide. A fine grid over a window of
  // a few Preisach grid steps around the Preisach figures, each point scored with a linear part of
  // its own (refine_own_linear), then the best few separate valleys are each polished (linear
  // part by output error, then a finer grid) and the best wins.
  // The step follows the band, at most 200 steps across the window (an unresolved probe's zero
  // band with a large grid step would otherwise make it 0.02 over several % of travel: 10^5
  // points). Above the step the window is 3 steps, so only unresolved bands meet the cap.
  const double W = opt.refine_window_steps * delta;
  const double h = std::max(std::clamp((fs0 + fd0) / 40, 0.02, 0.1), W / 200);
  using Point = Candidate;
  // The poles a candidate's valve position is scored with: the equation error's for that valve,
  // or the Preisach valve's. Scored with the Preisach valve's alone, the grid's ranking depends on
  // that part: on paper Example 1 with fit's default orders it put the true valley below one at
  // fd 1.0-1.5 (against 3.5) on seeds 1 and 11 of 16 and on the demo's record, and the polish
  // refined the wrong one.
  const bool own = opt.refine_own_linear && arx;
  auto poles_for = [&](const HeDataFit& fit, const std::vector<double>& x) {
    std::vector<double> a = own ? fit.ls_poles(x) : std::vector<double>{};
    return a.empty() ? a_start : a;
  };
  std::vector<Point> pts;
  for (double fs = std::max(0.0, fs0 - W); fs <= std::min(fs0 + W, width) + 1e-9; fs += h)
    for (double fd = 0.0; fd <= std::min(fs, fd0 + W) + 1e-9; fd += h) pts.push_back({0.0, fs, fd});
  const std::size_t local_points = pts.size();
  // And a coarse lattice over every band the visited range allows (0 <= fd <= fs <= width), about
  // `global_points` of them: the probe's figures are only as good as the Preisach model, which
  // measurement noise biases (fopdt, fs 5 fd 2, noise 1: the probe says fs 13.7, the window's
  // best 10.1, and the truth fits the data better than either).
  const double hg =
      opt.global_starts > 0 && opt.global_points > 0
          ? std::max(h, width / std::sqrt(2.0 * static_cast<double>(opt.global_points)))
          : 0.0;
  if (hg > 0)
    for (double fs = hg; fs <= width + 1e-9; fs += hg)
      for (double fd = 0.0; fd <= fs + 1e-9; fd += hg) pts.push_back({0.0, fs, fd});
  // The points on all cores, each worker with a fit of its own. Neighbouring points often slip
  // on the same samples (on long records, half of them): a position's cost, own poles included,
  // is computed once.
  const unsigned workers = worker_count(opt.threads, pts.size());
  std::vector<HeDataFit> fits(workers, fit);
  std::vector<std::vector<double>> xs(workers);  // positions: not allocated per point
  // The coarse lattice's bands are also scored with the Preisach valve's poles and with
  // Steiglitz-McBride's from those, the lowest cost kept: far from the probe the equation error's
  // poles can be far off (noise biases them; Steiglitz-McBride's filtering undoes most of that).
  const bool lattice_scoring = own && hg > 0;
  std::vector<HeDataFit> held(lattice_scoring ? workers : 0, fit);
  std::vector<HeDataFit> smf(held.size(), fit);
  // Steiglitz-McBride's poles for x, from the Preisach valve's (empty: none stable).
  auto sm_poles_for = [&](HeDataFit& g, const std::vector<double>& x) {
    g.set_poles(a_start);
    return g.sm_poles(x, opt.global_sm_passes);
  };
  // Each cost depends on the position alone, so it is remembered by the position's fingerprint:
  // `scored` the own poles' (the interval reuses it), `sm_scored` Steiglitz-McBride's.
  std::unordered_map<std::uint64_t, double> scored, sm_scored;
  std::mutex scored_mutex;
  auto remembered = [&](std::unordered_map<std::uint64_t, double>& costs, std::uint64_t key,
                        auto&& compute) {
    if (opt.reuse_costs) {
      const std::lock_guard<std::mutex> lock(scored_mutex);
      const auto seen = costs.find(key);
      if (seen != costs.end()) return seen->second;
    }
    const double c = compute();
    if (opt.reuse_costs) {
      const std::lock_guard<std::mutex> lock(scored_mutex);
      costs.emplace(key, c);
    }
    return c;
  };
  auto score = [&](unsigned w, Point& pt, bool lattice) {
    HeDataFit& f = fits[w];
    std::vector<double>& x = xs[w];
    const std::uint64_t key = f.valve(pt.fs, pt.fd, x);
    pt.cost = remembered(scored, key, [&] {
      if (own) f.set_poles(poles_for(f, x));
      return f.cost(x);
    });
    if (!lattice || !lattice_scoring) return;
    pt.cost = std::min(pt.cost, held[w].cost(key, x));
    if (opt.global_sm_passes > 0)  // and with Steiglitz-McBride's poles
      pt.cost = std::min(pt.cost, remembered(sm_scored, key, [&] {
                           HeDataFit& g = smf[w];
                           const std::vector<double> a = sm_poles_for(g, x);
                           if (a.empty()) return std::numeric_limits<double>::infinity();
                           g.set_poles(a);
                           return g.cost(x);
                         }));
  };
  parallel_for(pts.size(), workers,
               [&](unsigned w, std::size_t k) { score(w, pts[k], k >= local_points); });
  // The best cells of the coarse lattice again at a quarter of its step: a band that reproduces
  // the data's slips is a pit about 0.1 % wide, and a lattice point a step away from it often
  // costs three times as much, so it shows only in a cell's neighbourhood.
  if (hg > 0 && opt.global_cells > 0) {
    std::vector<Point> top(pts.begin() + static_cast<std::ptrdiff_t>(local_points), pts.end());
    const std::size_t cells = std::min(top.size(), opt.global_cells);
    std::partial_sort(top.begin(), top.begin() + static_cast<std::ptrdiff_t>(cells), top.end(),
                      [](const Point& l, const Point& r) { return l.cost < r.cost; });
    const std::size_t before = pts.size();
    for (std::size_t c = 0; c < cells; ++c)
      for (int i = -2; i <= 2; ++i)
        for (int j = -2; j <= 2; ++j) {
          const double fs = top[c].fs + i * hg / 4, fd = top[c].fd + j * hg / 4;
          if ((i != 0 || j != 0) && fd >= 0.0 && fd <= fs && fs <= width + 1e-9)
            pts.push_back({0.0, fs, fd});
        }
    parallel_for(pts.size() - before, workers,
                 [&](unsigned w, std::size_t k) { score(w, pts[before + k], true); });
  }
  // The window's best separate valleys, then the coarse lattice's best ones apart from those.
  auto by_cost = [](const Point& l, const Point& r) { return l.cost < r.cost; };
  const auto local_end = pts.begin() + static_cast<std::ptrdiff_t>(local_points);
  std::sort(pts.begin(), local_end, by_cost);
  std::sort(local_end, pts.end(), by_cost);
  std::vector<Point> starts;
  // A point joins the starts when it lies `apart` from the ones this call took and beyond the
  // polish's reach (4 h) of the earlier ones: a lattice point 2 lattice steps from the window's
  // start (1.07 % on paper Example 1 at noise 1) is a valley of its own, which the window's
  // polish cannot reach.
  const double reach = 4 * h;
  auto take = [&](auto from, auto to, std::size_t count, double apart) {
    const std::size_t earlier = starts.size(), limit = starts.size() + count;
    for (auto pt = from; pt != to && starts.size() < limit; ++pt) {
      bool separate = true;
      for (std::size_t i = 0; i < starts.size() && separate; ++i) {
        const Point& st = starts[i];
        const double d = std::max(std::abs(st.fs - pt->fs), std::abs(st.fd - pt->fd));
        separate = d > (i < earlier ? reach : apart);
      }
      if (separate) starts.push_back(*pt);
    }
  };
  take(pts.begin(), local_end, static_cast<std::size_t>(std::max(0, opt.refine_starts)), delta / 2);
  take(local_end, pts.end(), static_cast<std::size_t>(std::max(0, opt.global_starts)),
       std::max(delta / 2, 2 * hg));
  // A start's poles: of those its lattice point was scored with, the ones that fit best (the
  // polish that refines them finds a nearby minimum only: from the equation error's poles it lost
  // a valley that Steiglitz-McBride's had found on paper Example 1 at noise 1 and 2).
  auto start_poles = [&](HeDataFit& f, const std::vector<double>& x) {
    std::vector<double> best_a = poles_for(f, x);
    if (!lattice_scoring) return best_a;
    std::vector<std::vector<double>> others{a_start};
    if (opt.global_sm_passes > 0) others.push_back(sm_poles_for(f, x));
    f.set_poles(best_a);
    double best_c = f.cost(x);
    for (const auto& a : others) {
      if (a.empty()) continue;
      f.set_poles(a);
      const double c = f.cost(x);
      if (c < best_c) {
        best_c = c;
        best_a = a;
      }
    }
    return best_a;
  };
  // Each start polished by a worker with a fit of its own, from `nk` and `poles` (empty: the
  // start's own); the best in start order wins.
  struct Polished {
    std::vector<Point> points;
    std::vector<std::vector<double>> poles;  // each start's
    int delay;
  };
  auto polish = [&](const std::vector<Point>& from, int nk, const std::vector<double>& poles) {
    Polished out{from, std::vector<std::vector<double>>(from.size()), nk};
    const unsigned polishers = worker_count(opt.threads, from.size());
    std::vector<HeDataFit> pfits(polishers, fit);
    parallel_for(from.size(), polishers, [&](unsigned w, std::size_t i) {
      HeDataFit& f = pfits[w];
      Point& cur = out.points[i];
      f.set_delay(nk);
      out.poles[i] = poles.empty() ? start_poles(f, f.valve(cur.fs, cur.fd)) : poles;
      f.set_poles(out.poles[i]);
      for (int pass = 0; pass < (arx ? opt.refine_passes : 1); ++pass) {
        if (arx) refine_linear(f, f.valve(cur.fs, cur.fd));
        cur.cost = f.cost(cur.fs, cur.fd);
        const Point c0 = cur;
        const double hh = h / 4;
        std::vector<Band> grid;
        for (double fs = std::max(0.0, c0.fs - 4 * h); fs <= c0.fs + 4 * h + 1e-9; fs += hh)
          for (double fd = std::max(0.0, c0.fd - 4 * h); fd <= std::min(fs, c0.fd + 4 * h) + 1e-9;
               fd += hh)
            grid.push_back({fs, fd});
        // Scored a few at a time (HeDataFit::costs), then the first lowest in grid order kept.
        std::vector<double> costs(grid.size());
        for (std::size_t k = 0; k < grid.size(); k += HeDataFit::kLanes)
          f.costs(grid.data() + k, std::min(HeDataFit::kLanes, grid.size() - k), costs.data() + k);
        for (std::size_t k = 0; k < grid.size(); ++k)
          if (costs[k] < cur.cost) cur = {costs[k], grid[k].fs, grid[k].fd};
      }
    });
    return out;
  };
  Point best{std::numeric_limits<double>::infinity(), fs0, fd0};
  std::vector<double> best_poles = a_start;
  int best_delay = nk_start;
  std::vector<Point> polished;  // every polished valley
  auto keep_best = [&](const Polished& p) {
    for (std::size_t i = 0; i < p.points.size(); ++i) {
      polished.push_back(p.points[i]);
      if (p.points[i].cost < best.cost) {
        best = p.points[i];
        best_poles = p.poles[i];
        best_delay = p.delay;
      }
    }
  };
  // And a valve without stiction, always: whether it fits as well is the engineer's first
  // question, and the lattices only reach it when the best lies near it.
  if (std::none_of(starts.begin(), starts.end(),
                   [&](const Point& st) { return st.fs <= h && st.fd <= h; }))
    starts.push_back({0.0, 0.0, 0.0});
  keep_best(polish(starts, nk_start, {}));
  // The coarse lattice again, scored with the best's linear part: where the probe and the
  // equation error's poles were both off, the first round's best has poles near the truth's.
  for (int round = 1; round < opt.global_rounds && hg > 0; ++round) {
    HeDataFit winner = fit;
    winner.set_delay(best_delay);
    winner.set_poles(best_poles);
    if (arx) refine_linear(winner, winner.valve(best.fs, best.fd));
    std::vector<Point> lattice(local_end, pts.end());
    const unsigned n = worker_count(opt.threads, lattice.size());
    std::vector<HeDataFit> wfits(n, winner);
    // A few points per job (HeDataFit::costs).
    constexpr std::size_t kLanes = HeDataFit::kLanes;
    parallel_for((lattice.size() + kLanes - 1) / kLanes, n, [&](unsigned w, std::size_t j) {
      std::array<Band, kLanes> b;
      std::array<double, kLanes> c;
      const std::size_t from = j * kLanes, m = std::min(kLanes, lattice.size() - from);
      for (std::size_t l = 0; l < m; ++l) b[l] = {lattice[from + l].fs, lattice[from + l].fd};
      wfits[w].costs(b.data(), m, c.data());
      for (std::size_t l = 0; l < m; ++l) lattice[from + l].cost = c[l];
    });
    std::sort(lattice.begin(), lattice.end(), by_cost);
    starts = polished;
    const std::size_t before = starts.size();
    take(lattice.begin(), lattice.end(), static_cast<std::size_t>(std::max(0, opt.global_starts)),
         std::max(delta / 2, 2 * hg));
    if (starts.size() == before) break;
    const double was = best.cost;
    keep_best(polish(
        std::vector<Point>(starts.begin() + static_cast<std::ptrdiff_t>(before), starts.end()),
        winner.delay(), winner.poles()));
    if (!(best.cost < was)) break;
  }
  const double bfs = best.fs, bfd = best.fd, bcost = best.cost;
  // The linear part of the winner, from where its polish started (the loop above leaves the last
  // start's).
  fit.set_poles(best_poles);
  fit.set_delay(best_delay);
  if (arx) refine_linear(fit, fit.valve(bfs, bfd));
  if (opt.interval) {
    q.interval = profile_interval(fit, {std::min(bcost, fit.cost(bfs, bfd)), bfs, bfd},
                                  {own ? nk_start : -1, a_start, scored}, polished,
                                  {h, std::max(delta / 2, 2 * h), width}, opt);
  }

  // Per region: He's bands where the valve sticks in that region (PositionDependentStiction),
  // each region's band searched in turn around the overall figures, the others held, with the
  // overall linear part. A region the data did not visit keeps the Preisach probe's figures.
  const int R = static_cast<int>(q.regions.size());
  if (opt.refine_regions && R > 1) {
    fit.set_regions(q.op_lo, width);
    std::vector<Band> bands(static_cast<std::size_t>(R), Band{bfs, bfd});
    double cost = fit.cost(bands);
    for (int sweep = 0; sweep < 2; ++sweep) {
      for (int r = 0; r < R; ++r) {
        if (!q.regions[static_cast<std::size_t>(r)].valid) continue;
        Band& b = bands[static_cast<std::size_t>(r)];
        // This region's band over a grid, the others held: the points on all cores, the first
        // best in grid order kept.
        auto local = [&](Band centre, double half, double step) {
          std::vector<std::vector<Band>> sets;
          for (double fs = std::max(0.0, centre.fs - half); fs <= centre.fs + half + 1e-9;
               fs += step)
            for (double fd = std::max(0.0, centre.fd - half);
                 fd <= std::min(fs, centre.fd + half) + 1e-9; fd += step) {
              sets.push_back(bands);
              sets.back()[static_cast<std::size_t>(r)] = {fs, fd};
            }
          const unsigned n = worker_count(opt.threads, sets.size());
          std::vector<HeDataFit> fits(n, fit);
          std::vector<double> costs(sets.size());
          parallel_for(sets.size(), n,
                       [&](unsigned w, std::size_t i) { costs[i] = fits[w].cost(sets[i]); });
          for (std::size_t i = 0; i < sets.size(); ++i)
            if (costs[i] < cost) {
              cost = costs[i];
              b = sets[i][static_cast<std::size_t>(r)];
            }
        };
        if (sweep == 0) local({bfs, bfd}, W, 2 * h);
        local(b, 2 * h, h / 2);
      }
      if (arx) {  // the linear part for the valve with its regions
        refine_linear(fit, fit.valve(bands));
        cost = fit.cost(bands);
      }
    }
    // The regions' ranges' threshold: N_eff of the residual with every region's band.
    const double limit =
        opt.interval
            ? cost * std::exp(opt.interval_chi2 /
                              std::max(effective_sample_size(fit.residuals(fit.valve(bands))), 1.0))
            : 0.0;
    for (int r = 0; r < R; ++r) {
      auto& reg = q.regions[static_cast<std::size_t>(r)];
      if (!reg.valid) continue;
      const Band& b = bands[static_cast<std::size_t>(r)];
      reg.figures = figures(b.fs, b.fd, cost, fit.var_y());
      reg.stiction = reg.figures.band_percent > 0;
      if (opt.interval) {
        const auto [lo, hi] = region_interval(fit, bands, r, cost, limit, h, width, opt);
        reg.fs_lo = lo;
        reg.fs_hi = hi;
      }
    }
  }
  q.refined = true;
  q.overall = figures(bfs, bfd, bcost, fit.var_y());
  // Below the probe's step, stiction when the refined band clears that step after all (the
  // probe's criterion, on better figures) and the data reject fs = 0. Not on the interval alone:
  // on a long record it excludes 0 for any systematic misfit (a linear valve in paper Example 1
  // fits 0.07 % "better").
  if (!resolved)
    q.stiction = q.overall.band_percent > delta && q.interval.valid && q.interval.fs_lo > 0;
  q.summary = stiction_sentence(q);
  return q;
}

}  // namespace valvediag
