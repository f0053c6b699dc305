// Turns an identification result into what people and scripts read: a terminal summary, JSON,
// and the per-sample series. Formatting only; the CLI decides where it goes.
#pragma once

#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "valvediag/core/identification.hpp"
#include "valvediag/core/stiction_quantification.hpp"
#include "valvediag/diagnose/residual_analysis.hpp"
#include "valvediag/io/loop_data.hpp"

namespace valvediag {

struct FitContext {
  std::string data_name;
  std::size_t samples = 0;
  double sample_period = 0.0;
  std::string output_name = "pv";              // "pv" or "mv"
  std::string method;                          // "joint" or "alternation"
  const std::vector<double>* time = nullptr;   // time stamps, s (for intervals)
  const ResidualAnalysis* residual = nullptr;  // where the model fails (estimation window)
  // The OP the model was fitted on: the stiction figures then probe the identified valve with the
  // data's own OP over its estimation window (include/valvediag/core/stiction_quantification.hpp);
  // without it, with reversal curves over the whole Preisach grid (region support unknown).
  const std::vector<double>* op = nullptr;
  // With op: the output the model was fitted to (pv, or mv for a valve-position fit); the
  // figures are then refined on the data (He's valve + linear part fitted to op, pv).
  const std::vector<double>* pv = nullptr;
  // Figures computed once by the caller (the refinement takes seconds); else computed here.
  std::optional<StictionQuantification> stiction;
  int threads = 0;  // for the refinement (0: all cores)
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

// The summary has a `stiction:` line (He's fs and fd from the Preisach model, per OP region), the
// JSON a "stiction" object {fs_percent, fd_percent, band_percent, jump_percent, ..., regions}.
std::string format_summary(const IdentificationResult& r, const FitContext& ctx);
nlohmann::json to_json(const IdentificationResult& r, const FitContext& ctx);

// The stiction figures of a fit (estimation window of ctx.op when given).
StictionQuantification fit_stiction(const IdentificationResult& r, const FitContext& ctx);

}  // namespace valvediag
