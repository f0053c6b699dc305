// The verdict a plant engineer wants first: "stiction", "deadband", "other-nonlinearity",
// "no-valve-problem", or "not-enough-data" (the record cannot tell).
//
// verdict(Diagnosis) reads a diagnosis (the climbed ladder or the top supported finding).
//
// loop_verdict() is the verdict for a recorded loop (real plant data), resting on the model and
// the physics rather than on the shape of one data set:
//  1. Is the record usable? Enough samples, OP and PV not constant, OP not saturated nearly all
//     the time, OP moving beyond its own noise, and OP reversing often enough that a valve's
//     hysteresis is excited at all (paper section 5). Otherwise `not-enough-data`, with the reason.
//  2. Hysteresis evidence. The whole record is fitted with the valve models that have memory
//     (He stiction, the Preisach model) and with the bare `linear` one (x = u). A sticky valve
//     shows as fitness that the model with memory gains: in fitness points and relative to the
//     error the linear model leaves; both must be clear. And the diagnosis's trial fit of that
//     effect (scored on held-out data) must not lose on the held-out part: a memory that only
//     helps where it was fitted is over-fitting. (Saturation and characteristic fits are
//     reported too; on these records a static curve through one OP sweep and one slip mimics
//     stiction, so they are not used as the baseline.)
//  3. Physical size. The identified stiction band (He's fs + fd: the OP travel after a reversal
//     before the valve moves, in % of travel) must stand above the OP's own noise: a band inside
//     the noise is no valve problem. The slip jump (fs - fd) tells stiction from deadband.
//  4. Without hysteresis evidence, the diagnosis (diagnose() from `linear`, trial fits scored on
//     held-out data) names any other valve nonlinearity it supports, else `no-valve-problem`.
#pragma once

#include <cstddef>
#include <limits>
#include <string>
#include <vector>

#include "valvediag/diagnosis.hpp"
#include "valvediag/loop_data.hpp"

namespace valvediag {

std::string verdict(const Diagnosis& d);

struct VerdictOptions {
  double op_min = 0.0, op_max = 100.0;  // the valve's OP span: % of travel, saturation
  std::size_t min_samples = 200;
  double saturated_fraction = 0.9;      // OP at an end of its span this often: not usable
  double saturation_margin = 0.5;       // % of travel from an end that counts as "at the end"
  double min_op_range_noise = 4.0;      // OP's 5-95 % range over its noise (white noise: 3.3)
  int min_reversals = 2;                // identifiability (section 5): fewer, hysteresis unexcited
  double min_gain_points = 10.0;        // hysteresis over memoryless, fitness points
  double min_relative_gain = 0.25;      // ... and share of the error the linear model leaves
  double min_validation_gain = 0.0;     // the diagnosis's held-out gain of that effect
  double min_band_noise = 3.0;          // stiction band over the OP noise
  double deadband_jump_fraction = 0.1;  // slip jump below this share of the band: no jump
  double deadband_fit_points = 1.0;     // ... and deadband fits within this of the best
  bool run_diagnosis = true;            // step 4 (and the figures it reports)
  DiagnoseOptions diagnose;
  ModelFitOptions fit;  // whole-record fits (validation settings are ignored)
};

// What the verdict rests on; NaN where not computed.
struct VerdictFigures {
  static constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
  std::size_t samples = 0;
  double op_range = kNaN;   // OP 5-95 % range, % of travel
  double op_noise = kNaN;   // OP noise (robust sigma of the sample-to-sample change), % of travel
  double saturated = kNaN;  // fraction of samples with OP at an end of its span
  int op_reversals = 0;     // reversals of OP on a 10-level grid over its range
  // Whole-record fitness (eq 20), %: memoryless models and hysteresis models.
  double linear_fitness = kNaN, saturation_fitness = kNaN, characteristic_fitness = kNaN;
  double stiction_fitness = kNaN, preisach_fitness = kNaN, deadband_fitness = kNaN;
  std::string memoryless_model;   // best of linear, saturation, characteristic (reported)
  std::string hysteresis_model;   // best of stiction, preisach
  double hysteresis_gain = kNaN;  // points over linear (no stable linear model: over 0)
  double relative_gain = kNaN;    // gain / (100 - linear fitness)
  // The diagnosis's best held-out gain of a trial with memory (stiction, preisach, deadband),
  // points; NaN without a diagnosis.
  double hysteresis_validation_gain = kNaN;
  // He's figures from the stiction fit, % of valve travel.
  double fs = kNaN, fd = kNaN, band = kNaN, jump = kNaN;
  // The diagnosis from `linear` (validation-scored trial fits).
  std::string finding;  // top finding ("" when none)
  bool finding_supported = false;
  double finding_gain = kNaN;  // its gain, smaller of estimation and validation, points
};

struct LoopVerdict {
  std::string verdict;
  std::string reason;  // one plain sentence: what the verdict rests on
  VerdictFigures figures;
  Diagnosis diagnosis;  // empty steps when not run
};

// u: OP, y: PV, Ts: s. Never throws for bad data: it gives not-enough-data with the reason.
LoopVerdict loop_verdict(const std::vector<double>& u, const std::vector<double>& y, double Ts,
                         const VerdictOptions& opt = {});
LoopVerdict loop_verdict(const LoopData& d, const VerdictOptions& opt = {});

// Steps 2-4 on figures already computed (a usable record): the verdict and its reason. Exposed
// so that threshold checks (leave-one-out) need not refit.
std::string decide_verdict(const VerdictFigures& f, const VerdictOptions& opt,
                           std::string* reason = nullptr);

}  // namespace valvediag
