// Turns an identification result into what people and scripts read: a terminal summary, JSON,
// and the per-sample series. Formatting only; the CLI decides where it goes.
#pragma once

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "valvediag/identification.hpp"
#include "valvediag/loop_data.hpp"
#include "valvediag/residual_analysis.hpp"

namespace valvediag {

struct FitContext {
  std::string data_name;
  std::size_t samples = 0;
  double sample_period = 0.0;
  std::string output_name = "pv";              // "pv" or "mv"
  std::string method;                          // "joint" or "alternation"
  const std::vector<double>* time = nullptr;   // time stamps, s (for intervals)
  const ResidualAnalysis* residual = nullptr;  // where the model fails (estimation window)
};

const char* method_name(FitMethod m);

// Per-sample series of the fitted model: x_hat, pv_sim (simulated output) and residual.
struct FitSeries {
  std::vector<double> x_hat, y_sim, residual;
};
FitSeries fit_series(const IdentificationResult& r, const std::vector<double>& u,
                     const std::vector<double>& y);

// Residual analysis of the fitted model on its estimation window.
ResidualAnalysis analyse_fit(const IdentificationResult& r, const std::vector<double>& u,
                             const std::vector<double>& y, const FitSeries& s);

std::string format_summary(const IdentificationResult& r, const FitContext& ctx);
nlohmann::json to_json(const IdentificationResult& r, const FitContext& ctx);

}  // namespace valvediag
