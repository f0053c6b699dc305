// Which physical effect is missing from a loop model: residual evidence combined with trial fits
// scored on held-out data, ranked; and the automatic climb of the model ladder.
//
// For each candidate effect not in the model, a trial fit with it added is compared with the
// model on the validation part of the record (so a more flexible model cannot win by
// over-fitting), and on the estimation part: the smaller gain counts, relative to the error the
// model leaves. It is combined with the residual tests (residual_analysis.hpp) that point to the
// effect.
#pragma once

#include <functional>
#include <limits>
#include <string>
#include <vector>

#include "valvediag/diagnose/limit_cycle.hpp"
#include "valvediag/diagnose/residual_analysis.hpp"
#include "valvediag/diagnose/valve_travel.hpp"
#include "valvediag/diagnose/whole_record_test.hpp"
#include "valvediag/model/model_fit.hpp"
#include "valvediag/model/model_spec.hpp"

namespace valvediag {

struct Finding {
  std::string effect;                    // effect name (effects.md)
  double score = 0.0;                    // 0..1, how likely this effect is the missing one
  double validation_gain_percent = 0.0;  // fitness gained by the trial fit on validation data
  double estimation_gain_percent = 0.0;  // ... on estimation data
  double gain_percent = 0.0;             // the smaller of the two: what the score uses
  // A valve with memory: the trial's held_valve_validation_fitness() (NaN otherwise). Reported,
  // not scored: a stuck valve that does not slip in the held-out part holds PV as a compensated
  // load does (see held_valve_note).
  double held_valve_validation_fitness_percent = std::numeric_limits<double>::quiet_NaN();
  // One-step prediction of PV from the trial's valve position and dead time against the model's
  // (prediction_error.hpp, one ARX order for both): how much less error the trial leaves, % of
  // the model's RMS, on each part; and the change of BIC on the estimation part, the effect's
  // parameters counted (negative: the trial predicts PV better than its parameters cost).
  double prediction_estimation_gain_percent = std::numeric_limits<double>::quiet_NaN();
  double prediction_validation_gain_percent = std::numeric_limits<double>::quiet_NaN();
  double prediction_bic_change = std::numeric_limits<double>::quiet_NaN();
  // n ln(variance left by the trial / by the model) on the held-out part, n its samples: the
  // likelihood-ratio statistic there (an `integrator` is a restriction of the model's predictor,
  // held out unrefuted while this stays below the chi-square's 99 % point of one degree).
  double prediction_validation_deviance_change = std::numeric_limits<double>::quiet_NaN();
  // `integrator` only: the BIC of the predictor whose unit root is a drifting load's (A and B
  // both with the factor 1 - q^-1: PV's change driven by x's changes) less that of the
  // integrating one (x's level drives PV's change). Positive: the process integrates, not the
  // load.
  double prediction_drift_bic_change = std::numeric_limits<double>::quiet_NaN();
  // A valve effect's parameters refitted to that prediction (prediction_refit.hpp), which the
  // three figures above score; empty when the trial's own are scored (no refit).
  std::vector<NamedValue> prediction_parameters;
  // The gains as likelihoods (what the judge's errors, below, measure): the change of BIC on the
  // estimation part, 2 n ln(error left by the trial / by the model) + k ln n, and of the deviance
  // 2 n ln(...) on the held-out part, each n the model's effective residual samples on that part
  // (effective_sample_size: a slow error counts once) and k the free parameters the trial adds
  // (added_parameter_count).
  // Negative: the trial explains more than its parameters cost. NaN when a fit failed.
  double parameter_count = std::numeric_limits<double>::quiet_NaN();
  double output_bic_change = std::numeric_limits<double>::quiet_NaN();
  double validation_deviance_change = std::numeric_limits<double>::quiet_NaN();
  bool supported = false;                   // score and gain clear DiagnoseOptions' thresholds
  double evidence = 0.0;                    // strongest residual test pointing to it, 0..1
  std::string evidence_test;                // that test's name
  std::vector<NamedValue> parameters;       // the trial fit's parameters of the effect
  std::vector<ResidualInterval> intervals;  // where the model fails because of it
  std::vector<ResidualRegion> regions;      // operating regions that carry it
  std::string explanation;                  // one plain line an engineer can act on
  std::string indistinguishable_from;       // another effect that fits the data as well, if any
  ModelSpec trial_spec;
  double trial_fitness_percent = 0.0, trial_validation_fitness_percent = 0.0;
};

struct DiagnoseOptions {
  ModelFitOptions fit;  // validation_fraction defaults to 0.3 below when unset
  double validation_fraction = 0.3;
  std::vector<std::string> candidates;  // empty: every effect not in the model
  double min_gain_percent = 2.0;        // --auto: a step must gain this much (validation)
  double min_score = 0.35;              // --auto: and score at least this
  int max_steps = 4;                    // --auto: at most this many effects added
  // The whole-record test (whole_record_test.hpp) when the climb ends without memory: off, the
  // verdict rests on the held-out trial fits and the limit cycle alone.
  bool whole_record = true;
  WholeRecordOptions whole_record_options;
  // The valve-travel test, run when the valve position is given: its OP span (op_range)
  // turns friction into % of travel, so set it to the valve's OP range when OP is not 0..100.
  ValveTravelOptions valve_travel;
  // Called as the diagnosis goes: how far it got (0..1, rising) and what it is doing, e.g.
  // "step 2, trial models: 5 of 9 fitted". From the diagnosing thread and the fit workers, one
  // call at a time. (The workbench's job progress.)
  std::function<void(double fraction, const std::string& phase)> progress;
  // Time of the first sample, s: the conclusion names intervals at time_origin_s + k Ts (the
  // data's own time when a record was cut after a quiet lead-in, or its time axis starts late).
  double time_origin_s = 0.0;
};

// What a step's trial fits are judged on against its model. A self-regulating model: the
// simulated output (fitness on the estimation and the held-out part). An integrating one: its
// simulated output's error grows without bound from any rate error (measured: -534 % held out for
// the true model of an integrating loop, and gains of hundreds of points deciding rankings), so
// every fit of the step predicts the output `horizon` samples ahead from the measured output
// (MATLAB's compare(data, model, k)), with the output offset of each `interval` taken from the
// interval before, on the same samples. Finding's gains are then these fitnesses' gains; the
// simulated-output fitnesses stay reported.
struct KStepJudge {
  std::size_t horizon = 0;         // samples ahead; 0: the simulated output judges
  std::size_t interval = 0;        // the output offset's interval, samples
  std::size_t from = 0;            // the first sample with an interval of past
  std::size_t estimation_end = 0;  // the held-out part starts here
  double sample_period_s = 0.0;
  double model_fitness_percent = std::numeric_limits<double>::quiet_NaN();  // estimation part
  double model_validation_fitness_percent = std::numeric_limits<double>::quiet_NaN();
};

struct DiagnosisStep {
  ModelFit fit;                   // the model at this step
  ResidualAnalysis residual;      // where it fails
  std::vector<Finding> findings;  // ranked, most likely missing first
  KStepJudge judge;               // what the findings' gains measure
};

struct Diagnosis {
  std::vector<DiagnosisStep> steps;  // one without --auto; the climbed ladder with it
  // The climb's start: 1 when it went on from `integrator` because the first step had no stable
  // linear part or one only by force (ModelFit::forced_stable); the whole-record test measures
  // against that step.
  std::size_t start = 0;
  std::string conclusion;  // what is left (noise level, unexplained intervals)
  // The limit-cycle test (limit_cycle.hpp) with the first step's model: in an oscillating loop,
  // the evidence of a stick-slip cycle that trial fits can miss (a slip exactly at each OP
  // reversal leaves a fitted friction threshold no margin).
  LimitCycle limit_cycle;
  // The whole-record test (whole_record_test.hpp), run when neither the climb nor the limit
  // cycle found a valve with memory: a valve that slips once or twice in the record leaves the
  // held-out part too few slips to confirm its band.
  WholeRecordTest whole_record;
  // The valve-travel test (valve_travel.hpp), run by the overloads that take the recorded valve
  // position: the measured position outweighs what the closed-loop models suggest about friction.
  ValveTravel valve_travel;
  const DiagnosisStep& last() const { return steps.back(); }
};

// The model a verdict reads (verdict.hpp): the climbed ladder's final model; for a single step,
// its top finding's trial model when that finding is supported.
ModelSpec verdict_model(const Diagnosis& d);

// When part of a memory finding's held-out gain comes from holding the valve still rather than
// from predicted slips (Finding::held_valve_validation_fitness_percent): one sentence saying how
// much, for the reports; "" otherwise.
std::string held_valve_note(const Finding& f);

// What a step's gains measure, in one sentence for the reports: "" when the simulated output
// judges; otherwise the k-step judge's horizon and why.
std::string judge_note(const DiagnosisStep& s);

// The model-fit options every fit of a diagnosis uses (DiagnoseOptions::fit with its held-out
// share), for callers that re-examine its fits (band_interval).
ModelFitOptions fit_options(const DiagnoseOptions& opt);

// One diagnosis of `model` (the last step's findings rank the candidates).
Diagnosis diagnose(const std::vector<double>& u, const std::vector<double>& y, double Ts,
                   const ModelSpec& model, const DiagnoseOptions& opt = {});

// Climbs the ladder: adds the best supported effect while the validation error falls by a
// meaningful margin, then stops with a statement of what is left. When `start` has no stable
// linear part, the climb goes on from its `integrator` trial if that one is stable (a level).
Diagnosis diagnose_auto(const std::vector<double>& u, const std::vector<double>& y, double Ts,
                        const ModelSpec& start, const DiagnoseOptions& opt = {});

// The same for a loop whose valve position `mv` (same length as u) may be recorded: when mv is
// not empty, the valve-travel test reads friction from u -> mv with opt.valve_travel. One place
// for it, so that every caller passes the valve's OP range the same way.
Diagnosis diagnose(const std::vector<double>& u, const std::vector<double>& y,
                   const std::vector<double>& mv, double Ts, const ModelSpec& model,
                   const DiagnoseOptions& opt = {});
Diagnosis diagnose_auto(const std::vector<double>& u, const std::vector<double>& y,
                        const std::vector<double>& mv, double Ts, const ModelSpec& start,
                        const DiagnoseOptions& opt = {});

}  // namespace valvediag
