// Terminal text and JSON of a diagnosis (diagnosis.hpp) and of a model ladder.
#pragma once

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "valvediag/diagnose/diagnosis.hpp"
#include "valvediag/report/model_history.hpp"

namespace valvediag {

// The loop's verdict (loop_verdict.hpp decides it) as shown beside a diagnosis, which need not
// be the analysis it rests on.
struct VerdictText {
  std::string verdict;  // the word, printed as given
  // Why the record cannot be judged (unusable_reason() in loop_health.hpp), "" when it can: the
  // verdict is then not-enough-data while the fits are still shown.
  std::string unusable;
  // What the verdict rests on when it is not the diagnosis shown (one sentence), else "".
  std::string basis;
};
std::string format_diagnosis(const Diagnosis& d, const std::vector<double>& t,
                             const VerdictText& verdict);
// `verdict` goes to the key "verdict", its unusable reason to "unusable_reason".
nlohmann::json diagnosis_json(const Diagnosis& d, const std::vector<double>& t,
                              const VerdictText& verdict);
// The limit-cycle test's figures (limit_cycle.hpp) as `diagnose --json` and the sweep write them,
// and back (missing keys keep their defaults).
nlohmann::json limit_cycle_json(const LimitCycle& c);
LimitCycle limit_cycle_from_json(const nlohmann::json& j);
// The whole-record test's figures (whole_record_test.hpp), likewise.
nlohmann::json whole_record_json(const WholeRecordTest& w);
WholeRecordTest whole_record_from_json(const nlohmann::json& j);
// The valve-travel test's figures (valve_travel.hpp), likewise.
nlohmann::json valve_travel_json(const ValveTravel& v);
ValveTravel valve_travel_from_json(const nlohmann::json& j);
std::string format_ladder(const std::vector<HistoryEntry>& entries);

// A fit of a composable model (fit --model/--add/--remove): summary and JSON.
std::string format_model_fit(const ModelFit& f, const ResidualAnalysis& where,
                             const std::vector<double>& t);
nlohmann::json model_fit_json(const ModelFit& f, const ResidualAnalysis& where,
                              const std::vector<double>& t);

}  // namespace valvediag
