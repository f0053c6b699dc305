// Fitting a composable model (model_spec.hpp) to OP/PV data.
//
// Valve effects other than `preisach` are fitted by Jelali's separable least squares: for given
// valve parameters x = f(u) is simulated through the effect blocks (in canonical chain order),
// the ARX part is fitted by linear least squares over the structure grid (effect_estimators.hpp)
// and scored by the simulated-output error (eq 20). All valve parameters of the chain are searched
// jointly with NLopt: a global stage (DIRECT-L, or a coarse grid evaluated in parallel) and a
// Nelder-Mead polish from its best point, in boxes from the OP range.
// `preisach` is fitted by the core's identify() on a restricted grid.
// Process effects change the linear part: `delay` extends the nk range, `order` the na/nb range
// and adds an extra first-order lag after the valve effects (searched like a valve parameter),
// `integrator` fixes a (1 - q^-1) factor in A, `disturbance` adds a piecewise-linear slow load.
#pragma once

#include <cstddef>
#include <functional>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "valvediag/core/cancel.hpp"
#include "valvediag/core/hammerstein.hpp"
#include "valvediag/model/effect_estimators.hpp"
#include "valvediag/model/model_spec.hpp"
#include "valvediag/sim/valve_effects.hpp"

namespace valvediag {

enum class GlobalSearch { DirectL, Grid };

struct ModelFit;

struct ModelFitOptions {
  StructureRange structure;  // the base grid (small: every trial fit of `diagnose` pays for it)
  // nk range with `delay`; 0: the longest dead time the record can show, an eighth of the
  // estimation samples (at least the base grid's nk_max).
  int delay_nk_max = 0;
  int order_max = 4;                 // na, nb range with `order`
  double validation_fraction = 0.0;  // last fraction held out (0: none)
  std::size_t validation_start = 0;  // or the first held-out sample (0: use the fraction)
  // First estimation sample (0: the largest lag, the earliest the structure allows). Two models
  // compared on their fits are fitted on the same samples: one whose structure reaches further
  // back (a long dead time) starts later, and the other is refitted from there.
  std::size_t first_sample = 0;
  // Grid: every point of a regular grid (parallel), then a polish from each of the best
  // `polish_starts` points that are not grid neighbours of a better one. DirectL: NLopt's
  // GN_DIRECT_L (sequential), one polish from its best point; also used above 5000 grid points.
  GlobalSearch global = GlobalSearch::Grid;
  int global_evaluations = 0;  // DIRECT-L budget; 0: 100 per search dimension
  int grid_points = 0;         // per dimension; 0: 41, 21, 9, 6 for 1, 2, 3, 4 dimensions
  int polish_starts = 3;
  int local_evaluations = 0;  // 0: 60 per search dimension (Nelder-Mead)
  double local_xtol = 1e-4;   // relative to each coordinate's box width
  int preisach_L_min = 2, preisach_L_max = 16;
  std::size_t disturbance_knot_spacing = 0;  // samples; 0: LinearOptions' default
  // With `integrator`: the fit's criterion restarts the simulated level from measured PV every
  // this many samples (LinearOptions::level_anchor; 0: never). A load noise at the valve is a
  // random walk in an integrating output: over a whole record its drift, not the valve, would
  // decide the fit (measured: deadbands of 27 % of OP fitted to a 2.5 % one). One sample fits the
  // rate alone, where white measurement noise hides small valve effects (bands collapsed to 0).
  // Chosen on the benchmark's development seeds among 1, 5, 10, 20 and the output's horizon.
  std::size_t integrating_horizon = 10;
  // Steiglitz-McBride iterations refining the final linear part towards the output-error fit
  // (ArxEstimator::fit_output_error); 0: least squares only.
  int output_error_iterations = 5;
  int threads = 0;  // 0: all cores (Grid search, preisach, fit_models)
  // A fit of a model this spec extends (diagnose: the step's model, each trial adding an effect to
  // it), on the same data: its valve parameters, the added effects at rest, start the valve search
  // and stay a candidate of the final choice, so the wider model never fits the estimation data
  // worse than the one it extends (a search of more coordinates on a coarser grid can miss the
  // narrower model's basin). nullptr: the search starts from every effect at rest.
  const ModelFit* extends = nullptr;
  // Called as the valve search goes (one call at a time, from the fit's threads): the share of
  // it done, rising to 1, and what it is doing. A stage's share fills as its evaluations reach its
  // budget (a grid's points; a polish's most evaluations), so a polish that converges early
  // jumps to the next stage. For the Preisach weights (the core's identification), the share of
  // its configurations fitted. Not called by fit_models (its fits run side by side).
  std::function<void(double, const std::string&)> progress;
  // Set by another thread: the fit throws Cancelled (core/cancel.hpp) at its next valve-search
  // evaluation or identify() structure. Every trial fit of a diagnosis shares DiagnoseOptions::fit.
  const std::atomic<bool>* cancel = nullptr;
};

// How the solver ended. Impossible problems (bad data, bad options) throw instead.
enum class ModelFitStatus {
  Converged,         // the local polish met its tolerance (or nothing to search)
  EvaluationLimit,   // the polish used its evaluation budget before meeting the tolerance
  NumericalTrouble,  // NLopt reported a failure; the best point seen is returned
  NoStableModel,     // no structure gave a stable linear part: fitness is NaN
};
const char* to_string(ModelFitStatus s);

struct FittedEffect {
  std::string name;
  std::string variant;  // stiction model, characteristic kind found, "" otherwise
  std::vector<NamedValue> parameters;
};

struct ModelFit {
  ModelSpec spec;
  ModelFitStatus status = ModelFitStatus::Converged;
  std::string stop_reason;
  std::vector<FittedEffect> effects;  // one per effect of the spec, same order
  ArxStructure structure;
  bool integrating = false;  // A = (1 - q^-1) A'(q^-1): a, b, c belong to the differenced form
  // Least squares gave no stable A for the chosen structure; its output-error fit started from
  // the reflected poles (ArxEstimator::fit_output_error). A level fitted as self-regulating can
  // land here: the climb then tries `integrator` first.
  bool forced_stable = false;
  std::vector<double> a, b;
  double c = 0.0;
  // Estimated slow load d(t) (empty without `disturbance`). On the held-out part it is predicted
  // one knot interval ahead from the measured past (the mean equation error of the interval
  // before), never fitted to the held-out samples; simulate_model() holds the last estimated
  // value instead.
  std::vector<double> disturbance;
  double fitness_percent = std::numeric_limits<double>::quiet_NaN();  // estimation (eq 20)
  double validation_fitness_percent = std::numeric_limits<double>::quiet_NaN();  // NaN: no split
  std::size_t first_sample = 0;    // t0: samples before it seed the simulation
  std::size_t estimation_end = 0;  // one past the last estimation sample
  std::vector<double> x_hat;       // simulated valve position (preisach: gamma' mu, ||b|| = 1)
  std::vector<double> y_sim;       // simulated output, whole record
  std::vector<ValveEffect> valve;  // fitted blocks (empty for linear and preisach)
  std::optional<HammersteinModel> preisach;  // the identified Preisach model
  // The valve parameters' search coordinates at the fit (unit box, effect_estimators.hpp);
  // empty without valve parameters (linear, preisach).
  std::vector<double> valve_coordinates;
  int evaluations = 0;  // separable-problem evaluations (each: one valve simulation + grid)
  double elapsed_s = 0.0;
};

// u: OP, y: PV, Ts: sample period (s). Throws std::invalid_argument for impossible problems
// (lengths differ, too few samples, non-finite samples, constant OP, Ts <= 0, bad options).
ModelFit fit_model(const std::vector<double>& u, const std::vector<double>& y, double Ts,
                   const ModelSpec& spec, const ModelFitOptions& opt = {});
// Independent fits of several specs on the same data, shared out over the cores. each_done, when
// given, is called after each fit with how many are done (one call at a time, counts rising).
std::vector<ModelFit> fit_models(const std::vector<double>& u, const std::vector<double>& y,
                                 double Ts, const std::vector<ModelSpec>& specs,
                                 const ModelFitOptions& opt = {},
                                 const std::function<void(std::size_t)>& each_done = {});

// The fitted model driven by another record of the same loop (validation on separate data, as in
// the paper's Example 4): the valve from rest at u[0] (Preisach: the fitted initial memory), the
// first `first_sample` outputs seed the simulation, a fitted disturbance is held at its last value.
// Throws std::invalid_argument when the fit has no model or the record is too short.
std::vector<double> simulate_model(const ModelFit& fit, const std::vector<double>& u,
                                   const std::vector<double>& y);

// The validation fitness (eq 20, held-out part) `fit` would have if its valve stayed, from the
// first held-out sample on, where the estimation part left it (x_hat held; the linear part, c and
// the load as fitted and predicted). NaN without a held-out part or a stable fit. A valve with
// memory that predicts no movement there earns its held-out score by holding PV still, as a load
// the controller compensates does too; what it gains over this, its predicted slips explain.
double held_valve_validation_fitness(const ModelFit& fit, const std::vector<double>& y);

// The fit's k-step-ahead prediction of the output (MATLAB's compare(data, model, k)): y(t) from
// the measured output up to t - k and the simulated valve position, through the fitted linear
// part; an integrating fit starts from the measured level at t - k. The load is `load` when given
// (a series as long as y), else the fit's. Samples before the fit's first sample plus k keep the
// simulated output. Empty when the fit has no linear part.
std::vector<double> k_step_output(const ModelFit& fit, const std::vector<double>& y, std::size_t k,
                                  const std::vector<double>* load = nullptr);

// How well the data fix a fitted friction effect's band (`effect` "stiction": He's fs, Kano's S,
// Stenman's d; "deadband": d): its profile-likelihood interval. A band is inside when, with the
// chain's other valve parameters re-fitted, N_eff ln(SSE / best SSE) <= 3.84 (chi-square with one
// degree of freedom, 95 %) on the estimation part; SSE is the search's simulated-output cost, N_eff
// the effective sample size of the fit's residual (a slow load's wander is not many proofs).
// `opt` and the data must be those of the fit. Invalid when the fit has no such effect.
struct BandInterval {
  bool valid = false;
  double lo = std::numeric_limits<double>::quiet_NaN();  // OP units
  double hi = std::numeric_limits<double>::quiet_NaN();
  double effective_samples = 0.0;
  int evaluations = 0;  // separable-problem evaluations it took
  bool capped = false;  // a side reached its step budget still inside: the range is wider
  // The walk up reached the search box's top still inside: the data do not bound the band from
  // above, and `hi` is the box's top (for a band, the record's OP span: a valve that slipped at
  // most once or twice). Read the range as "at least lo".
  bool open_above = false;
};
BandInterval band_interval(const std::vector<double>& u, const std::vector<double>& y, double Ts,
                           const ModelFit& fit, const std::string& effect,
                           const ModelFitOptions& opt = {});

// Free parameters `effect` adds to a fitted model: a Preisach valve its nonzero weights, a load
// one level per knot over the estimation samples, an integrator none (it fixes a pole). Used to
// charge flexible effects (Occam's tie-breaks, BIC).
double effect_parameter_count(const std::string& effect, const ModelFit& fit, double Ts);

// Free parameters a trial with `effect` has beyond `model`: the effect's own less those of the
// model's effects the trial no longer has (`preisach` takes the place of a fitted `stiction` or
// `deadband`: add_effect).
double added_parameter_count(const std::string& effect, const ModelFit& trial,
                             const ModelFit& model, double Ts);

// The linear options fit_model uses for a spec (structure range widened by delay/order,
// integrator, disturbance, estimation window), for callers that reuse ArxEstimator.
LinearOptions linear_options(const ModelSpec& spec, const ModelFitOptions& opt, std::size_t N);

}  // namespace valvediag
