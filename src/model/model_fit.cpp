#include "valvediag/model/model_fit.hpp"

#include <nlopt.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <exception>
#include <mutex>
#include <optional>
#include <stdexcept>
#include <unordered_map>
#include <utility>

#include "valvediag/core/autocorrelation.hpp"
#include "valvediag/core/identification.hpp"
#include "valvediag/core/parallel_for.hpp"
#include "valvediag/core/profile_walk.hpp"

namespace valvediag {

namespace {

std::size_t estimation_end(std::size_t N, const ModelFitOptions& opt) {
  if (opt.validation_start > 0) return std::min(opt.validation_start, N);
  if (opt.validation_fraction > 0)
    return static_cast<std::size_t>(
        std::llround(static_cast<double>(N) * (1.0 - opt.validation_fraction)));
  return N;
}

void check_problem(const std::vector<double>& u, const std::vector<double>& y, double Ts,
                   const ModelFitOptions& opt) {
  if (u.size() != y.size()) throw std::invalid_argument("OP and PV differ in length");
  if (!(std::isfinite(Ts) && Ts > 0)) throw std::invalid_argument("sample period must be > 0");
  if (!(opt.validation_fraction >= 0 && opt.validation_fraction < 0.9))
    throw std::invalid_argument("validation fraction must lie in [0, 0.9)");
  if (opt.validation_start > 0 && opt.validation_start + 10 > u.size())
    throw std::invalid_argument("the validation part starts too close to the end of the data");
  if ((opt.delay_nk_max != 0 && opt.delay_nk_max < opt.structure.nk_max) || opt.order_max < 1 ||
      (opt.grid_points != 0 && opt.grid_points < 2) || opt.polish_starts < 1 ||
      opt.global_evaluations < 0 || opt.local_evaluations < 0 || !(opt.local_xtol > 0))
    throw std::invalid_argument("model fit options out of range");
  for (std::size_t t = 0; t < u.size(); ++t)
    if (!std::isfinite(u[t]) || !std::isfinite(y[t]))
      throw std::invalid_argument("non-finite sample at index " + std::to_string(t));
  if (u.empty()) throw std::invalid_argument("no samples");
  const auto [lo, hi] = std::minmax_element(u.begin(), u.end());
  if (!(*hi > *lo)) throw std::invalid_argument("the input is constant: nothing to identify");
}

// The outer problem: valve coordinates (scaled to the unit box) -> simulated-output SSE.
struct Search {
  Search(const std::vector<double>& u_, const ArxEstimator& est_, InputRange r)
      : u(u_), est(est_), range(r) {}
  const std::vector<double>& u;
  const ArxEstimator& est;
  std::vector<EffectSpec> effects;  // valve effects with coordinates, chain order
  std::vector<SearchParameter> coords;
  std::vector<std::size_t> offset;  // first coordinate of each effect
  InputRange range;
  double penalty = 0.0;  // cost of a point with no stable model
  std::atomic<int> evaluations{0};
  std::mutex mtx;
  double best_cost = std::numeric_limits<double>::infinity();
  std::vector<double> best_z;
  std::exception_ptr error;

  std::vector<double> theta(const double* z) const {
    std::vector<double> th(coords.size());
    for (std::size_t i = 0; i < coords.size(); ++i)
      th[i] = coords[i].lower + std::clamp(z[i], 0.0, 1.0) * (coords[i].upper - coords[i].lower);
    return th;
  }
  // The unit-box coordinate i of a parameter value (theta's inverse, clamped to the box).
  double coordinate(std::size_t i, double value) const {
    return std::clamp((value - coords[i].lower) / (coords[i].upper - coords[i].lower), 0.0, 1.0);
  }
  ValveChain chain(const double* z) const {
    const auto th = theta(z);
    std::vector<ValveEffect> blocks;
    for (std::size_t k = 0; k < effects.size(); ++k)
      blocks.push_back(make_valve_block(effects[k], th.data() + offset[k], range));
    return ValveChain(std::move(blocks));
  }
  std::vector<double> valve_position(const double* z) const {
    ValveChain c = chain(z);
    std::vector<double> x(u.size());
    c.reset(u[0]);
    c.steps(u.data(), x.data(), u.size());
    return x;
  }
  // The coordinates searched (indices into coords); the others stay at `base`. Empty: all.
  std::vector<std::size_t> active;
  std::vector<double> base;
  std::size_t dim() const { return active.empty() ? coords.size() : active.size(); }
  std::vector<double> full(const double* za) const {
    if (active.empty()) return std::vector<double>(za, za + coords.size());
    std::vector<double> z = base;
    for (std::size_t i = 0; i < active.size(); ++i) z[active[i]] = za[i];
    return z;
  }
  std::vector<double> restrict_to_active(const std::vector<double>& z) const {
    if (active.empty()) return z;
    std::vector<double> za(active.size());
    for (std::size_t i = 0; i < active.size(); ++i) za[i] = z[active[i]];
    return za;
  }
  // Coordinates that are not searched but profiled: each evaluation takes the best of their
  // few values (SearchParameter::profile_points), so the searched landscape is the lower
  // envelope over the discrete states and never worse than with the state fixed.
  std::vector<std::size_t> profiled;
  std::vector<std::size_t> searched() const {
    std::vector<std::size_t> v;
    for (std::size_t i = 0; i < coords.size(); ++i)
      if (coords[i].profile_points == 0) v.push_back(i);
    return v;
  }
  const std::atomic<bool>* cancel = nullptr;  // ModelFitOptions::cancel
  // ModelFitOptions::progress: the stage under way fills [stage_lo, stage_hi) of the search as
  // its evaluations reach its budget; the share reported only rises (in steps of a hundredth).
  const std::function<void(double, const std::string&)>* progress = nullptr;
  double span_lo = 0.0, span_hi = 1.0;  // the share of the search the caller gives a stage
  double stage_lo = 0.0, stage_hi = 0.0, reported = -1.0;
  int stage_first = 0, stage_budget = 1;
  std::string stage_name;
  void stage(double lo, double hi, int budget, std::string name) {
    if (!progress || !*progress) return;
    const std::lock_guard<std::mutex> lock(mtx);
    stage_lo = lo;
    stage_hi = hi;
    stage_first = evaluations.load();
    stage_budget = std::max(1, budget);
    stage_name = std::move(name);
  }
  // The linear part's error per valve position, remembered: the grid and the polishes revisit
  // positions (a stick-slip valve's moves only where a slip does; 38 % of the fits of a
  // 4,000-sample climb were repeats). The fit depends on the position alone.
  struct PositionKey {
    std::uint64_t h1, h2;  // two hashes of the position: a collision is vanishingly unlikely
    bool operator==(const PositionKey&) const = default;
  };
  struct PositionHash {
    std::size_t operator()(const PositionKey& k) const { return static_cast<std::size_t>(k.h1); }
  };
  std::unordered_map<PositionKey, double, PositionHash> fitted;  // sse, NaN: no stable fit
  static PositionKey key_of(const std::vector<double>& x) {
    // xxHash64's rounds, merge and finaliser, two seeds: four lanes each, so that the chains of
    // multiplies overlap.
    constexpr std::uint64_t p1 = 0x9E3779B185EBCA87u, p2 = 0xC2B2AE3D27D4EB4Fu,
                            p3 = 0x165667B19E3779F9u, p4 = 0x85EBCA77C2B2AE63u;
    const auto round = [](std::uint64_t acc, std::uint64_t v) {
      return std::rotl(acc + v * p2, 31) * p1;
    };
    const auto avalanche = [](std::uint64_t h) {
      h ^= h >> 33;
      h *= p2;
      h ^= h >> 29;
      h *= p3;
      return h ^ (h >> 32);
    };
    std::array<std::uint64_t, 4> a{p1 + p2, p2, 0, 0 - p1}, b{p3, p3 ^ p4, p4, p1 ^ p3};
    const std::size_t n = x.size(), n4 = n / 4 * 4;
    for (std::size_t i = 0; i < n4; i += 4)
      for (std::size_t l = 0; l < 4; ++l) {
        const auto v = std::bit_cast<std::uint64_t>(x[i + l]);
        a[l] = round(a[l], v);
        b[l] = round(b[l], v ^ p4);
      }
    for (std::size_t i = n4; i < n; ++i) {
      const auto v = std::bit_cast<std::uint64_t>(x[i]);
      a[0] = round(a[0], v);
      b[0] = round(b[0], v ^ p4);
    }
    const auto merge = [&](const std::array<std::uint64_t, 4>& v) {
      std::uint64_t h =
          std::rotl(v[0], 1) + std::rotl(v[1], 7) + std::rotl(v[2], 12) + std::rotl(v[3], 18);
      for (const std::uint64_t w : v) h = (h ^ round(0, w)) * p1 + p4;
      return avalanche(h + n);
    };
    return {merge(a), merge(b)};
  }
  double cost(const double* za) {
    throw_if_cancelled(cancel);  // nlopt_cost keeps it, run_nlopt rethrows it
    ++evaluations;
    std::vector<double> zc = full(za);
    const double c = profile_minimum(coords, profiled, zc, [this](const std::vector<double>& z) {
      const std::vector<double> x = valve_position(z.data());
      const PositionKey key = key_of(x);
      double sse;
      {
        const std::lock_guard<std::mutex> lock(mtx);
        const auto seen = fitted.find(key);
        sse = seen != fitted.end() ? seen->second : -1.0;
      }
      if (sse < 0) {  // not seen (an sse is >= 0 or NaN)
        const LinearFit f = est.fit(x);
        sse = f.ok ? f.sse : std::numeric_limits<double>::quiet_NaN();
        const std::lock_guard<std::mutex> lock(mtx);
        fitted.emplace(key, sse);
      }
      return std::isnan(sse) ? penalty : sse;
    });
    std::lock_guard<std::mutex> lock(mtx);
    if (c < best_cost) {
      best_cost = c;
      best_z = zc;
    }
    if (progress && *progress) {
      const double done =
          std::min(1.0, static_cast<double>(evaluations.load() - stage_first) / stage_budget);
      const double share = stage_lo + (stage_hi - stage_lo) * done;
      if (share >= reported + 0.01) {
        reported = share;
        (*progress)(share, stage_name);
      }
    }
    return c;
  }
};

double nlopt_cost(unsigned n, const double* z, double* grad, void* data) {
  (void)n;
  (void)grad;  // derivative-free algorithms only
  auto* s = static_cast<Search*>(data);
  try {
    return s->cost(z);
  } catch (...) {
    std::lock_guard<std::mutex> lock(s->mtx);
    if (!s->error) s->error = std::current_exception();
    return s->penalty;
  }
}

struct NloptRun {
  nlopt_result result;
};

NloptRun run_nlopt(nlopt_algorithm alg, Search& s, std::vector<double>& z, int maxeval, double xtol,
                   double* fmin = nullptr, double initial_step = 0.05) {
  const unsigned n = static_cast<unsigned>(z.size());
  nlopt_opt o = nlopt_create(alg, n);
  if (!o) throw std::runtime_error("NLopt could not create an optimizer");
  const std::vector<double> lb(n, 0.0), ub(n, 1.0), step(n, initial_step);
  nlopt_set_lower_bounds(o, lb.data());
  nlopt_set_upper_bounds(o, ub.data());
  nlopt_set_min_objective(o, nlopt_cost, &s);
  nlopt_set_maxeval(o, maxeval);
  if (xtol > 0) nlopt_set_xtol_abs1(o, xtol);
  if (alg == NLOPT_LN_NELDERMEAD) nlopt_set_initial_step(o, step.data());
  double f = 0.0;
  const nlopt_result r = nlopt_optimize(o, z.data(), &f);
  nlopt_destroy(o);
  if (fmin) *fmin = f;
  if (s.error) std::rethrow_exception(s.error);
  return {r};
}

// Grid over the unit box evaluated on all cores; returns every point's cost (index order).
std::vector<double> grid_search(Search& s, int points, int threads) {
  const std::size_t n = s.dim();
  std::size_t total = 1;
  for (std::size_t i = 0; i < n; ++i) total *= static_cast<std::size_t>(points);
  std::vector<double> costs(total);
  const unsigned workers = worker_count(threads, total);
  std::vector<std::vector<double>> zs(workers, std::vector<double>(n));
  parallel_for(total, workers, [&](unsigned w, std::size_t k) {
    std::vector<double>& z = zs[w];
    std::size_t r = k;
    for (std::size_t i = 0; i < n; ++i) {
      z[i] = static_cast<double>(r % static_cast<std::size_t>(points)) / (points - 1);
      r /= static_cast<std::size_t>(points);
    }
    costs[k] = nlopt_cost(static_cast<unsigned>(n), z.data(), nullptr, &s);
  });
  if (s.error) std::rethrow_exception(s.error);
  return costs;
}

// The best grid points that are not neighbours of a better one: starts for the local polish
// (stick-slip costs are rugged, a single start often polishes a side ridge).
std::vector<std::vector<double>> grid_starts(const std::vector<double>& costs, std::size_t n,
                                             int points, int count) {
  std::vector<std::size_t> order(costs.size());
  for (std::size_t k = 0; k < order.size(); ++k) order[k] = k;
  std::sort(order.begin(), order.end(), [&](auto a, auto b) { return costs[a] < costs[b]; });
  auto coords = [&](std::size_t k) {
    std::vector<int> c(n);
    for (std::size_t i = 0; i < n; ++i) {
      c[i] = static_cast<int>(k % static_cast<std::size_t>(points));
      k /= static_cast<std::size_t>(points);
    }
    return c;
  };
  std::vector<std::vector<int>> picked;
  for (std::size_t k : order) {
    if (static_cast<int>(picked.size()) >= count) break;
    const auto c = coords(k);
    bool near = false;
    for (const auto& p : picked) {
      int dist = 0;
      for (std::size_t i = 0; i < n; ++i) dist = std::max(dist, std::abs(p[i] - c[i]));
      near = near || dist <= 1;
    }
    if (!near) picked.push_back(c);
  }
  std::vector<std::vector<double>> starts;
  for (const auto& c : picked) {
    std::vector<double> z(n);
    for (std::size_t i = 0; i < n; ++i) z[i] = static_cast<double>(c[i]) / (points - 1);
    starts.push_back(z);
  }
  return starts;
}

// Global stage plus local polishes over the active coordinates; returns the winning polish's
// NLopt result (s.best_z holds the best point seen).
nlopt_result search_space(Search& s, const ModelFitOptions& opt,
                          const std::vector<double>* start = nullptr) {
  const int dim = static_cast<int>(s.dim());
  const int n_global = opt.global_evaluations > 0 ? opt.global_evaluations : 100 * dim;
  const int n_local = opt.local_evaluations > 0 ? opt.local_evaluations : 60 * dim;
  int points = opt.grid_points;
  if (points == 0) points = dim == 1 ? 41 : dim == 2 ? 21 : dim == 3 ? 9 : 6;
  std::vector<std::vector<double>> starts;
  double step = 0.05;
  const double lo = s.span_lo, hi = s.span_hi, mid = lo + 0.5 * (hi - lo);
  if (opt.global == GlobalSearch::Grid && std::pow(points, dim) <= 5000) {
    const int total = static_cast<int>(std::pow(points, dim));
    s.stage(lo, mid, total, "valve parameters: a grid of " + std::to_string(total) + " points");
    const auto costs = grid_search(s, points, opt.threads);
    starts = grid_starts(costs, s.dim(), points, std::max(1, opt.polish_starts));
    step = 0.5 / (points - 1);
  } else {
    s.stage(lo, mid, n_global, "valve parameters: a global search (DIRECT-L)");
    std::vector<double> z(s.dim(), 0.5);
    run_nlopt(NLOPT_GN_DIRECT_L, s, z, n_global, 0.0);
    starts.push_back(s.restrict_to_active(s.best_z));
  }
  if (start) starts.push_back(s.restrict_to_active(*start));
  // Independent polishes, one per start, on the cores.
  s.stage(mid, hi, n_local * static_cast<int>(starts.size()),
          "valve parameters: polishing from " + std::to_string(starts.size()) + " starts");
  std::vector<nlopt_result> results(starts.size(), NLOPT_SUCCESS);
  std::vector<double> ends(starts.size(), std::numeric_limits<double>::infinity());
  parallel_for(
      starts.size(), worker_count(opt.threads, starts.size()), [&](unsigned, std::size_t k) {
        std::vector<double> zk = starts[k];
        results[k] =
            run_nlopt(NLOPT_LN_NELDERMEAD, s, zk, n_local, opt.local_xtol, &ends[k], step).result;
      });
  const std::size_t winner =
      static_cast<std::size_t>(std::min_element(ends.begin(), ends.end()) - ends.begin());
  return results[winner];
}

// Coordinates at which every effect is absent (x = u): zero bands, limits at the OP range,
// zero curvature, zero lag.
std::vector<double> neutral_point(const Search& s) {
  std::vector<double> z(s.coords.size(), 0.0);
  for (std::size_t k = 0; k < s.effects.size(); ++k) {
    const auto& e = s.effects[k];
    if (e.name == "saturation") z[s.offset[k] + 1] = 1.0;
    if (e.name == "characteristic" && e.variant == "auto") z[s.offset[k]] = 0.5;
    if (e.name == "preisach") {  // one level everywhere: no mild side; the window's middle,
      z[s.offset[k] + 1] = 0.5;  // over a tenth of it
      z[s.offset[k] + 3] = 0.5;
      z[s.offset[k] + 5] = s.coordinate(s.offset[k] + 5, 0.1);
      z[s.offset[k] + 6] = 0.5;  // one fd/fs on both sides
    }
  }
  return z;
}

// A travel limit must earn its place on the estimation data, as a bigger ARX structure must
// (LinearOptions::parsimony_percent). One that the valve never reaches there, or barely, leaves
// the estimation fit flat, so the search stops anywhere between the data's reach and the edge of
// the OP range, and the held-out part, when it goes further, is clipped there by chance
// (measured: one simulated saturation loop got a lower limit of 48.5 or 45.5 % from rounding
// alone, and 36 or 83 % held-out fitness; the true limit was 5 %). A limit whose removal costs
// less than that many points of estimation fitness goes where neutral_point() puts it, the edge
// of the record's OP range: no clip the estimation data does not show.
// Nor one that only clips the OP's wander while the controller rejects a slow load: the linear
// model makes PV follow that wander, which the load cancelled, and a clip at the middle of it
// removes half of that error (measured: lower limits at 50 % on three simulated saturation loops
// whose OP went to 48.5 % only while regulating at 50 %, against a true 5 %; 14-17 % held-out
// fitness). The load's error is one slow curve, so the limit must also pass a likelihood-ratio
// test at 1 % on the effective number of independent residual samples: there it gained a
// statistic of 2.4-4.9, while each true limit gained over 100.
// The effective sample size of a fit's simulated residual over the estimation part: a
// likelihood-ratio test on it does not take a slow load's wander for many proofs. 0 without a fit.
double residual_samples(const Search& s, const std::vector<double>& y, const std::vector<double>& x,
                        const LinearFit& f) {
  if (!f.ok) return 0.0;
  return effective_sample_size(y, s.est.simulate(f, x), s.est.start(), s.est.end());
}

void widen_unsupported_limits(const Search& s, const std::vector<double>& y,
                              std::vector<double>& z) {
  constexpr double kChiSquare1Dof99 = 6.635;  // 99 % quantile of chi-square with 1 dof
  const double window = s.est.options().parsimony_percent;
  const std::vector<double> absent = neutral_point(s);
  const auto fitness = [](const LinearFit& f) {
    return f.ok ? f.fitness_percent : -std::numeric_limits<double>::infinity();
  };
  for (std::size_t k = 0; k < s.effects.size(); ++k) {
    if (s.effects[k].name != "saturation") continue;
    const std::size_t lo = s.offset[k], share = lo + 1;  // lower, upper's share of [lower, umax]
    const std::vector<double> x = s.valve_position(z.data());
    const LinearFit kept = s.est.fit(x);
    const double samples = residual_samples(s, y, x, kept);
    const auto unsupported = [&](const std::vector<double>& at) {
      const LinearFit f = s.est.fit(s.valve_position(at.data()));
      if (fitness(f) >= fitness(kept) - window) return true;
      return kept.ok && f.ok && kept.sse > 0 &&
             samples * std::log(f.sse / kept.sse) < kChiSquare1Dof99;
    };
    // The lower limit removed with the upper one where it is (its share of the wider span), then
    // the upper one removed.
    std::vector<double> wide = z;
    const std::vector<double> th = s.theta(z.data());
    const double upper =
        std::get<Saturation>(make_valve_block(s.effects[k], th.data() + lo, s.range)).upper();
    const double r = s.range.umax - s.range.umin;
    wide[lo] = absent[lo];
    wide[share] = s.coordinate(share, r > 0 ? (upper - s.range.umin) / r : 1.0);
    if (unsupported(wide)) z = wide;
    wide = z;
    wide[share] = absent[share];
    if (unsupported(wide)) z = wide;
  }
}

std::vector<double> difference(const std::vector<double>& y) {
  std::vector<double> w(y.size(), 0.0);
  for (std::size_t t = 1; t < y.size(); ++t) w[t] = y[t] - y[t - 1];
  return w;
}

// Reported parameters of the process effects, from the fitted linear part.
void describe_process_effects(ModelFit& fit, const ArxEstimator* est, double Ts) {
  for (auto& fe : fit.effects) {
    if (fe.name == "delay") {
      fe.parameters = {{"nk", static_cast<double>(fit.structure.nk), "samples"},
                       {"dead_time", fit.structure.nk * Ts, "s"}};
    } else if (fe.name == "order") {
      double lag = 0.0;
      for (const auto& p : fe.parameters)
        if (p.name == "tau") lag = p.value;
      fe.parameters = {{"na", static_cast<double>(fit.structure.na), ""},
                       {"nb", static_cast<double>(fit.structure.nb), ""}};
      if (!fit.valve.empty()) fe.parameters.push_back({"extra_lag", lag, "s"});
    } else if (fe.name == "integrator" || fe.name == "disturbance") {
      double a1 = 1.0, bsum = 0.0;
      for (double v : fit.a) a1 += v;
      for (double v : fit.b) bsum += v;
      if (fe.name == "integrator") {
        fe.parameters = {{"rate_gain", bsum / a1 / Ts, "PV/s per OP"}};
      } else if (!fit.disturbance.empty()) {
        const auto [lo, hi] = std::minmax_element(
            fit.disturbance.begin() + static_cast<std::ptrdiff_t>(fit.first_sample),
            fit.disturbance.end());
        // The load as its steady-state effect on PV (d / A(1)), or as a PV rate when integrating.
        fe.parameters = {
            {"knot_spacing", est ? static_cast<double>(est->knot_spacing()) * Ts : 0.0, "s"},
            {"load_range", (*hi - *lo) / a1 / (fit.integrating ? Ts : 1.0),
             fit.integrating ? "PV/s" : "PV"}};
      }
    }
  }
}

// The held-out part of a model with `disturbance`: an unmeasured load is not known ahead, but a
// slow one can be predicted from the recent past. Over each knot interval of the held-out part the
// load is the mean equation error (A and B fixed) of the interval before it, the first from the
// last interval of the estimation part: a prediction h samples ahead from measured PV only. The
// output is simulated through the fixed dynamics. A real slow load is followed one interval late;
// a "load" that only stands in for fast events the dynamics miss (a valve slip, the response to a
// set-point step) cannot be predicted and earns nothing. (Fitting the load to the held-out samples
// themselves would score the load's flexibility, not the model.)
void predict_load_on_validation(ModelFit& fit, const std::vector<double>& y, std::size_t h) {
  const std::size_t N = y.size(), e0 = fit.estimation_end;
  if (fit.disturbance.size() != N || e0 >= N || h == 0 || fit.y_sim.size() != N) return;
  const std::size_t na = fit.a.size(), nb = fit.b.size();
  const std::size_t nk = static_cast<std::size_t>(fit.structure.nk);
  const std::size_t lag = std::max(na, nk + nb);
  if (e0 < lag + 1) return;
  std::vector<double> v(y), vs(fit.y_sim);  // target and simulated (differenced if integrating)
  if (fit.integrating) {
    for (std::size_t t = N - 1; t >= 1; --t) {
      v[t] = y[t] - y[t - 1];
      vs[t] = fit.y_sim[t] - fit.y_sim[t - 1];
    }
    v[0] = vs[0] = 0.0;
  }
  // Equation error of the measured data: the load plus noise.
  auto equation_error = [&](std::size_t t) {
    double r = v[t];
    for (std::size_t i = 1; i <= na; ++i) r += fit.a[i - 1] * v[t - i];
    for (std::size_t j = 1; j <= nb; ++j) r -= fit.b[j - 1] * fit.x_hat[t - nk - j];
    return r;
  };
  auto mean_error = [&](std::size_t from, std::size_t to) {
    double sum = 0;
    for (std::size_t t = from; t < to; ++t) sum += equation_error(t);
    return sum / static_cast<double>(to - from);
  };
  const std::size_t first = std::max(lag, e0 > h ? e0 - h : 0);
  double load = mean_error(first, e0);
  for (std::size_t from = e0; from < N; from += h) {
    const std::size_t to = std::min(N, from + h);
    for (std::size_t t = from; t < to; ++t) {
      double sv = load;
      for (std::size_t i = 1; i <= na; ++i) sv -= fit.a[i - 1] * vs[t - i];
      for (std::size_t j = 1; j <= nb; ++j) sv += fit.b[j - 1] * fit.x_hat[t - nk - j];
      vs[t] = sv;
      fit.disturbance[t] = load;
      fit.y_sim[t] = fit.integrating ? fit.y_sim[t - 1] + sv : sv;
    }
    load = mean_error(from, to);
  }
}

// The separable problem fit_model searches for a spec: the linear estimator and the valve's
// search coordinates. With `order` the extra lag is searched over the base na, nb range (the lag
// stands for the extra orders there, at a quarter of the cost); the final fit uses the whole
// range.
// A second search over the same valve coordinates with another linear range.
void copy_coordinates(Search& to, const Search& from) {
  to.effects = from.effects;
  to.coords = from.coords;
  to.offset = from.offset;
  to.penalty = from.penalty;
  to.profiled = from.profiled;
  to.cancel = from.cancel;
}

struct Problem {
  Problem(const std::vector<double>& u, const std::vector<double>& y, double Ts,
          const ModelSpec& spec, const ModelFitOptions& opt)
      : lo(linear_options(spec, opt, u.size())),
        est(y, lo),
        narrow_lo(narrow_options(spec, opt, lo)),
        narrow(narrow_lo ? std::optional<ArxEstimator>(std::in_place, y, *narrow_lo)
                         : std::nullopt),
        s(u, narrow ? *narrow : est, input_range(u, Ts)) {
    for (const auto& e : spec.effects) {
      const auto c = search_parameters(e, s.range);
      if (c.empty()) continue;
      s.effects.push_back(e);
      s.offset.push_back(s.coords.size());
      s.coords.insert(s.coords.end(), c.begin(), c.end());
    }
    double mean = 0.0, den = 0.0;
    for (std::size_t t = est.start(); t < est.end(); ++t) mean += y[t];
    mean /= static_cast<double>(est.end() - est.start());
    for (std::size_t t = est.start(); t < est.end(); ++t) den += (y[t] - mean) * (y[t] - mean);
    s.penalty = 10.0 * den + 1.0;  // fitness about -216 %: worse than any stable fit
    for (std::size_t i = 0; i < s.coords.size(); ++i)
      if (s.coords[i].profile_points > 0) s.profiled.push_back(i);
    s.cancel = opt.cancel;
  }
  // The valve search scores every candidate with the best linear part over a structure range.
  // `order` and `delay` widen that range; the search scores over the base grid's orders and
  // dead times (fit_model then searches again around a dead time the base grid does not hold).
  static std::optional<LinearOptions> narrow_options(const ModelSpec& spec,
                                                     const ModelFitOptions& opt,
                                                     const LinearOptions& lo) {
    LinearOptions ln = lo;
    ln.range.na_max = std::min(lo.range.na_max, std::max(opt.structure.na_max, ln.range.na_min));
    ln.range.nb_max = std::min(lo.range.nb_max, std::max(opt.structure.nb_max, ln.range.nb_min));
    if (spec.has("delay"))
      ln.range.nk_max = std::min(lo.range.nk_max, std::max(opt.structure.nk_max, lo.range.nk_min));
    if (ln.range.na_max == lo.range.na_max && ln.range.nb_max == lo.range.nb_max &&
        ln.range.nk_max == lo.range.nk_max)
      return std::nullopt;
    return ln;
  }
  // The search scored fewer dead times than the whole range holds: a second search may help.
  bool delay_window() const { return narrow_lo && narrow_lo->range.nk_max < lo.range.nk_max; }
  // With delay_window(): the same valve coordinates, scored over the dead times within the base
  // grid's nk span of nk.
  Search& around_delay(const std::vector<double>& u, const std::vector<double>& y, int nk,
                       const ModelFitOptions& opt) {
    const int span = std::max(1, opt.structure.nk_max - opt.structure.nk_min);
    LinearOptions lw = *narrow_lo;
    lw.range.nk_min = std::clamp(nk - span, lo.range.nk_min, lo.range.nk_max);
    lw.range.nk_max = std::clamp(nk + span, lw.range.nk_min, lo.range.nk_max);
    again.reset();
    around.emplace(y, lw);
    again.emplace(u, *around, s.range);
    copy_coordinates(*again, s);
    return *again;
  }
  LinearOptions lo;
  ArxEstimator est;
  std::optional<LinearOptions> narrow_lo;
  std::optional<ArxEstimator> narrow;
  Search s;
  std::optional<ArxEstimator> around;
  std::optional<Search> again;
};

// The core's identify() searches dead times up to 200 samples.
constexpr int kPreisachNkMax = 200;

ModelFit fit_preisach(const std::vector<double>& u, const std::vector<double>& y, double Ts,
                      const ModelSpec& spec, const ModelFitOptions& opt, ModelFit fit) {
  const LinearOptions lo = linear_options(spec, opt, u.size());
  FitOptions fo;
  fo.na_min = lo.range.na_min;
  fo.na_max = lo.range.na_max;
  fo.nb_min = lo.range.nb_min;
  fo.nb_max = lo.range.nb_max;
  fo.nk_min = lo.range.nk_min;
  fo.nk_max = std::min(lo.range.nk_max, kPreisachNkMax);
  fo.L_min = opt.preisach_L_min;
  fo.cancel = opt.cancel;
  fo.L_max = opt.preisach_L_max;
  fo.validation_fraction = opt.validation_fraction;
  fo.validation_start = opt.validation_start;
  fo.first_sample = opt.first_sample;
  fo.threads = opt.threads;
  fo.keep_all_configurations = true;
  if (opt.progress)
    fo.progress = [&opt](double share) {
      opt.progress(share, "Preisach weights: the relay configurations of each L, nk and na");
    };
  const std::vector<double> target = lo.integrating ? difference(y) : y;
  const IdentificationResult res = identify(u, target, fo);
  fit.evaluations = static_cast<int>(res.configurations.size());
  fit.first_sample = res.first_sample;
  fit.estimation_end = res.estimation_end;
  if (res.status == IdentificationStatus::NoStableModel) {
    fit.status = ModelFitStatus::NoStableModel;
    fit.stop_reason = "no stable Preisach-ARX configuration";
    return fit;
  }
  const HammersteinModel& m = res.model;
  fit.preisach = m;
  fit.x_hat = simulate_valve(m, u);
  fit.structure = {m.structure.na, m.structure.nb, m.structure.nk};
  switch (res.best.status) {
    case SolverStatus::Converged:
      fit.status = ModelFitStatus::Converged;
      break;
    case SolverStatus::IterationLimit:
      fit.status = ModelFitStatus::EvaluationLimit;
      break;
    case SolverStatus::NumericalTrouble:
      fit.status = ModelFitStatus::NumericalTrouble;
      break;
  }
  fit.stop_reason = "preisach: " + res.best.stop_reason;
  int nonzero = 0;
  for (double v : m.mu) nonzero += v > 0;
  for (auto& fe : fit.effects) {
    if (fe.name != "preisach") continue;
    fe.variant = "general";
    fe.parameters = {{"L", static_cast<double>(m.grid.L), "levels"},
                     {"nonzero_weights", static_cast<double>(nonzero), ""},
                     {"umin", m.grid.umin, "OP"},
                     {"umax", m.grid.umax, "OP"}};
  }
  std::optional<ArxEstimator> est;
  if (lo.drift) {
    // The load term is not in the core's problem: refit the linear part with the drift for the
    // identified valve position (one separable step, weights kept).
    LinearOptions l2 = lo;
    l2.start = res.first_sample;
    l2.end = res.estimation_end;
    est.emplace(y, l2);
    const LinearFit f = est->fit(fit.x_hat, true);
    if (!f.ok) {
      fit.status = ModelFitStatus::NoStableModel;
      fit.stop_reason = "no stable linear part with the disturbance term";
      return fit;
    }
    fit.structure = f.structure;
    fit.a = f.a;
    fit.b = f.b;
    fit.c = f.c;
    fit.disturbance = est->drift_series(f);
    fit.y_sim = est->simulate(f, fit.x_hat);
    fit.first_sample = est->start();
    predict_load_on_validation(fit, y, est->knot_spacing());
  } else {
    fit.a = m.a;
    fit.b = m.b;
    fit.c = m.c;
    fit.y_sim = simulate_arx(m, fit.x_hat, target, res.first_sample);
    if (lo.integrating) {
      for (std::size_t t = 0; t < res.first_sample; ++t) fit.y_sim[t] = y[t];
      for (std::size_t t = res.first_sample; t < y.size(); ++t)
        fit.y_sim[t] = fit.y_sim[t - 1] + fit.y_sim[t];
    }
  }
  fit.fitness_percent = fitness_percent(y, fit.y_sim, fit.first_sample, fit.estimation_end);
  if (fit.estimation_end < y.size())
    fit.validation_fitness_percent = fitness_percent(y, fit.y_sim, fit.estimation_end, y.size());
  describe_process_effects(fit, est ? &*est : nullptr, Ts);
  return fit;
}

}  // namespace

const char* to_string(ModelFitStatus s) {
  switch (s) {
    case ModelFitStatus::Converged:
      return "converged";
    case ModelFitStatus::EvaluationLimit:
      return "evaluation limit";
    case ModelFitStatus::NumericalTrouble:
      return "numerical trouble";
    case ModelFitStatus::NoStableModel:
      return "no stable model";
  }
  return "?";
}

double held_valve_validation_fitness(const ModelFit& fit, const std::vector<double>& y) {
  const std::size_t N = y.size(), e0 = fit.estimation_end;
  if (fit.status == ModelFitStatus::NoStableModel || fit.b.empty() || e0 == 0 || e0 >= N ||
      fit.x_hat.size() != N || fit.y_sim.size() != N)
    return std::numeric_limits<double>::quiet_NaN();
  // The model is linear from x_hat to PV: holding the valve adds the response to the change of
  // x_hat, which is zero before the held-out part.
  const std::size_t na = fit.a.size(), nb = fit.b.size();
  const std::size_t nk = static_cast<std::size_t>(std::max(0, fit.structure.nk));
  std::vector<double> dv(N, 0.0), ys(fit.y_sim);
  auto dx = [&](std::size_t t) { return t >= e0 ? fit.x_hat[e0 - 1] - fit.x_hat[t] : 0.0; };
  double dy = 0.0;
  for (std::size_t t = e0; t < N; ++t) {
    double s = 0.0;
    for (std::size_t i = 1; i <= na && i <= t; ++i) s -= fit.a[i - 1] * dv[t - i];
    for (std::size_t k = 1; k <= nb; ++k)
      if (t >= nk + k) s += fit.b[k - 1] * dx(t - nk - k);
    dv[t] = s;
    dy = fit.integrating ? dy + s : s;
    ys[t] += dy;
  }
  return fitness_percent(y, ys, e0, N);
}

double effect_parameter_count(const std::string& effect, const ModelFit& fit, double Ts) {
  std::vector<NamedValue> p;
  for (const auto& e : fit.effects)
    if (e.name == effect) p = e.parameters;
  auto param = [&p](const char* name, double fallback) {
    for (const auto& v : p)
      if (v.name == name) return v.value;
    return fallback;
  };
  // The general weights count each; position-dependent friction has fs, the mild side, the two
  // sides' fd/fs, the position and the transition's width.
  if (effect == "preisach") return std::max(1.0, param("nonzero_weights", 6.0));
  if (effect == "disturbance") {
    const double h = param("knot_spacing", 0.0) / Ts;
    return h > 0 ? static_cast<double>(fit.estimation_end - fit.first_sample) / h + 1.0 : 10.0;
  }
  if (effect == "integrator") return 0.0;
  if (effect == "order") return std::max(1.0, param("na", 2) + param("nb", 2) - 3.0);
  // Bands and limits; He's motion at the record's start is a profiled state, not a parameter.
  if (effect == "stiction" || effect == "saturation") {
    double n = 0.0;
    for (const auto& v : p) n += v.name != "initial_motion";
    return std::max(1.0, n);
  }
  return 1.0;  // deadband, characteristic, actuator-lag, delay
}

double added_parameter_count(const std::string& effect, const ModelFit& trial,
                             const ModelFit& model, double Ts) {
  double k = effect_parameter_count(effect, trial, Ts);
  for (const auto& e : model.effects)
    if (e.name != effect && !trial.spec.has(e.name)) k -= effect_parameter_count(e.name, model, Ts);
  return k;
}

LinearOptions linear_options(const ModelSpec& spec, const ModelFitOptions& opt, std::size_t N) {
  LinearOptions lo;
  lo.range = opt.structure;
  if (spec.has("delay"))
    lo.range.nk_max = opt.delay_nk_max > 0 ? opt.delay_nk_max
                                           : std::max(opt.structure.nk_max,
                                                      static_cast<int>(estimation_end(N, opt) / 8));
  if (spec.has("order")) {
    lo.range.na_max = std::max(lo.range.na_max, opt.order_max);
    lo.range.nb_max = std::max(lo.range.nb_max, opt.order_max);
  }
  lo.integrating = spec.has("integrator");
  lo.drift = spec.has("disturbance");
  lo.drift_knot_spacing = opt.disturbance_knot_spacing;
  lo.start = opt.first_sample;
  lo.end = estimation_end(N, opt);
  if (lo.integrating) lo.level_anchor = opt.integrating_horizon;
  return lo;
}

// Effect k's coordinates searched from s.base (the others held there); s.best_z holds the best
// point seen. Position-dependent friction in five stages, each from the best point before: one
// level everywhere (He's fs and fd/fs: the two-parameter stiction it nests), then where and how
// much the level changes (over a tenth of the working window), then that with the severe side's
// level and fd/fs on a joint grid, then the two sides' fd/fs, then all six polished together with
// the transition's width. A joint grid over six coordinates is too coarse to hold a band of a few
// % of OP. The third stage because He's one band lies between the two sides' and the second
// holds it as the severe side's: a polish from there rarely climbs to the severe band; and with
// fd/fs in it because He's one fd/fs, held there, fits a severe band as a deadband of the
// wrong width (measured, 65 development cases of seeds 0-779, against the three-coordinate grid
// with fd/fs held and one fd/fs for both sides: the trial's estimation gain median 0.95 -> 1.47
// points, 2 points or more on 19 -> 25, the true valve position fitting the estimation part 1
// point better than the search's on 17 of 42 -> 11 of 37 trials that gained under 2).
nlopt_result search_effect(Search& s, std::size_t k, const ModelFitOptions& opt) {
  const std::size_t o = s.offset[k];
  const auto stage = [&](std::vector<std::size_t> active, const ModelFitOptions& so) {
    s.active = std::move(active);
    const nlopt_result r = search_space(s, so);
    s.base = s.best_z;
    return r;
  };
  if (s.effects[k].name == "preisach") {
    // He's stage on He's own grid (its cost is rugged: a coarser grid polished into worse
    // basins than the `stiction` fit it must not lose to); the change's on a grid half as fine.
    ModelFitOptions coarse = opt;
    if (coarse.grid_points == 0) coarse.grid_points = 11;
    stage({o, o + 2}, opt);
    stage({o + 1, o + 3}, coarse);
    {
      // The severe level lies above He's one band: its grid spans He's band to 3 times it,
      // not the whole range, whose 11 points are steps of a tenth of it (measured, the same 65
      // cases: gaining 2 points on 13 instead of 11, the true valve fitting 1 point better than
      // the search's on 17 of the 42 under 2 instead of 20).
      const SearchParameter whole = s.coords[o];
      SearchParameter severe = whole;
      severe.lower = s.theta(s.base.data())[o];
      severe.upper = std::min(whole.upper, 3.0 * severe.lower);
      // The coordinate's box changes: base and best point keep their values (theta, coordinate).
      const auto rebox = [&](const SearchParameter& to) {
        const double b = s.theta(s.base.data())[o], best = s.theta(s.best_z.data())[o];
        s.coords[o] = to;
        s.base[o] = s.coordinate(o, b);
        s.best_z[o] = s.coordinate(o, best);
      };
      const bool narrow = severe.upper > severe.lower * 1.01;
      if (narrow) rebox(severe);
      ModelFitOptions joint = coarse;  // four coordinates: 6^4 points, as many as 11^3
      if (opt.grid_points == 0) joint.grid_points = 6;
      stage({o, o + 1, o + 2, o + 3}, joint);
      if (narrow) rebox(whole);
    }
    stage({o + 2, o + 6}, coarse);
    s.active = {o, o + 1, o + 2, o + 3, o + 5, o + 6};
    std::vector<double> z = s.restrict_to_active(s.base);
    const int n_local =
        opt.local_evaluations > 0 ? opt.local_evaluations : 60 * static_cast<int>(s.active.size());
    const nlopt_result r =
        run_nlopt(NLOPT_LN_NELDERMEAD, s, z, n_local, opt.local_xtol, nullptr, 0.02).result;
    s.base = s.best_z;
    return r;
  }
  std::vector<std::size_t> active;
  const std::size_t end = k + 1 < s.effects.size() ? s.offset[k + 1] : s.coords.size();
  for (std::size_t i = o; i < end; ++i)
    if (s.coords[i].profile_points == 0) active.push_back(i);
  if (active.empty()) return NLOPT_SUCCESS;
  return stage(std::move(active), opt);
}

// Time constants (shares of the lag's range) at which a lag beside a valve nonlinearity is
// profiled: denser where the lag is short beside the range (60 samples), as most are.
constexpr std::array<double, 12> kLagProfile = {0.0, 0.02, 0.04, 0.07, 0.1,  0.14,
                                                0.2, 0.28, 0.4,  0.55, 0.75, 1.0};

// The joint polish of every searched coordinate from s.best_z, and again from `start` (a fit
// of the model this one extends) when given; the better result's status.
nlopt_result polish_all(Search& s, const ModelFitOptions& opt, const std::vector<double>* start,
                        double lo, double hi) {
  s.active = s.searched();
  const double mid = start ? lo + 0.5 * (hi - lo) : hi;
  const int n_local =
      opt.local_evaluations > 0 ? opt.local_evaluations : 60 * static_cast<int>(s.coords.size());
  s.stage(lo, mid, n_local, "valve parameters: all effects polished together");
  s.base = s.best_z;
  std::vector<double> zj = s.restrict_to_active(s.base);
  double end = 0.0;
  nlopt_result r =
      run_nlopt(NLOPT_LN_NELDERMEAD, s, zj, n_local, opt.local_xtol, &end, 0.02).result;
  if (start) {  // from the extended model's point (s.best_z keeps the better)
    s.stage(mid, hi, n_local, "valve parameters: polished again from the model this one extends");
    double end_start = 0.0;
    s.base = *start;
    std::vector<double> zs = s.restrict_to_active(*start);
    const nlopt_result rs =
        run_nlopt(NLOPT_LN_NELDERMEAD, s, zs, n_local, opt.local_xtol, &end_start, 0.02).result;
    if (end_start < end) r = rs;
  }
  return r;
}

// The valve coordinates' search: one effect alone by search_space; a lag (actuator-lag or order)
// beside one valve nonlinearity by a profile of the lag; other composed chains each effect first on
// its own (the others at rest), then a joint polish of all coordinates from there (a joint grid is
// too coarse in 4 or more dimensions). The best point is left in s.best_z.
nlopt_result search_valve(Search& s, const ModelFitOptions& opt,
                          const std::vector<double>* start = nullptr) {
  const auto is_lag = [&s](std::size_t k) { return is_lag_effect(s.effects[k].name); };
  if (s.effects.size() == 2 && is_lag(0) != is_lag(1)) {
    // A lag (an actuator's or an extra process lag) and one valve nonlinearity: searched effect
    // by effect, the lag fitted with the nonlinearity at rest takes up its delay, and the
    // nonlinearity fitted beside that lag keeps it there (measured, development seed 89: an
    // actuator lag of 18.2 s for the true 7.5 s, the true valve position fitting the estimation
    // part 5.5 points better). The lag is profiled: the nonlinearity searched on a coarser grid
    // at each of its time constants, the best point polished in all coordinates. Both lags alike:
    // `order` competes with `actuator-lag` beside a sticky valve, and the ranking should compare
    // the two placements, not two searches.
    const std::size_t lag = is_lag(0) ? 0 : 1;
    const std::size_t other = 1 - lag;
    ModelFitOptions coarse = opt;
    if (coarse.grid_points == 0) coarse.grid_points = 11;
    coarse.polish_starts = 1;
    const double from = s.span_lo, width = s.span_hi - s.span_lo;
    const double parts = static_cast<double>(kLagProfile.size() + 2);
    const auto part = [&](double k) { return from + width * k / parts; };
    const std::vector<double> rest = neutral_point(s);
    for (std::size_t i = 0; i < kLagProfile.size(); ++i) {
      s.span_lo = part(static_cast<double>(i));
      s.span_hi = part(static_cast<double>(i + 1));
      s.base = rest;
      s.base[s.offset[lag]] = kLagProfile[i];
      search_effect(s, other, coarse);
    }
    // At the best lag, the nonlinearity on its own grid (He's cost is rugged: the coarse grid
    // can polish into a worse basin).
    s.span_lo = part(parts - 2.0);
    s.span_hi = part(parts - 1.0);
    s.base = s.best_z;
    search_effect(s, other, opt);
    s.span_lo = from;
    s.span_hi = from + width;
    return polish_all(s, opt, start, part(parts - 1.0), part(parts));
  }
  if (s.effects.size() > 1) {
    s.base = neutral_point(s);
    // Two passes: an effect fitted with the others still at rest can take a wrong basin.
    const std::size_t passes = 2 * s.effects.size();
    // Each pass, the joint polish and the one from the extended model: equal parts of the share
    // the caller gave this search (half of it before a second search around a long dead time).
    const double from = s.span_lo, width = s.span_hi - s.span_lo;
    const double parts = static_cast<double>(passes + (start ? 2 : 1));
    const auto part = [&](double k) { return from + width * k / parts; };
    for (std::size_t pass = 0; pass < passes; ++pass) {
      s.span_lo = part(static_cast<double>(pass));
      s.span_hi = part(static_cast<double>(pass + 1));
      search_effect(s, pass % s.effects.size(), opt);
    }
    s.span_lo = from;
    s.span_hi = from + width;
    return polish_all(s, opt, start, part(static_cast<double>(passes)), part(parts));
  }
  if (!s.profiled.empty()) {
    s.base = neutral_point(s);
    s.active = s.searched();
  }
  if (s.effects.size() == 1 && s.effects[0].name == "preisach") return search_effect(s, 0, opt);
  return search_space(s, opt, start);
}

// The output-error refinement from the linear part of `m`, a fit of a model this one extends,
// for valve position x: the extended model itself when nothing improves on it. Not ok when the
// two differ in integrating or `m` carries a load (its knots are not kept).
LinearFit extended_linear_fit(const ArxEstimator& est, const ModelFit& m,
                              const std::vector<double>& x, const ModelFitOptions& opt) {
  if (m.integrating != est.options().integrating || !m.disturbance.empty() || m.a.empty() ||
      m.b.empty() || m.structure.nk < 0)
    return {};
  LinearFit start;
  start.structure = m.structure;
  start.a = m.a;
  start.b = m.b;
  start.c = m.c;
  start.ok = true;
  return est.fit_from(start, x, opt.output_error_iterations);
}

// The coordinates of `m`, a fit of a model the search's spec extends, with the added effects at
// rest (neutral_point); nullopt when `m` holds none of the search's effects.
std::optional<std::vector<double>> extended_point(const Search& s, const ModelFit& m) {
  std::vector<double> z = neutral_point(s);
  std::size_t off = 0;
  bool any = false;
  for (const auto& e : m.spec.effects) {
    const auto c = search_parameters(e, s.range);
    if (c.empty()) continue;
    if (off + c.size() > m.valve_coordinates.size()) return std::nullopt;
    for (std::size_t k = 0; k < s.effects.size(); ++k) {
      const std::size_t end = k + 1 < s.offset.size() ? s.offset[k + 1] : s.coords.size();
      if (s.effects[k] == e && end - s.offset[k] == c.size()) {
        std::copy_n(m.valve_coordinates.begin() + static_cast<std::ptrdiff_t>(off), c.size(),
                    z.begin() + static_cast<std::ptrdiff_t>(s.offset[k]));
        any = true;
      }
    }
    off += c.size();
  }
  if (off != m.valve_coordinates.size() || !any) return std::nullopt;
  return z;
}

namespace {

// Bayes' criterion of a fit's simulated output over the estimation samples [t0, t1), with k
// parameters, on n_eff independent samples (the residual is coloured: counting every sample
// lets 40 more weights buy a few tenths of a point): how `preisach:auto` weighs Preisach
// weights against six friction figures.
double output_bic(const ModelFit& f, const std::vector<double>& y, std::size_t t0, std::size_t t1,
                  double k, double n_eff) {
  if (f.status == ModelFitStatus::NoStableModel || f.y_sim.size() != y.size() || t1 <= t0 + 1)
    return std::numeric_limits<double>::infinity();
  double sse = 0.0;
  for (std::size_t t = t0; t < t1; ++t) sse += (y[t] - f.y_sim[t]) * (y[t] - f.y_sim[t]);
  const double n = static_cast<double>(t1 - t0);
  return n_eff * std::log(std::max(sse, 1e-300) / n) + k * std::log(n_eff);
}

double linear_parameter_count(const ModelFit& f) {
  return static_cast<double>(f.a.size() + f.b.size()) + (f.disturbance.empty() ? 1.0 : 0.0);
}

ModelFit fit_separable(const std::vector<double>& u, const std::vector<double>& y, double Ts,
                       const ModelSpec& spec, const ModelFitOptions& opt, ModelFit fit);

}  // namespace

ModelFit fit_model(const std::vector<double>& u, const std::vector<double>& y, double Ts,
                   const ModelSpec& spec, const ModelFitOptions& opt) {
  const auto t_start = std::chrono::steady_clock::now();
  check_problem(u, y, Ts, opt);
  throw_if_cancelled(opt.cancel);  // between a diagnosis' trial fits
  ModelFit fit;
  fit.spec = spec;
  fit.integrating = spec.has("integrator");
  for (const auto& e : spec.effects) fit.effects.push_back({e.name, e.variant, {}});
  auto finish = [&](ModelFit& f) {
    f.elapsed_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t_start).count();
  };
  if (const EffectSpec* pe = spec.find("preisach"); pe && pe->variant != "position-dependent") {
    // auto fits two models: the progress of each fills half.
    const auto half = [&opt](double lo) {
      ModelFitOptions o = opt;
      if (opt.progress)
        o.progress = [&opt, lo](double share, const std::string& what) {
          opt.progress(lo + 0.5 * share, what);
        };
      return o;
    };
    const bool both = pe->variant != "general";
    ModelFit general = fit_preisach(u, y, Ts, spec, both ? half(0.0) : opt, fit);
    if (!both) {
      finish(general);
      return general;
    }
    // auto: the general weights and the position-dependent friction, each fitted, the better
    // by BIC over the estimation samples both simulate.
    ModelSpec narrow = spec;
    for (auto& e : narrow.effects)
      if (e.name == "preisach") e.variant = "position-dependent";
    ModelFit banded = fit_separable(u, y, Ts, narrow, half(0.5), fit);
    banded.spec = spec;
    const std::size_t t0 = std::max(general.first_sample, banded.first_sample);
    const std::size_t t1 = std::min(general.estimation_end, banded.estimation_end);
    double n_eff = static_cast<double>(t1 > t0 ? t1 - t0 : 1);
    if (banded.y_sim.size() == y.size() && t1 > t0 + 1)
      n_eff = std::max(effective_sample_size(y, banded.y_sim, t0, t1), 2.0);
    const double bic_general = output_bic(
        general, y, t0, t1,
        linear_parameter_count(general) + effect_parameter_count("preisach", general, Ts), n_eff);
    const double bic_banded = output_bic(
        banded, y, t0, t1,
        linear_parameter_count(banded) + effect_parameter_count("preisach", banded, Ts), n_eff);
    ModelFit& won = bic_banded <= bic_general ? banded : general;
    won.evaluations = general.evaluations + banded.evaluations;
    finish(won);
    return std::move(won);
  }
  fit = fit_separable(u, y, Ts, spec, opt, std::move(fit));
  finish(fit);
  return fit;
}

namespace {

ModelFit fit_separable(const std::vector<double>& u, const std::vector<double>& y, double Ts,
                       const ModelSpec& spec, const ModelFitOptions& opt, ModelFit fit) {
  Problem p(u, y, Ts, spec, opt);
  const LinearOptions& lo = p.lo;
  const ArxEstimator& est = p.est;
  Search& s = p.s;
  fit.first_sample = est.start();
  fit.estimation_end = est.end();
  std::vector<double> z(s.coords.size(), 0.5);
  fit.status = ModelFitStatus::Converged;
  fit.stop_reason = "no valve parameters to search";
  std::optional<LinearFit> final_fit;  // the output-error fit of the final z, when made below
  if (!s.coords.empty()) {
    s.progress = &opt.progress;
    s.span_hi = p.delay_window() ? 0.5 : 1.0;  // a second search around a long dead time after
    const std::optional<std::vector<double>> ze =
        opt.extends && opt.extends->x_hat.size() == u.size() ? extended_point(s, *opt.extends)
                                                             : std::nullopt;
    nlopt_result outcome = search_valve(s, opt, ze ? &*ze : nullptr);
    z = s.best_z;
    const Search* won = &s;
    if (p.delay_window()) {
      // The first search scored the base grid's dead times only. The whole range's best one for
      // its valve, when outside them, centres a second search of the base grid's nk span; the
      // valve that fits better over the whole range wins. Two searches, not one over hundreds
      // of dead times.
      const LinearFit first = est.fit(s.valve_position(z.data()), false);
      const StructureRange& r = p.narrow_lo->range;
      if (first.ok && first.structure.nk > r.nk_max) {
        Search& again = p.around_delay(u, y, first.structure.nk, opt);
        again.progress = &opt.progress;
        again.span_lo = 0.5;
        again.reported = s.reported;
        const nlopt_result second = search_valve(again, opt);
        const LinearFit f = est.fit(again.valve_position(again.best_z.data()), false);
        if (f.ok && f.sse < first.sse) {
          z = again.best_z;
          outcome = second;
          won = &again;
        }
      }
    }
    widen_unsupported_limits(*won, y, z);
    if (opt.output_error_iterations > 0) {
      // The search scores valve parameters with the least-squares linear part; the final linear
      // part is the output-error refinement. The chain at rest (x = u) is the model without the
      // effects: keep it when its refined fit is better, so that a model with an effect added
      // never fits the estimation data worse than the model without it.
      // So is the model it extends (ModelFitOptions::extends), its added effects at rest.
      const std::vector<double> zn = neutral_point(s);
      LinearFit fb = est.fit_output_error(s.valve_position(z.data()), opt.output_error_iterations);
      LinearFit fn = est.fit_output_error(s.valve_position(zn.data()), opt.output_error_iterations);
      const bool neutral = fn.ok && (!fb.ok || fn.sse < fb.sse);
      if (neutral) z = zn;
      final_fit = std::move(neutral ? fn : fb);
      if (ze) {
        const std::vector<double> xe = s.valve_position(ze->data());
        for (LinearFit fe :
             {*ze != z ? est.fit_output_error(xe, opt.output_error_iterations) : LinearFit{},
              extended_linear_fit(est, *opt.extends, xe, opt)})
          if (fe.ok && (!final_fit->ok || fe.sse < final_fit->sse)) {
            z = *ze;
            final_fit = std::move(fe);
          }
      }
    }
    switch (outcome) {
      case NLOPT_SUCCESS:
      case NLOPT_STOPVAL_REACHED:
      case NLOPT_FTOL_REACHED:
      case NLOPT_XTOL_REACHED:
        fit.status = ModelFitStatus::Converged;
        fit.stop_reason = "Nelder-Mead polish met its tolerance";
        break;
      case NLOPT_MAXEVAL_REACHED:
      case NLOPT_MAXTIME_REACHED:
        fit.status = ModelFitStatus::EvaluationLimit;
        fit.stop_reason = "Nelder-Mead polish used its evaluation budget";
        break;
      default:
        fit.status = ModelFitStatus::NumericalTrouble;
        fit.stop_reason = "NLopt failed (code " + std::to_string(static_cast<int>(outcome)) +
                          "); best point seen kept";
        break;
    }
    fit.evaluations = s.evaluations.load() + (p.again ? p.again->evaluations.load() : 0);
    fit.valve_coordinates = z;
    ValveChain chain = s.chain(z.data());
    fit.valve = chain.effects();
    for (std::size_t k = 0; k < s.effects.size(); ++k) {
      for (auto& fe : fit.effects) {
        if (fe.name != s.effects[k].name) continue;
        fe.parameters = block_parameters(fit.valve[k]);
        fe.variant = effect_model(fit.valve[k]);
      }
    }
  }
  fit.x_hat = s.coords.empty() ? u : s.valve_position(z.data());
  // The fit of this x_hat is made above when the refinement chose z: the same fit, not made again.
  LinearFit f = final_fit ? std::move(*final_fit)
                          : est.fit_output_error(fit.x_hat, opt.output_error_iterations);
  if (!final_fit && opt.extends && opt.extends->x_hat == fit.x_hat) {
    // Only process effects added (no valve search): the extended model's linear part is a start.
    LinearFit fe = extended_linear_fit(est, *opt.extends, fit.x_hat, opt);
    if (fe.ok && (!f.ok || fe.sse < f.sse)) f = std::move(fe);
  }
  ++fit.evaluations;
  if (!f.ok) {
    fit.status = ModelFitStatus::NoStableModel;
    fit.stop_reason = "no structure gave a stable linear part";
    return fit;
  }
  fit.forced_stable = f.forced_stable;
  if (f.forced_stable)
    fit.stop_reason +=
        "; least squares gave no stable A, so the output-error fit started from "
        "its poles reflected inside the unit circle";
  fit.structure = f.structure;
  fit.a = f.a;
  fit.b = f.b;
  fit.c = f.c;
  fit.disturbance = est.drift_series(f);
  fit.y_sim = est.simulate(f, fit.x_hat);
  if (lo.drift) predict_load_on_validation(fit, y, est.knot_spacing());
  fit.fitness_percent = fitness_percent(y, fit.y_sim, fit.first_sample, fit.estimation_end);
  if (fit.estimation_end < y.size())
    fit.validation_fitness_percent = fitness_percent(y, fit.y_sim, fit.estimation_end, y.size());
  describe_process_effects(fit, &est, Ts);
  return fit;
}

}  // namespace

BandInterval band_interval(const std::vector<double>& u, const std::vector<double>& y, double Ts,
                           const ModelFit& fit, const std::string& effect,
                           const ModelFitOptions& opt) {
  constexpr double kChiSquare1Dof95 = 3.841;  // 95 % quantile of chi-square with 1 dof
  BandInterval out;
  if (fit.valve_coordinates.empty() || u.size() != y.size() ||
      fit.status == ModelFitStatus::NoStableModel)
    return out;
  Problem p(u, y, Ts, fit.spec, opt);
  // Scored over dead times that hold the fit's own (its search's second range, `delay`).
  Search& s = p.delay_window() ? p.around_delay(u, y, fit.structure.nk, opt) : p.s;
  if (s.coords.size() != fit.valve_coordinates.size()) return out;
  std::size_t band = s.coords.size();
  for (std::size_t k = 0; k < s.effects.size(); ++k)
    if (s.effects[k].name == effect) band = s.offset[k];
  if (band == s.coords.size()) return out;
  const std::vector<double> z0 = fit.valve_coordinates;
  const double c0 = s.cost(z0.data());
  {
    const std::vector<double> x = s.valve_position(z0.data());
    const LinearFit f = s.est.fit(x);
    if (!f.ok || !(c0 > 0)) return out;
    out.effective_samples = residual_samples(s, y, x, f);
  }
  // Inside: within the threshold of the fit's cost, or below it (a band the walk finds that fits
  // better widens the range to it: the fitted band is not better supported than that one).
  auto inside = [&](double c) {
    return out.effective_samples * std::log(c / c0) <= kChiSquare1Dof95;
  };
  for (std::size_t i = 0; i < s.coords.size(); ++i)
    if (i != band && s.coords[i].profile_points == 0) s.active.push_back(i);
  // Out from the fit in steps of a twentieth of the band (at least 0.2 % of the box), the other
  // coordinates re-fitted by Nelder-Mead from the previous point's (walk_profile: a step doubles
  // after 10 points in a row inside, and each side ends after 3 points in a row outside the
  // threshold, as the cost is rugged, or at the box's edge).
  const double v0 = z0[band];
  const int before = s.evaluations.load();
  std::vector<double> z;
  auto cost = [&](double v, bool restart) {
    if (restart) z = z0;
    s.base = z;
    s.base[band] = v;
    if (s.active.empty()) return s.cost(s.base.data());
    double c = 0.0;
    std::vector<double> za = s.restrict_to_active(s.base);
    const int evals =
        opt.local_evaluations > 0 ? opt.local_evaluations : 30 * static_cast<int>(s.active.size());
    run_nlopt(NLOPT_LN_NELDERMEAD, s, za, evals, 1e-3, &c, 0.05);
    z = s.full(za.data());
    return c;
  };
  const ProfileRange r = walk_profile(v0, c0, {0.0, 1.0, std::max(v0 / 20.0, 0.002)}, cost, inside);
  out.evaluations = s.evaluations.load() - before;
  const SearchParameter& par = s.coords[band];
  const double width = par.upper - par.lower;
  out.lo = par.lower + r.lo * width;
  out.hi = par.lower + r.hi * width;
  out.capped = r.capped;
  out.open_above = r.open_above;
  out.valid = true;
  return out;
}

std::vector<double> simulate_model(const ModelFit& fit, const std::vector<double>& u,
                                   const std::vector<double>& y) {
  if (u.size() != y.size()) throw std::invalid_argument("OP and PV differ in length");
  if (fit.status == ModelFitStatus::NoStableModel || fit.b.empty())
    throw std::invalid_argument("the fit has no model to simulate");
  const std::size_t t0 = fit.first_sample, N = u.size();
  if (N <= t0) throw std::invalid_argument("record shorter than the model's lags");
  std::vector<double> x(N);
  if (fit.preisach) {
    x = simulate_valve(*fit.preisach, u);
  } else {
    ValveChain chain(fit.valve);
    chain.reset(u[0]);
    chain.steps(u.data(), x.data(), N);
  }
  const double load =
      fit.disturbance.empty()
          ? fit.c
          : fit.disturbance[std::min(fit.estimation_end, fit.disturbance.size()) - 1];
  std::vector<double> ys(y), ws(N, 0.0);
  for (std::size_t t = 1; t < N; ++t) ws[t] = y[t] - y[t - 1];
  std::vector<double>& v = fit.integrating ? ws : ys;
  const std::size_t nk = static_cast<std::size_t>(fit.structure.nk);
  for (std::size_t t = t0; t < N; ++t) {
    double s = load;
    for (std::size_t i = 1; i <= fit.a.size(); ++i) s -= fit.a[i - 1] * v[t - i];
    for (std::size_t k = 1; k <= fit.b.size(); ++k)
      if (t >= nk + k) s += fit.b[k - 1] * x[t - nk - k];
    v[t] = s;
    if (fit.integrating) ys[t] = ys[t - 1] + s;
  }
  return ys;
}

std::vector<ModelFit> fit_models(const std::vector<double>& u, const std::vector<double>& y,
                                 double Ts, const std::vector<ModelSpec>& specs,
                                 const ModelFitOptions& opt,
                                 const std::function<void(std::size_t)>& each_done) {
  std::vector<ModelFit> out(specs.size());
  ModelFitOptions one = opt;
  one.threads = 1;    // the parallelism is across the specs
  one.progress = {};  // fits side by side: each_done reports them
  std::mutex reporting;
  std::size_t done = 0;
  parallel_for(specs.size(), worker_count(opt.threads, specs.size()), [&](unsigned, std::size_t k) {
    out[k] = fit_model(u, y, Ts, specs[k], one);
    if (!each_done) return;
    const std::lock_guard<std::mutex> lock(reporting);
    each_done(++done);
  });
  return out;
}

std::vector<double> k_step_output(const ModelFit& fit, const std::vector<double>& y, std::size_t k,
                                  const std::vector<double>* load_series) {
  const std::size_t N = y.size();
  if (k == 0 || fit.y_sim.size() != N || fit.x_hat.size() != N || fit.structure.nk < 0) return {};
  if (load_series && load_series->size() != N) return {};
  const std::size_t na = fit.a.size(), nb = fit.b.size();
  const std::size_t nk = static_cast<std::size_t>(fit.structure.nk);
  const std::size_t lag = std::max(na, nk + nb);
  const std::vector<double>* load = load_series                   ? load_series
                                    : fit.disturbance.size() == N ? &fit.disturbance
                                                                  : nullptr;
  std::vector<double> dy;  // an integrating fit's recursion runs on the differenced output
  if (fit.integrating) {
    dy.assign(N, 0.0);
    for (std::size_t t = 1; t < N; ++t) dy[t] = y[t] - y[t - 1];
  }
  const std::vector<double>& v = fit.integrating ? dy : y;
  std::vector<double> out = fit.y_sim, p(k);
  const std::size_t first = std::max(fit.first_sample, lag + 1) + k;
  for (std::size_t t = first; t < N; ++t) {
    const std::size_t s = t - k;  // measured up to s
    double level = fit.integrating ? y[s] : 0.0;
    for (std::size_t j = 1; j <= k; ++j) {
      const std::size_t tt = s + j;
      double pv = load ? (*load)[tt] : fit.c;
      for (std::size_t i = 1; i <= na; ++i)
        pv -= fit.a[i - 1] * (tt - i <= s ? v[tt - i] : p[tt - i - s - 1]);
      for (std::size_t m = 1; m <= nb; ++m) pv += fit.b[m - 1] * fit.x_hat[tt - nk - m];
      p[j - 1] = pv;
      level += pv;
    }
    out[t] = fit.integrating ? level : p[k - 1];
  }
  return out;
}

}  // namespace valvediag
