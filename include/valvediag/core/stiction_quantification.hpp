// Stiction quantification from an identified Preisach valve model (the paper leaves it as future
// work, section 7): the figures engineers use for He's stiction model, in % of valve travel (OP
// units), overall and per OP region.
//
// The figures are He's parameters exactly as src/sim defines them (HeStiction,
// include/valvediag/sim/valve_effects.hpp), so a simulated truth and the estimate compare directly:
//   fs  static friction band: after the valve last moved, the OP travels fs + fd against the
//       direction of travel before the valve moves again (the stiction band, deadband +
//       stickband, `band` below);
//   fd  kinetic friction band: a moving valve lags the OP by fd; when it breaks free it jumps by
//       fs - fd (the slip jump, `jump` below).
// So fs = (band + jump) / 2 and fd = (band - jump) / 2; Kano's / Choudhury's S = band, J = jump.
//
// Method. The identified Preisach block is probed with an input inside the OP range the data
// visited, and He's model, scaled (s x + c: with ||b|| = 1 the Preisach output is in the ARX's
// units, not in %), is fitted to the Preisach response by least squares: a grid search over
// (fs, fd) and the phase of He's slip staircase (set by the valve's unknown history), s and c
// solved exactly, then two finer grids. The probe is the data's own OP when given: a model
// identified from a limit cycle is known only on inputs like it (Proposition 3), and outside the
// visited range relays never switched and carry no weight, so probing there would report
// stiction that is not in the data. Without data: the major loop and first-order reversal curves
// (Mayergoyz's FORCs: to a reversal level and back, at every level, both ways) over the grid.
// He sees the input on the grid as the Preisach model does (level centres), and is evaluated for
// an input that moves linearly between samples, so a slip happens at the exact crossing (the
// sampled flowchart would slip late by up to a sample and shrink the jump). The band is then
// known to a grid step (`resolution_percent`): the estimate is the middle of the interval that
// fits equally well. Why a fit rather than reading off one band and one jump: weights identified
// from noisy data spread over neighbouring relays and carry small spurious weights, so "the first
// move after a reversal" is fragile; the fit uses every reversal and slip at once, and gives He's
// parameters back for a model built from He's weights (Proposition 1). Why long sweeps matter: if
// no sweep makes two slips (OP sweeps shorter than 2 fs), a jump J at scale s and J' at
// s' = s J / J' give the same output: the band is measured, its split into fs and fd is not
// (`jump_identified` false).
//
// Per region (equal parts of the visited OP range): He is fitted again, with the overall scale,
// to the FORCs whose reversal lies in the region, over a window after the reversal (the band
// then depends on the friction where the valve sticks, as PositionDependentStiction has it).
//
// Refinement on the data (the overload with pv; `overall` then holds the refined figures,
// `preisach` the probe's). The probe alone is biased: its band is known to a grid step only, and
// a lattice fitted by NNLS shortens it (measured: fs low by 1-4 % of travel even when fitted to
// the noise-free valve position; 10 of 19 simulated loops within 20 %). So the probe's figures
// are the start, and He's valve is fitted inside the Hammerstein structure to (op, pv) directly:
// He's flowchart on the held OP (as the valve sees it), the linear part's simulated output
// B/A x + c + free response solved by least squares for each candidate (output error: with a
// slow pole the equation error is blind to the valve), A's poles and the delay (nk +- 2)
// re-fitted by Nelder-Mead, first to the Preisach valve's own position, then to He's. The cost
// over (fs, fd) has valleys a tenth of a % wide (one slip a sample late costs more than noise),
// so: a fine grid (step min(0.1, band/40) %) within `refine_window_steps` grid steps of the
// probe's figures, the best `refine_starts` separate valleys each polished (linear part, finer
// grid, twice), the best wins; each point of that grid is scored with poles of its own, the
// equation error's for its valve (`refine_own_linear`). Per region, the same with one band per
// region where the valve is held (PositionDependentStiction), region by region, around the overall
// figures. The probe's window is only as good as the Preisach model, and measurement noise biases
// that (equation error): so a coarse lattice over every band the visited range allows is scored
// too (with the own poles, the Preisach valve's and Steiglitz-McBride's, the lowest cost; SM's
// filtering by 1/A makes the equation error's noise nearly white, so it does not bias the poles
// the way it biases the own ones), its best valleys away from the window's are polished as well,
// and then, while that lowers the cost, the lattice is scored again with the best fit's linear
// part and its best new valleys polished. A band that reproduces the data's slips is a pit about
// 0.1 % wide, so the lattice's best cells are scored again at a quarter of its step, and each
// start is polished from the poles that fit it best (12 loops at noise 0.5-2: 2 within 20 % from
// the window alone, 11 with the lattice; in the miss the truth fits better than the estimate, so
// the search is what is left). The profile-likelihood interval (StictionInterval) then says how
// well the data fix the figures. Measured on 19 simulated loops (4 processes, noise 0.05-0.3, fs
// 2-10, fd 0.5-4): 19 within 20 % or 0.5 % of travel, most within 0.1 %. The regions are equal
// parts of the OP range, not the valve's, so an asymmetric valve's table is only roughly right
// (its order is).
#pragma once

#include <cmath>
#include <cstddef>
#include <string>
#include <vector>

#include "valvediag/core/hammerstein.hpp"
#include "valvediag/core/op_range.hpp"

namespace valvediag {

struct StictionQuantificationOptions {
  int regions = 3;  // equal parts of the visited OP range
  // A region counts as visited when it holds at least this fraction of the samples and at least
  // `min_region_reversals` OP reversals (turning points of the virtual input).
  double min_region_sample_fraction = 0.05;
  int min_region_reversals = 1;
  // With pv: refine the overall figures by fitting He's valve inside the Hammerstein structure to
  // the data, searched within this many grid steps of the Preisach figures.
  bool refine_on_data = true;
  // Refine too when the probe's band is below its grid step; stiction is then reported when the
  // refined band exceeds that step and its interval excludes fs = 0.
  bool refine_unresolved = true;
  double refine_window_steps = 3.0;
  int refine_passes = 2;  // re-estimations of the linear part's poles and delay
  int refine_starts = 8;  // separate valleys of the coarse search that are polished
  // And this many separate valleys of a coarse lattice (about `global_points` bands) over every
  // band the visited OP range allows, away from those: the probe's window is only as good as the
  // Preisach model, which measurement noise biases. 0: the window alone.
  int global_starts = 2;
  std::size_t global_points = 3000;
  // The best this many points of the coarse lattice are scored again at a quarter of its step
  // around them (24 points each); 0: not.
  std::size_t global_cells = 48;
  // Rounds of the coarse lattice: after the first, it is scored again with the best fit's linear
  // part and its best new valleys polished, while that lowers the cost.
  int global_rounds = 3;
  // The coarse lattice's bands are scored with the equation error's poles, the Preisach valve's
  // and Steiglitz-McBride's after this many passes from those (0: not), the lowest cost kept.
  int global_sm_passes = 3;
  // Score each point of the coarse search with poles of its own (the equation error's for its
  // valve) and polish from them; false: with the poles fitted to the Preisach valve's position.
  bool refine_own_linear = true;
  bool refine_regions = true;  // per-region bands refined on the data too
  int refine_delay_range = 2;  // delays nk +- this are tried
  // Score a valve path once: the probe's samples merged into runs of one grid level, and a
  // candidate's cost remembered by its position's fingerprint (a hash of its slips) while the
  // linear part stays. false: every sample and every candidate computed (the benchmark's
  // baseline; the same figures).
  bool reuse_costs = true;
  // B's taps' products with each other summed one by one, as every other product (the reference
  // the tests hold the fast path to); false: from one dot product per lag difference and the
  // window's ends (the same figures, the costs to rounding).
  bool plain_sums = false;
  // Worker threads for the refinement's grid and polish (0: all cores); the figures do not
  // depend on it.
  int threads = 0;
  // The refined figures' profile-likelihood interval (StictionInterval): the chi-square(1)
  // quantile of its level (3.84: 95 %; 6.63: 99 %), and how many (fs, fd) candidates it may score
  // before it stops widening (then `capped`).
  bool interval = true;
  double interval_chi2 = 3.841;
  std::size_t interval_max_points = 20000;
};

// He's figures, % of valve travel (OP units). NaN when they cannot be measured.
struct StictionFigures {
  double fs_percent = 0.0;    // He's fs: static friction band
  double fd_percent = 0.0;    // He's fd: kinetic friction band
  double band_percent = 0.0;  // fs + fd: OP travel after a reversal before the valve moves
  double jump_percent = 0.0;  // fs - fd: the slip jump
  double fit_percent = 0.0;   // how well He's model explains the Preisach response (eq 20 form)
};

// How well the data fix the refined fs and fd: every (fs, fd) whose fit to the data (the linear
// part's gain, offset and initial state by least squares; its poles the best fit's or the
// candidate's own, whichever fits better) is within the likelihood-ratio threshold of the best,
//   N_eff ln(cost / best cost) <= chi2   (chi-square with one degree of freedom),
// and the range of fs (and of fd) over them: fs's and fd's profile-likelihood intervals. N_eff is
// the best fit's residual's effective sample size (autocorrelation.hpp): the output error's
// residual is coloured, and counted as N independent samples it would make the interval far too
// narrow. Candidates lie on the refinement's lattice (step `step_percent`) around the best, which
// widens wherever a candidate within the threshold lies on its edge. The interval says how flat
// the cost is, not how far the model is from the truth: a missing effect moves the figures
// without widening it.
struct StictionInterval {
  bool valid = false;  // computed: the figures were refined on data
  double fs_lo = 0.0, fs_hi = 0.0;
  double fd_lo = 0.0, fd_hi = 0.0;
  double chi2 = 0.0;               // the threshold's chi-square quantile (3.84: 95 %)
  double effective_samples = 0.0;  // N_eff
  double cost_ratio = 0.0;         // largest cost / best cost inside: exp(chi2 / N_eff)
  double step_percent = 0.0;       // the lattice step: the ends are known to it
  std::size_t points = 0;          // candidates scored
  bool capped = false;             // the point budget stopped the widening: at least this wide
  // A band within the threshold lies on the lattice's top (the OP span the figures are probed
  // on): the data do not bound fs from above, and fs_hi is that span.
  bool fs_open_above = false;
  double level() const { return std::erf(std::sqrt(chi2 / 2)); }  // chi2's probability (0.95)
};

struct StictionRegion {
  double op_lo = 0.0, op_hi = 0.0;  // OP range of the region, %
  StictionFigures figures;
  StictionFigures preisach;  // the Preisach probe's figures (= figures unless refined)
  int probes = 0;            // reversal curves of the probe with their reversal in the region
  std::size_t samples = 0;   // data samples in the region (0 without data)
  int data_reversals = 0;    // OP reversals of the data in the region (0 without data)
  bool visited = false;      // by the data (true when no data was given: unknown, assumed)
  bool valid = false;        // visited and probed: the figures say something about the valve
  bool stiction = false;     // valid and band above the resolution
  // The region's fs that the data fit as well (95 %, as StictionInterval): the region's fs walked
  // out from its refined value, its fd re-fitted near the previous point's, the other regions'
  // bands and the linear part held. NaN when not refined on data. Regions are equal parts of the
  // OP range, not of the valve's: a wide range says the data cannot place the band there.
  double fs_lo = std::numeric_limits<double>::quiet_NaN();
  double fs_hi = std::numeric_limits<double>::quiet_NaN();
};

struct StictionQuantification {
  bool valid = false;     // a model with weights and a visited range of at least two levels
  bool stiction = false;  // the band exceeds the resolution (one grid step)
  // false when no probe sweep makes two slips: band measured, its split into fs, fd is not.
  bool jump_identified = false;
  bool data_given = false;  // op data given: visited range and region support from the data
  StictionFigures overall;
  StictionFigures preisach;         // the Preisach probe's figures (= overall unless refined)
  bool refined = false;             // overall refined on the data (op, pv)
  StictionInterval interval;        // of the refined overall figures
  double resolution_percent = 0.0;  // grid step delta: bands below it are not resolved
  double scale = 0.0;               // Preisach output units per % of valve travel (He's s)
  double op_lo = 0.0, op_hi = 0.0;  // visited OP range the probe covers
  std::vector<StictionRegion> regions;
  std::string summary;  // one plain sentence
};

// `op`: the controller output the model was identified on (may be empty: then the whole grid
// range is probed and region support is unknown). Throws std::invalid_argument for a model whose
// weights do not match its grid. With `pv` (same length as op, the output the model was
// identified on, or the valve position for a valve-position model) the figures are refined on
// the data when the probe resolves stiction; a few seconds for 3000 samples.
StictionQuantification quantify_stiction(const HammersteinModel& model,
                                         const std::vector<double>& op = {},
                                         const StictionQuantificationOptions& opt = {});
StictionQuantification quantify_stiction(const HammersteinModel& model,
                                         const std::vector<double>& op,
                                         const std::vector<double>& pv,
                                         const StictionQuantificationOptions& opt = {});

// The figures in % of a valve whose OP span is `span` (OP in other units than %; the figures
// above are in OP units, so % only for a 0..100 span): fs, fd, band, jump and the resolution,
// overall and per region, times 100 / (span.hi - span.lo), and `scale` per % of that span. OP
// ranges (op_lo, op_hi of the probe and the regions) stay in OP units. Throws
// std::invalid_argument unless span.lo < span.hi, both finite.
StictionQuantification in_percent_of_span(StictionQuantification q, const OpRange& span);

}  // namespace valvediag
