// The one verdict of a loop record: stiction, deadband, other-nonlinearity, no-valve-problem or
// not-enough-data, with the stiction size and what it rests on. Every command that prints or
// writes a verdict (fit --verdict, diagnose, report, sweep, demo) calls loop_verdict(), so the same
// data and options give the same verdict everywhere.
//
// The analysis is the sweep's: the usability checks (unusable_reason, loop_health.hpp), the
// quiet lead-in left out (quiet_lead_in.hpp), `diagnose --auto` from `linear` (diagnosis.hpp),
// the verdict rule (verdict.hpp) and the friction size of the climb's final model. It reads
// nothing but the data and the options: no model history, no model a command was asked to show.
#pragma once

#include <limits>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "valvediag/core/op_range.hpp"
#include "valvediag/diagnose/diagnosis.hpp"
#include "valvediag/io/loop_data.hpp"
#include "valvediag/sweep/loop_health.hpp"
#include "valvediag/sweep/quiet_lead_in.hpp"

namespace valvediag {

struct VerdictOptions {
  OpRange range;  // the valve's OP span, for % of travel
  // The climb's settings (held-out share, min gain, fit threads, whole-record options). Its
  // candidates are ignored (the verdict tries every effect) and valve_travel.op_range is set from
  // `range`. time_origin_s: the time the reason's times count from at the record's first sample
  // (0: seconds into the record, as a sweep gives them; the data's first time stamp: its own axis).
  DiagnoseOptions diagnose;
  std::size_t min_samples = 200;
  // Analyse the whole record even when OP holds still for most of it (quiet_lead_in.hpp).
  bool keep_lead_in = false;
  // Held-out shares at which the climb is run again to see whether the verdict holds (--split-
  // check); empty: none. The verdict itself stays the one at diagnose.validation_fraction.
  std::vector<double> check_splits;
};

// He's fs (the static friction band) and the slip jump fs - fd, in % of valve travel (the OP
// range), when the model has friction (Kano: S and J; Stenman and deadband: d); NaN otherwise.
struct FrictionSize {
  static constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
  double band_percent = kNaN, jump_percent = kNaN;
  // The band's (fs's) 95 % interval: a Preisach valve's refined figures' (StictionInterval), or
  // a friction effect's profile likelihood (NaN when not known).
  double band_lo_percent = kNaN, band_hi_percent = kNaN;
  // The data do not bound the band from above: band_hi_percent is the record's OP span, the
  // search's top, and the range reads "at least band_lo_percent".
  bool band_hi_open = false;
  // The friction refitted to the one-step prediction of PV (prediction_refit.hpp) in the climb's
  // step that added it, when that refit moved it and the finding ranked first: in closed loop
  // the simulated-output fit above can collapse a friction the prediction sees (NaN otherwise).
  double prediction_band_percent = kNaN, prediction_jump_percent = kNaN;
};

// The verdict of the same record scored on another held-out share (VerdictOptions::check_splits).
struct SplitVerdict {
  double validate = 0.0;
  std::string verdict;
};

struct LoopVerdict {
  // stiction, deadband, other-nonlinearity, no-valve-problem, not-enough-data; "error" when the
  // analysis itself failed (then `error` says why).
  std::string verdict;
  std::string reason;  // why the data is not enough, or what the verdict rests on
  std::string error;
  FrictionSize stiction;
  // The climb the verdict rests on (diagnose --auto from linear), on the record from
  // analysed_from_s on; no steps when the record was not judged (not-enough-data, error).
  Diagnosis diagnosis;
  std::string model;             // the climb's final model ("" when not judged)
  LoopHealth health;             // of the whole record
  QuietLeadIn lead_in;           // the lead-in left out, in samples of the record
  double analysed_from_s = 0.0;  // s after the record's first sample
  std::vector<SplitVerdict> split_verdicts;
  bool judged() const { return !diagnosis.steps.empty(); }
};

// Throws only for programming errors; bad or short data give not-enough-data with the reason.
LoopVerdict loop_verdict(const LoopData& d, const VerdictOptions& opt = {});

// The friction figures of a fitted model, in % of the valve's OP range; NaN when the model has no
// friction effect. `op`: the data's OP (the Preisach figures probe on it); `pv`: the output the
// model was fitted to (the Preisach figures are then refined on the data; empty: the probe's
// figures). `threads`: for the refinement (0: all cores). With `setting`, the sample period and
// options the model was fitted with, a friction effect's band gets its profile-likelihood
// interval too (band_interval, model_fit.hpp).
struct FitSetting {
  double Ts = 1.0;
  ModelFitOptions options;
};
FrictionSize friction_size(const ModelFit& fit, const std::vector<double>& op,
                           const std::vector<double>& pv, const OpRange& range = {},
                           int threads = 0, const std::optional<FitSetting>& setting = {});
// The same for a diagnosis's final model; when the verdict rests on a stick-slip limit cycle
// and the model has no friction effect, the band is the cycle's apparent stiction (the OP-PV
// ellipse's width, limit_cycle.hpp) and the jump is unknown (NaN).
FrictionSize friction_size(const Diagnosis& d, const std::vector<double>& op,
                           const std::vector<double>& pv, const OpRange& range = {},
                           int threads = 0, const std::optional<FitSetting>& setting = {});

// The verdicts of the record diagnosed again with each held-out share of `splits` (its lead-in
// already left out), the rest of `opt` as given: climbed from `start` with `climb`, else one
// diagnosis of `start`. A share that leaves too little to fit gives "error".
std::vector<SplitVerdict> split_verdicts(const LoopData& d, const DiagnoseOptions& opt,
                                         const std::vector<double>& splits, bool climb = true,
                                         const ModelSpec& start = {});

// How many of the shares give `verdict`, its own share included: {agree, of}. {1, 1} without a
// split check.
std::pair<int, int> split_agreement(const std::string& verdict,
                                    const std::vector<SplitVerdict>& splits);

// The quiet lead-in loop_verdict leaves out of d (none with opt.keep_lead_in): quiet_lead_in(),
// unless the part after it fails unusable_reason() while the whole record passes it
// (whole_usable: the caller's unusable_reason() of d was "").
QuietLeadIn lead_in_left_out(const LoopData& d, const VerdictOptions& opt, bool whole_usable);

}  // namespace valvediag
