// The workbench's models of one loop: the ladder built in this session (each fit kept in memory,
// its row appended to the loop's model history file when it has one), the latest diagnosis and
// the job requests that grow them. The work calls the functions the CLI calls: fit_model (fit
// --model), add_effect/remove_effect (fit --add/--remove), diagnose/diagnose_auto (diagnose),
// history_entry (the numbers `ladder` prints), model_fit_json (fit --json) and html_report
// (report).
#pragma once

#include <functional>
#include <memory>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "valvediag/core/op_range.hpp"
#include "valvediag/diagnose/diagnosis.hpp"
#include "valvediag/io/loop_data.hpp"
#include "valvediag/model/model_fit.hpp"
#include "valvediag/report/model_history.hpp"
#include "valvediag/serve/jobs.hpp"

namespace valvediag::serve {

// Options of every fit and diagnosis of the session: diagnose's.
struct ModelOptions {
  double validate = 0.3;  // held-out share (diagnose --validate)
  double min_gain = 2.0;  // diagnose --min-gain
  OpRange range;          // --op-range
  int threads = 0;        // of each fit (ModelFitOptions::threads); 0: all cores
  ModelFitOptions fit_options() const;
  // The first held-out sample of n samples, by fit_model's rule for validation_fraction.
  std::size_t estimation_end(std::size_t n) const;
  DiagnoseOptions diagnose_options(const LoopData& d) const;
};

// Models a loop's ladder holds at most: each keeps its simulated series, and memory stays bounded
// however often a client adds. A job on a full ladder fails and says so.
inline constexpr std::size_t kMaxLadderSteps = 100;

struct ModelStep {
  std::string action;  // how it came: "fit", "add stiction", "remove deadband", "diagnose"
  // The data it was fitted to: the loop's analysed part, or its latest seconds (a job's last_s;
  // a live loop's data as it was then). Its fit's series and indices are of these samples.
  std::shared_ptr<const LoopData> data;
  double validate = 0.3;  // the held-out share of the fit
  ModelFit fit;
  ResidualAnalysis where;  // where it fails, on the estimation part
  HistoryEntry entry;      // its row of the ladder
};

// What a client asked of a job (POST /api/loops/{id}/jobs).
struct JobRequest {
  std::string action;              // fit, add, remove, diagnose
  std::string model;               // fit: the spec
  std::string effect;              // add, remove: the effect ("stiction", "deadband:...")
  bool climb = false;              // diagnose: climb the ladder (diagnose --auto)
  std::optional<double> validate;  // the held-out share; nullopt: the server's (--validate)
  std::optional<double> last_s;    // fit the latest this many seconds only; nullopt: all
  nlohmann::json info() const;
};
// The held-out shares a job may ask for: the page's split can be dragged within them.
inline constexpr double kMinJobValidate = 0.05, kMaxJobValidate = 0.6;
// Throws std::invalid_argument naming what is wrong (unknown action or key, a bad model or effect
// name, a missing field, a validate outside kMinJobValidate..kMaxJobValidate, a last_s not a
// positive number of seconds).
JobRequest parse_job_request(const nlohmann::json& body);

class LoopModels {
 public:
  // history_file: the loop's model history (model_history.hpp), to which each model the jobs add
  // to the ladder is appended, as fit and diagnose append theirs, so that `valvediag ladder`
  // lists them; "" writes none.
  explicit LoopModels(std::string history_file = "");
  // The models go to `writer` instead (a recording's table); empty: none.
  explicit LoopModels(std::function<nlohmann::json(const std::vector<HistoryEntry>&)> writer)
      : writer_(std::move(writer)) {}
  // Adds the entries to the history; the job's "history": null without one.
  nlohmann::json record_history(const std::vector<HistoryEntry>& entries) const;
  std::vector<std::shared_ptr<const ModelStep>> steps() const;
  std::shared_ptr<const ModelStep> step(std::size_t n) const;  // nullptr: no such step
  std::shared_ptr<const ModelStep> last() const;               // nullptr: none yet
  void push(std::shared_ptr<const ModelStep> s);
  struct Diagnosed {
    std::shared_ptr<const Diagnosis> diagnosis;
    nlohmann::json json;                   // diagnose --json's keys (diagnosis_json)
    std::shared_ptr<const LoopData> data;  // the data diagnosed
  };
  std::optional<Diagnosed> diagnosis() const;
  void set_diagnosis(Diagnosed d);

 private:
  std::function<nlohmann::json(const std::vector<HistoryEntry>&)> writer_;
  mutable std::mutex m_;
  std::vector<std::shared_ptr<const ModelStep>> steps_;
  std::optional<Diagnosed> diagnosis_;
};

// Runs a request on the loop `d` (the part diagnose analyses; with the request's last_s, its
// latest seconds), grows `models`, appends the new models to its history when it has one, and
// returns the job's result (with "history": {"entries": N in the file}, or {"error": why} when
// the file could not be written: the models stand without it; null without a history file or a
// new model; "data": the samples fitted, "validate": the held-out share). Checks `control` for
// cancellation; throws Cancelled, or std::invalid_argument when the model cannot be fitted or the
// ladder is full (max_steps models).
nlohmann::json run_job(const JobRequest& req, std::shared_ptr<const LoopData> d, LoopModels& models,
                       const ModelOptions& opt, JobControl& control,
                       std::size_t max_steps = kMaxLadderSteps);
nlohmann::json run_job(const JobRequest& req, const LoopData& d, LoopModels& models,
                       const ModelOptions& opt, JobControl& control,
                       std::size_t max_steps = kMaxLadderSteps);
// The samples of `d` in its latest `seconds` (t >= last t - seconds); all of it when it spans
// less.
LoopData latest_part(const LoopData& d, double seconds);

// GET /api/loops/{id}/ladder: each step's model and fitness, as `valvediag ladder` prints them,
// with the time span of the data it was fitted to.
nlohmann::json ladder_json(const LoopModels& models);
// GET /api/loops/{id}/models/{n}: `fit --json`'s document of the step.
nlohmann::json model_json(const ModelStep& s, const LoopData& d);
// PV, the step's simulated PV and the residual, as the series' min/max buckets.
nlohmann::json simulation_json(const ModelStep& s, const LoopData& d, double from, double to,
                               int buckets);
// A valve effect in the model (stiction, deadband, preisach, saturation, characteristic,
// actuator-lag): its valve position x_hat differs from OP, and it has a signature.
bool has_valve_effect(const ModelSpec& spec);
// The valve signature: the step's valve position (x_hat) against OP, decimated_path()'s columns
// "op" and "x" with the held-out samples flagged, the model, estimation_end_s and x_in_op_units
// (false for preisach, whose x_hat is scaled to ||b|| = 1). Throws std::invalid_argument when
// no sample lies in [from, to].
nlohmann::json signature_json(const ModelStep& s, const LoopData& d, double from, double to,
                              int points);
// The HTML report of the current model (the last step) on its data, as `valvediag report` writes
// it; its diagnosis when the latest one is of that model. Throws std::invalid_argument without a
// model.
std::string report_html(const LoopModels& models, const std::string& name,
                        const std::string& verdict);

}  // namespace valvediag::serve
