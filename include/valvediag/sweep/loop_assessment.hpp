// One loop of a diagnostic sweep: is the record usable, how healthy is the loop, which model
// explains it (diagnose --auto from `linear`), the verdict, the stiction size, and a severity to
// rank loops by. No files, no bus: the sweep command feeds it LoopData. The verdict and the
// stiction size are the loop's one verdict (loop_verdict.hpp).
#pragma once

#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "valvediag/diagnose/diagnosis.hpp"
#include "valvediag/io/loop_data.hpp"
#include "valvediag/sweep/loop_health.hpp"
#include "valvediag/sweep/loop_verdict.hpp"
#include "valvediag/sweep/quiet_lead_in.hpp"

namespace valvediag {

// A sweep assesses a loop with exactly the verdict's options.
using AssessOptions = VerdictOptions;

struct LadderStep {
  std::string model;
  double fitness_percent = 0.0, validation_fitness_percent = 0.0;
};

struct LoopAssessment {
  static constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
  std::string loop;    // name (site config) or file stem
  std::string source;  // file, or database and window
  std::string tag;     // the loop's tag as the data names it (LoopData::tag); "" when it does not
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
  // The friction refitted to the one-step prediction that ranked it (FrictionSize; NaN: none).
  double prediction_stiction_percent = kNaN;
  std::string model;  // best model (top of the climbed ladder)
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

// The whole assessment of one record: loop_verdict() and the figures of the climb it rests on.
// Throws only for programming errors; bad or short data give verdict not-enough-data with the
// reason.
// `diagnosis`: receives the climbed ladder when one was run (for the loop's report); it covers
// the record from analysed_from_s on (drop_lead_in of the data with lead_in_left_out(d, opt)).
LoopAssessment assess_loop(const LoopData& d, const std::string& name,
                           const AssessOptions& opt = {}, Diagnosis* diagnosis = nullptr);

// Severity from verdict, stiction size and oscillation: stiction 6, deadband 5,
// other-nonlinearity 3, no-valve-problem 1, not-enough-data 0, error -1; + 1 when the loop
// oscillates (an unjudged loop too: in an OP-only sweep the cycling valves come first); + the
// stiction band in % of travel / 2, at most 3. A split check does not change it: measured, the
// memory verdicts it fails to repeat were as often true as false (README).
double severity(const LoopAssessment& a);

// How many of the held-out shares give the assessment's verdict (split_agreement in
// loop_verdict.hpp).
std::pair<int, int> split_agreement(const LoopAssessment& a);

// Highest severity first; ties by stiction size, then name.
void rank(std::vector<LoopAssessment>& loops);

}  // namespace valvediag
