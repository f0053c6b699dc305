#include "valvediag/diagnose/prediction_refit.hpp"

#include <nlopt.h>

#include <algorithm>
#include <cmath>
#include <limits>

#include "valvediag/sim/valve_effects.hpp"

namespace valvediag {
namespace {

struct Refit {
  const std::vector<double>& u;
  const std::vector<double>& y;
  const PredictionRefitOptions& opt;
  const PredictionErrorSearch& search;  // the estimation part's variance, PV's sums kept
  std::vector<ValveEffect> blocks;      // the trial's chain; block k is refitted
  std::size_t k = 0;
  EffectSpec spec;
  InputRange range;
  std::vector<SearchParameter> coords;  // of block k
  std::vector<std::size_t> searched, profiled;
  std::vector<double> base;  // block k's coordinates in the unit box
  std::size_t nk = 0;        // the predictor's dead time during the search
  int evaluations = 0;
  std::vector<double> x;  // scratch

  double value(std::size_t i, double z) const {
    return coords[i].lower + std::clamp(z, 0.0, 1.0) * (coords[i].upper - coords[i].lower);
  }
  const std::vector<double>& position(const std::vector<double>& z) {
    std::vector<double> th(coords.size());
    for (std::size_t i = 0; i < coords.size(); ++i) th[i] = value(i, z[i]);
    std::vector<ValveEffect> chain_blocks = blocks;
    chain_blocks[k] = make_valve_block(spec, th.data(), range);
    ValveChain chain(std::move(chain_blocks));
    x.resize(u.size());
    chain.reset(u[0]);
    chain.steps(u.data(), x.data(), u.size());
    return x;
  }
  // The estimation part's one-step prediction error at unit-box point z, the profiled
  // coordinates at their best value (written back into z).
  double cost(std::vector<double>& z) {
    return profile_minimum(coords, profiled, z, [this](const std::vector<double>& zc) {
      ++evaluations;
      const double v = search.estimation_variance(position(zc), nk);
      return std::isfinite(v) ? v : std::numeric_limits<double>::infinity();
    });
  }
};

// The two-coordinate grid: the band from kBandGridLow to kBandGridHigh times the first grid's
// best, the second coordinate over its whole range.
constexpr std::size_t kBandGridPoints = 26, kSecondGridPoints = 11;
constexpr double kBandGridLow = 0.5, kBandGridHigh = 2.2;

double nlopt_cost(unsigned n, const double* za, double* grad, void* data) {
  auto& r = *static_cast<Refit*>(data);
  if (grad) std::fill(grad, grad + n, 0.0);
  std::vector<double> z = r.base;
  for (unsigned i = 0; i < n; ++i) z[r.searched[i]] = za[i];
  const double c = r.cost(z);
  return std::isfinite(c) ? c : std::numeric_limits<double>::max();
}

}  // namespace

bool refitted_to_prediction(const std::string& effect) {
  return effect != "preisach" && (is_valve_effect(effect) || effect == "order");
}

PredictionRefit refit_by_prediction(const std::vector<double>& u, const std::vector<double>& y,
                                    double Ts, const ModelFit& trial, const std::string& effect,
                                    const PredictionRefitOptions& opt) {
  PredictionRefit out;
  const std::size_t N = y.size();
  if (u.size() != N || N == 0 || trial.valve.empty() || trial.x_hat.size() != N ||
      opt.estimation_end > N || opt.from < opt.nk_max + opt.order || opt.grid_points < 2)
    return out;
  const PredictionErrorSearch search(y, opt.order, opt.from, opt.estimation_end, opt.integrating);
  Refit r{u, y, opt, search, trial.valve, 0, {}, input_range(u, Ts), {}, {}, {}, {}, 0, 0, {}};
  // Block j of the chain is the j-th effect of the spec with search coordinates (model_fit).
  std::size_t j = 0, offset = 0, k_offset = 0;
  bool found = false;
  for (const auto& e : trial.spec.effects) {
    const auto c = search_parameters(e, r.range);
    if (c.empty()) continue;
    if (e.name == effect && !found) {
      found = true;
      r.k = j;
      r.spec = e;
      r.coords = c;
      k_offset = offset;
    }
    ++j;
    offset += c.size();
  }
  if (!found || j != trial.valve.size() || offset != trial.valve_coordinates.size()) return out;
  for (std::size_t i = 0; i < r.coords.size(); ++i) {
    r.base.push_back(trial.valve_coordinates[k_offset + i]);
    (r.coords[i].profile_points > 0 ? r.profiled : r.searched).push_back(i);
  }
  if (r.searched.empty()) return out;
  const PredictionError at_trial = best_arx_prediction_error(
      y, trial.x_hat, opt.nk_max, opt.order, opt.from, opt.estimation_end, opt.integrating);
  if (!at_trial.ok) return out;
  r.nk = at_trial.nk;
  // The grid: the first searched coordinate, denser near its lower end (bands and lags are
  // mostly small against their range), with the others at the trial's values and, when there
  // are others, also at the middle of their ranges.
  std::vector<double> best_z = r.base;
  double best = r.cost(best_z);
  const std::size_t first = r.searched.front();
  const bool from_zero = r.coords[first].lower == 0.0;
  for (int variant = 0; variant < (r.searched.size() > 1 ? 2 : 1); ++variant)
    for (std::size_t g = 0; g < opt.grid_points; ++g) {
      std::vector<double> z = r.base;
      const double s = static_cast<double>(g) / static_cast<double>(opt.grid_points - 1);
      z[first] = from_zero ? s * s * s : s;
      if (variant == 1)
        for (std::size_t i : r.searched)
          if (i != first) z[i] = 0.5;
      const double c = r.cost(z);
      if (c < best) {
        best = c;
        best_z = z;
      }
    }
  // A friction's band and its second coordinate (the jump's share, or fd/fs): both on a grid around
  // the band the first grid found, multiplicative in the band. The prediction's cost in them is a
  // narrow valley (slips a sample early or late cost more than a jump buys: measured, He's
  // friction 5 % off its band predicted no better than a deadband), which the first grid, the
  // other coordinate held at two values, and a local polish from it did not reach.
  if (r.spec.name == "stiction" && r.searched.size() == 2 && best_z[first] > 0.0) {
    const std::size_t second = r.searched[1];
    const std::vector<double> around = best_z;
    for (std::size_t g = 0; g < kBandGridPoints; ++g) {
      const double f = kBandGridLow *
                       std::pow(kBandGridHigh / kBandGridLow,
                                static_cast<double>(g) / static_cast<double>(kBandGridPoints - 1));
      for (std::size_t q = 0; q < kSecondGridPoints; ++q) {
        std::vector<double> z = around;
        z[first] = std::min(1.0, around[first] * f);
        z[second] = static_cast<double>(q) / static_cast<double>(kSecondGridPoints - 1);
        const double c = r.cost(z);
        if (c < best) {
          best = c;
          best_z = z;
        }
      }
    }
  }
  // Nelder-Mead from the grid's best over the searched coordinates.
  {
    const auto n = static_cast<unsigned>(r.searched.size());
    nlopt_opt o = nlopt_create(NLOPT_LN_NELDERMEAD, n);
    if (o) {
      std::vector<double> lo(n, 0.0), hi(n, 1.0), za(n), step(n);
      for (unsigned i = 0; i < n; ++i) {
        za[i] = best_z[r.searched[i]];
        step[i] = std::max(0.02, 0.25 * std::min(za[i], 1.0 - za[i]));
      }
      r.base = best_z;
      nlopt_set_lower_bounds(o, lo.data());
      nlopt_set_upper_bounds(o, hi.data());
      nlopt_set_initial_step(o, step.data());
      nlopt_set_min_objective(o, nlopt_cost, &r);
      nlopt_set_maxeval(o, opt.local_evaluations * static_cast<int>(n));
      nlopt_set_xtol_abs1(o, 1e-4);
      double c = 0.0;
      if (nlopt_optimize(o, za.data(), &c) > 0 && c < best) {
        std::vector<double> z = best_z;
        for (unsigned i = 0; i < n; ++i) z[r.searched[i]] = za[i];
        const double again = r.cost(z);  // sets the profiled coordinates
        if (again < best) {
          best = again;
          best_z = z;
        }
      }
      nlopt_destroy(o);
    }
  }
  out.x_hat = r.position(best_z);
  out.error = best_arx_prediction_error(y, out.x_hat, opt.nk_max, opt.order, opt.from,
                                        opt.estimation_end, opt.integrating);
  std::vector<double> th(r.coords.size());
  for (std::size_t i = 0; i < r.coords.size(); ++i) th[i] = r.value(i, best_z[i]);
  out.parameters = block_parameters(make_valve_block(r.spec, th.data(), r.range));
  if (!out.error.ok || at_trial.estimation_variance <= out.error.estimation_variance) {
    // The trial's own parameters predict no worse.
    out.error = at_trial;
    out.x_hat = trial.x_hat;
    out.parameters = block_parameters(trial.valve[r.k]);
  } else {
    out.moved = true;
  }
  out.evaluations = r.evaluations;
  out.ok = out.error.ok;
  return out;
}

}  // namespace valvediag
