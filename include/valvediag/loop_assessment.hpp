// One loop of a diagnostic sweep: is the record usable, how healthy is the loop, which model
// explains it (diagnose --auto from `linear`), the verdict, the stiction size, and a severity to
// rank loops by. No files, no bus: the sweep command feeds it LoopData.
#pragma once

#include <limits>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "valvediag/diagnosis.hpp"
#include "valvediag/loop_data.hpp"
#include "valvediag/loop_health.hpp"
#include "valvediag/quiet_lead_in.hpp"

namespace valvediag {

struct AssessOptions {
  OpRange range;  // the valve's OP span (site config), for % of travel
  // The --auto climb from `linear`; its valve_travel.op_range is set from `range`, which is the
  // one span a sweep holds.
  DiagnoseOptions diagnose;
  std::size_t min_samples = 200;
  // Analyse the whole record even when OP holds still for most of it (quiet_lead_in.hpp).
  bool keep_lead_in = false;
  // Held-out shares at which the climb is run again to see whether the verdict holds (sweep
  // --split-check); empty: none. The verdict itself stays the one at diagnose.validation_fraction.
  std::vector<double> check_splits;
};

struct LadderStep {
  std::string model;
  double fitness_percent = 0.0, validation_fitness_percent = 0.0;
};

// The verdict of the same record scored on another held-out share (AssessOptions::check_splits).
struct SplitVerdict {
  double validate = 0.0;
  std::string verdict;
};

struct LoopAssessment {
  static constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
  std::string loop;    // name (site config) or file stem
  std::string source;  // file, or database and window
  // stiction, deadband, other-nonlinearity, no-valve-problem, not-enough-data; "error" when the
  // analysis itself failed (then `error` says why).
  std::string verdict;
  std::string reason;  // why the data is not enough, or what the verdict rests on
  // He's fs (the static friction band) and the slip jump fs - fd, in % of valve travel (the OP
  // range), when the model has friction (Kano: S and J; Stenman and deadband: d).
  double stiction_percent = kNaN, slip_jump_percent = kNaN;
  // The range of fs the data fit as well (95 % profile likelihood, stiction_quantification.hpp),
  // when the size comes from a Preisach valve's refined figures; NaN otherwise.
  double stiction_lo_percent = kNaN, stiction_hi_percent = kNaN;
  bool stiction_hi_open = false;  // hi is the record's OP span: the data do not bound fs above
  std::string model;              // best model (top of the climbed ladder)
  double fitness_percent = kNaN, validation_fitness_percent = kNaN;
  std::string first_missing;  // the effect the linear model misses first ("" when none)
  std::vector<LadderStep> ladder;
  LoopHealth health;
  LimitCycle limit_cycle;        // the diagnosis's limit-cycle test (not run: not oscillating)
  WholeRecordTest whole_record;  // the diagnosis's whole-record test (not run: not needed)
  ValveTravel valve_travel;      // the valve-travel test (not run: MV not recorded)
  // The verdicts at the other held-out shares, when asked for and the record was judged. A
  // verdict one of them does not repeat rests on where the record was split: read it with care.
  std::vector<SplitVerdict> split_verdicts;
  double severity = 0.0;  // ranking key, higher first (see assess_loop)
  double elapsed_s = 0.0;
  // Where the diagnosis started, s after the record's first sample: > 0 when a quiet lead-in
  // was left out (quiet_lead_in.hpp); the loop-health figures cover the whole record.
  double analysed_from_s = 0.0;
  QuietLeadIn lead_in;  // the lead-in left out, in samples of the record (not in the JSON)
  std::string error;    // the analysis failed: exception text, timeout, crash
  std::string report;   // the loop's HTML report, when one was written
};

// The whole assessment of one record. Throws only for programming errors; bad or short data
// give verdict not-enough-data with the reason.
// `diagnosis`: receives the climbed ladder when one was run (for the loop's report); it covers
// the record from analysed_from_s on (drop_lead_in of the data with lead_in_left_out(d, opt)).
LoopAssessment assess_loop(const LoopData& d, const std::string& name,
                           const AssessOptions& opt = {}, Diagnosis* diagnosis = nullptr);

// He's fs and the slip jump of a fitted model's friction, in % of the valve's OP range; NaN when
// the model has no friction effect. `op`: the data's OP (the Preisach figures probe on it);
// `pv`: the output the model was fitted to (the Preisach figures are then refined on the data;
// empty: the probe's figures). `threads`: for the refinement (0: all cores). With `setting`, the
// sample period and options the model was fitted with, a friction effect's band gets its
// profile-likelihood interval too (band_interval, model_fit.hpp).
struct FrictionSize {
  double band_percent = LoopAssessment::kNaN, jump_percent = LoopAssessment::kNaN;
  // The band's (fs's) 95 % interval: a Preisach valve's refined figures' (StictionInterval), or
  // a friction effect's profile likelihood (NaN when not known).
  double band_lo_percent = LoopAssessment::kNaN, band_hi_percent = LoopAssessment::kNaN;
  // The data do not bound the band from above: band_hi_percent is the record's OP span, the
  // search's top, and the range reads "at least band_lo_percent".
  bool band_hi_open = false;
};
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

// Severity from verdict, stiction size and oscillation: stiction 6, deadband 5,
// other-nonlinearity 3, no-valve-problem 1, not-enough-data 0, error -1; + 1 when the loop
// oscillates (an unjudged loop too: in an OP-only sweep the cycling valves come first); + the
// stiction band in % of travel / 2, at most 3. A split check does not change it: measured, the
// memory verdicts it fails to repeat were as often true as false (README).
double severity(const LoopAssessment& a);

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
// The same for an assessment's verdict.
std::pair<int, int> split_agreement(const LoopAssessment& a);

// The quiet lead-in assess_loop leaves out of d (none with opt.keep_lead_in): quiet_lead_in(),
// unless the part after it fails unusable_reason() while the whole record passes it
// (whole_usable: the caller's unusable_reason() of d was "").
QuietLeadIn lead_in_left_out(const LoopData& d, const AssessOptions& opt, bool whole_usable);

// Highest severity first; ties by stiction size, then name.
void rank(std::vector<LoopAssessment>& loops);

}  // namespace valvediag
