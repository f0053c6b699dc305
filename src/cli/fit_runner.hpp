// Runs an identification on loop data and formats it; shared by `fit` and `demo`.
#pragma once

#include <nlohmann/json.hpp>
#include <string>

#include "valvediag/core/identification.hpp"
#include "valvediag/core/op_range.hpp"
#include "valvediag/io/loop_data.hpp"

namespace valvediag::cli {

struct FitRun {
  IdentificationResult result;
  std::string summary;
  nlohmann::json json;
};

// output: "pv" (process) or "mv" (valve position). Checks the data before fitting. The
// stiction figures are in % of the valve's OP span `range`.
FitRun run_fit(const LoopData& d, const FitOptions& fo, const std::string& output,
               const OpRange& range = {});
void write_series(const std::string& path, const LoopData& d, const FitRun& run);

}  // namespace valvediag::cli
