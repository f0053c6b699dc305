// A sweep's results for people and scripts: the plant summary ranked by severity (terminal
// table), CSV, JSON (also the results file a shard writes and sweep-merge reads), and an HTML
// index linking each loop's report.
#pragma once

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "valvediag/sweep/loop_assessment.hpp"

namespace valvediag {

struct SweepInfo {
  std::string started_utc, finished_utc;
  std::string source;  // site config and database, or "files"
  std::string shard;   // "I/N" or ""
  double window_s = 0;
  double validation_fraction = 0.3;  // of each record held out for scoring (sweep --validate)
  double elapsed_s = 0;
};

// The split check's extra verdicts as JSON: [{"validate": share, "verdict": ...}, ...].
nlohmann::json split_check_json(const std::vector<SplitVerdict>& splits);

nlohmann::json assessment_json(const LoopAssessment& a);
// Throws std::runtime_error naming the missing or mistyped key.
LoopAssessment assessment_from_json(const nlohmann::json& j);

nlohmann::json sweep_json(const SweepInfo& info, const std::vector<LoopAssessment>& loops);
// Reads a results file's JSON (sweep_json); throws std::runtime_error naming what is wrong.
std::vector<LoopAssessment> sweep_loops_from_json(const nlohmann::json& j);

// "2/3": the held-out shares that give the loop's verdict (split_agreement); "-" without a
// split check.
std::string split_agreement_text(const LoopAssessment& a);

// The ranked plant summary (loops in the given order) and a count per verdict.
std::string format_sweep_table(const std::vector<LoopAssessment>& loops);
std::string sweep_csv(const std::vector<LoopAssessment>& loops);
// `report_links[i]`: relative path of loop i's report, or "" for none.
std::string sweep_html(const SweepInfo& info, const std::vector<LoopAssessment>& loops,
                       const std::vector<std::string>& report_links);

}  // namespace valvediag
