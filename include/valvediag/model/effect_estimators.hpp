// The pieces of the separable least-squares estimators (Jelali 2008, as the paper's baselines):
// for given valve-effect parameters the valve position x = f(u) is simulated through the blocks of
// valve_effects.hpp, the linear part is fitted by linear least squares over a small structure grid,
// and each structure is scored by its simulated-output error (eq 20). model_fit.hpp searches the
// valve parameters with NLopt around this.
#pragma once

#include <cstddef>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "valvediag/model/model_spec.hpp"
#include "valvediag/sim/valve_effects.hpp"

namespace valvediag {

// A(q^-1) y = B(q^-1) x + c,  B = b1 q^-(nk+1) + ... + b_nb q^-(nk+nb) (as in hammerstein.hpp).
struct ArxStructure {
  int na = 1, nb = 1, nk = 0;
  bool operator==(const ArxStructure&) const = default;
};

struct StructureRange {
  int na_min = 1, na_max = 2;
  int nb_min = 1, nb_max = 2;
  int nk_min = 0, nk_max = 10;
};

struct LinearOptions {
  StructureRange range;
  // `integrator`: A has a fixed (1 - q^-1) factor. The ARX part is fitted to the differenced
  // output w = y(t) - y(t-1) and the simulation integrates it back; c is then a ramp rate.
  bool integrating = false;
  // Integrating: the fit's criterion restarts the simulated level from the measured output every
  // this many samples (multiple shooting; 0: the whole window is one simulation). The reported
  // simulation (simulate) always runs through.
  std::size_t level_anchor = 0;
  // `disturbance`: a slow unmeasured load d(t) in the equation, A y = B x + d + e, with d
  // piecewise linear between knots every `drift_knot_spacing` samples over the estimation data
  // (hat functions; they replace c). d passes through 1/A like a load entering the process.
  // After the estimation data d holds its last value (so validation is honest).
  bool drift = false;
  std::size_t drift_knot_spacing = 0;  // samples; 0: max(30, estimation length / 16)
  std::size_t start = 0;               // first equation sample t0 (0: from the largest lag)
  std::size_t end = 0;                 // one past the last estimation sample (0: all)
  // Among structures within this many fitness points of the best: fewest na + nb, then the
  // smallest nk, then the smallest na (the core's rule; fitness alone prefers bigger models).
  double parsimony_percent = 0.1;
  // The reference search: the Gram blocks as dense matrix products, every structure fitted and
  // simulated to the end, one after another, in a loop of general orders (the benchmark's
  // baseline). Without it fit() gives the same structure, its coefficients to rounding.
  bool plain_scan = false;
};

struct SseWindow;  // one simulation lane of the structure search (arx_estimator.cpp)

struct LinearFit {
  bool ok = false;  // false: no structure gave a stable model
  ArxStructure structure;
  std::vector<double> a, b;         // A = 1 + a1 q^-1 + ...; b carries the gain
  double c = 0.0;                   // 0 with drift (the hat functions sum to one)
  std::vector<double> drift_knots;  // d at the knots (empty without drift)
  double sse = std::numeric_limits<double>::infinity();  // simulated output, estimation window
  double fitness_percent = std::numeric_limits<double>::quiet_NaN();
  // Least squares gave an unstable A for this structure: the fit started from A with its roots
  // outside the unit circle reflected inside (fit_output_error).
  bool forced_stable = false;
};

// The linear half of the separable problem for one output record. Everything that does not
// depend on x (lagged outputs, drift basis, their Gram blocks) is built once; each fit() costs
// O(n lags) for the x-dependent Gram blocks (shifted sums) plus one simulation per structure, cut
// short once the structure can no longer be chosen (on the same Gram blocks the answer is a plain
// scan's, to the bit).
// Thread-safe for concurrent fit() calls.
class ArxEstimator {
 public:
  // Throws std::invalid_argument when the window is too short for the structure range.
  ArxEstimator(std::vector<double> y, const LinearOptions& opt);

  // Best structure of the range for valve position x (x.size() == y.size()); with `parsimony`
  // the rule of LinearOptions::parsimony_percent picks among near-best structures.
  LinearFit fit(const std::vector<double>& x, bool parsimony = false) const;
  LinearFit fit(const std::vector<double>& x, const ArxStructure& s) const;
  // As fit(x, true), with each structure's least-squares fit refined towards the output-error
  // fit by Steiglitz-McBride iterations (output and valve position filtered by 1/A of the last
  // iterate, A and B fitted again): least squares on the equation error is biased when the
  // noise is coloured (load noise, closed loop), which hides extra lags and dead time. The
  // iterate with the smallest simulated-output error is kept, so a refined structure never
  // scores worse than its least-squares fit. A structure whose least-squares A is unstable (a
  // long closed-loop record biases the equation error past the unit circle) starts from A with
  // its outside roots reflected inside, and counts only when its refined fit beats the record's
  // mean (fitness above 0). Without drift terms only (with them: fit(x, true)).
  LinearFit fit_output_error(const std::vector<double>& x, int iterations) const;
  // The output-error refinement (as fit_output_error's) from a given linear part without a load,
  // for x: the start is scored and kept unless an iterate does better. With drift its constant is
  // a flat load (knots all equal; the load's own knots are fitted by least squares, as in fit()).
  // Not ok when the start's structure is outside this estimator's range or its A is unstable.
  LinearFit fit_from(const LinearFit& start, const std::vector<double>& x, int iterations) const;
  // Simulated output over the whole record (samples before start() copied from y; the drift
  // held after end()).
  std::vector<double> simulate(const LinearFit& f, const std::vector<double>& x) const;
  // The estimated load d(t) over the whole record (empty without drift).
  std::vector<double> drift_series(const LinearFit& f) const;

  std::size_t start() const { return t0_; }
  std::size_t end() const { return end_; }
  std::size_t knot_spacing() const { return h_; }
  const LinearOptions& options() const { return opt_; }

 private:
  struct Gram;
  Gram x_blocks(const std::vector<double>& x) const;
  Gram dense_blocks(const std::vector<double>& x) const;  // the same as matrix products
  // One structure, fitted and simulated to the end.
  LinearFit solve(const Gram& g, const ArxStructure& s, const std::vector<double>& x) const;
  // a, b and c (or the load's knots) of structure s by least squares; false when the normal
  // equations fail or A is unstable. The plain scan solves all columns at once; the search,
  // reduced_coefficients(), the lags only, with the tail eliminated by tail().
  bool coefficients(const Gram& g, const ArxStructure& s, LinearFit& f) const;
  bool reduced_coefficients(const Gram& g, const ArxStructure& s, LinearFit& f) const;
  void tail(Gram& g) const;
  double ridge(const Gram& g) const;
  // Sets f's sse and fitness and marks it ok when sse is finite and within bound.
  void score(LinearFit& f, double sse, double bound) const;
  // The simulated output's SSE over the estimation window.
  double window_sse(const LinearFit& f, const std::vector<double>& x) const;
  // The same for n <= 4 fits of equal na and nb, simulated side by side; sse[i] for fs[i]. Stops
  // early, with sums above bound, once every one exceeds it (then none can be chosen).
  void window_sse4(const LinearFit* fs, std::size_t n, const std::vector<double>& x, double bound,
                   double* sse) const;
  // One lane over the buffers v and load (the caller's, reused between calls); load nullptr:
  // the lane carries the load as its knots only (the unrolled kernels make it sample by sample).
  SseWindow window(const LinearFit& f, const std::vector<double>& x, std::vector<double>& v,
                   std::vector<double>* load) const;
  LinearFit pick(const std::vector<LinearFit>& fits) const;  // the parsimony rule
  LinearFit plain_fit(const Gram& g, const std::vector<double>& x, bool parsimony) const;
  LinearFit refine(const LinearFit& ls, const std::vector<double>& x, int iterations) const;

  std::vector<double> y_, w_;  // output and regression target (w = y or its difference)
  LinearOptions opt_;
  std::size_t t0_ = 0, end_ = 0, h_ = 0, knots_ = 0;
  int lag0_ = 1, lags_ = 0;       // x lags lag0_ .. lag0_ + lags_ - 1
  int nfixed_ = 0;                // fixed columns: w lags 1..na_max, then const or hats
  std::vector<double> F_;         // fixed columns, column-major, rows t0..end-1
  std::vector<double> hat_frac_;  // drift: sample k's distance past its knot, in knot intervals
  std::vector<double> FF_, Fw_;
  double ww_ = 0.0, den_ = 0.0;
};

// Bounds and units of one coordinate of the outer search.
struct SearchParameter {
  std::string name, unit;
  double lower = 0.0, upper = 0.0;
  // > 0: a discrete state, not searched: every evaluation takes the best of this many evenly
  // spaced values (profiled out).
  int profile_points = 0;
};

// The least of cost(z) over the values of the profiled coordinates (indices into coords; their
// profile_points evenly spaced over the unit box), the other coordinates as z has them; z is left
// at the least one's values. cost returns +inf for a point it cannot score.
template <class Cost>
double profile_minimum(const std::vector<SearchParameter>& coords,
                       const std::vector<std::size_t>& profiled, std::vector<double>& z,
                       Cost&& cost) {
  std::size_t combos = 1;
  for (std::size_t p : profiled) combos *= static_cast<std::size_t>(coords[p].profile_points);
  double best = std::numeric_limits<double>::infinity();
  std::vector<double> zb = z;
  for (std::size_t k = 0; k < combos; ++k) {
    std::size_t r = k;
    for (std::size_t p : profiled) {
      const auto n = static_cast<std::size_t>(coords[p].profile_points);
      z[p] = n > 1 ? static_cast<double>(r % n) / static_cast<double>(n - 1) : 0.5;
      r /= n;
    }
    const double c = cost(z);
    if (c < best) {
      best = c;
      zb = z;
    }
  }
  z = std::move(zb);
  return best;
}

// What the data says about the search box: the OP range, the sample period, and the window the
// valve mostly works in (OP's 5 and 95 % quantiles; both 0: the OP range). Controller transients
// to 0 or 100 % widen the range, not the window.
struct InputRange {
  double umin = 0.0, umax = 100.0, Ts = 1.0;
  double window_lo = 0.0, window_hi = 0.0;
  double lo() const { return window_hi > window_lo ? window_lo : umin; }
  double hi() const { return window_hi > window_lo ? window_hi : umax; }
};

// The input range of OP record u: its extremes and its 5 and 95 % quantiles (rank truncated).
InputRange input_range(const std::vector<double>& u, double Ts);

// Search coordinates of one valve effect, bounded from the OP range R = umax - umin:
//   stiction he: fs in [0, R], r = fd/fs in [0, 1] (keeps fs >= fd), and the valve's motion at
//     the start m in {-1, 0, 1} (HeStiction's initial_motion: down, rest, up; profiled);
//   kano, choudhury: S in [0, R], r = J/S in [0, 1];  stenman: d in [0, R];  deadband: d in [0, R]
//     (a band wider than the OP range never lets the valve move);
//   saturation: lower in [umin, umax - R/100], upper = lower + share (umax - lower), share in
//     [0.01, 1];
//   characteristic auto: signed curvature k in [-ln 200, ln 200] (k > 0 equal-percentage with
//     R = e^k, k < 0 quick-opening with R = e^-k, |k| < 1e-3 linear); a fixed kind: ln R in
//     [1e-3, ln 200];
//   actuator-lag: tau in [0, 60 Ts];
//   order: an extra process lag in [0, 60 Ts] (a first-order block after the valve effects,
//     besides the wider na, nb range);
//   preisach position-dependent: He's friction, one level below a valve position p and another
//     above it (PositionDependentStiction, changing linearly across a transition around p): the
//     severe side's fs in [0, R], the mild side c in [-1, 1] (c > 0: fs (1 - c) below p, fs
//     above; c < 0: fs below, fs (1 + c) above; 0: He's one level), r = fd/fs in [0, 1] on both
//     sides, p in the working window, the motion at the start (profiled, as He's), and the
//     transition's width as a share of the working window in [0.02, 1].
// The general `preisach` and the other process effects have none (they are fitted otherwise).
// Throws for unknown names.
std::vector<SearchParameter> search_parameters(const EffectSpec& e, const InputRange& r);
// The block for coordinates theta (as many as search_parameters gives).
ValveEffect make_valve_block(const EffectSpec& e, const double* theta, const InputRange& r);

struct NamedValue {
  std::string name;
  double value = 0.0;
  // "OP": the controller output's own units (a band's width or a level). It equals % of travel
  // only when OP spans 0..100; the stiction figures give the share of travel (OpRange).
  std::string unit;
};
// The physical parameters of a block as reported: fs, fd / S, J / d / lower, upper / R / tau.
std::vector<NamedValue> block_parameters(const ValveEffect& block);

}  // namespace valvediag
