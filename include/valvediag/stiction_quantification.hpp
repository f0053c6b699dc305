// Stiction quantification from an identified Preisach valve model (the paper leaves it as future
// work, section 7): the figures engineers use for He's stiction model, in % of valve travel (OP
// units), overall and per OP region.
//
// The figures are He's parameters exactly as src/sim defines them (HeStiction,
// include/valvediag/valve_effects.hpp), so a simulated truth and the estimate compare directly:
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
#pragma once

#include <cstddef>
#include <string>
#include <vector>

#include "valvediag/hammerstein.hpp"

namespace valvediag {

struct StictionQuantificationOptions {
  int regions = 3;  // equal parts of the visited OP range
  // A region counts as visited when it holds at least this fraction of the samples and at least
  // `min_region_reversals` OP reversals (turning points of the virtual input).
  double min_region_sample_fraction = 0.05;
  int min_region_reversals = 1;
};

// He's figures, % of valve travel (OP units). NaN when they cannot be measured.
struct StictionFigures {
  double fs_percent = 0.0;    // He's fs: static friction band
  double fd_percent = 0.0;    // He's fd: kinetic friction band
  double band_percent = 0.0;  // fs + fd: OP travel after a reversal before the valve moves
  double jump_percent = 0.0;  // fs - fd: the slip jump
  double fit_percent = 0.0;   // how well He's model explains the Preisach response (eq 20 form)
};

struct StictionRegion {
  double op_lo = 0.0, op_hi = 0.0;  // OP range of the region, %
  StictionFigures figures;
  int probes = 0;           // reversal curves of the probe with their reversal in the region
  std::size_t samples = 0;  // data samples in the region (0 without data)
  int data_reversals = 0;   // OP reversals of the data in the region (0 without data)
  bool visited = false;     // by the data (true when no data was given: unknown, assumed)
  bool valid = false;       // visited and probed: the figures say something about the valve
  bool stiction = false;    // valid and band above the resolution
};

struct StictionQuantification {
  bool valid = false;     // a model with weights and a visited range of at least two levels
  bool stiction = false;  // the band exceeds the resolution (one grid step)
  // false when no probe sweep makes two slips: band measured, its split into fs, fd is not.
  bool jump_identified = false;
  bool data_given = false;  // op data given: visited range and region support from the data
  StictionFigures overall;
  double resolution_percent = 0.0;  // grid step delta: bands below it are not resolved
  double scale = 0.0;               // Preisach output units per % of valve travel (He's s)
  double op_lo = 0.0, op_hi = 0.0;  // visited OP range the probe covers
  std::vector<StictionRegion> regions;
  std::string summary;  // one plain sentence
};

// `op`: the controller output the model was identified on (may be empty: then the whole grid
// range is probed and region support is unknown). Throws std::invalid_argument for a model whose
// weights do not match its grid.
StictionQuantification quantify_stiction(const HammersteinModel& model,
                                         const std::vector<double>& op = {},
                                         const StictionQuantificationOptions& opt = {});

}  // namespace valvediag
