#include "verdict_output.hpp"

#include <cmath>

#include "valvediag/report/json_number.hpp"
#include "valvediag/report/sweep_report.hpp"
#include "valvediag/util/text_stats.hpp"

namespace valvediag::cli {

VerdictOptions verdict_options(const OpRange& range, double validate, bool keep_lead_in, double t0,
                               double min_gain_percent) {
  VerdictOptions o;
  o.range = range;
  o.keep_lead_in = keep_lead_in;
  o.diagnose.validation_fraction = validate;
  o.diagnose.min_gain_percent = min_gain_percent;
  o.diagnose.time_origin_s = t0;
  return o;
}

std::string verdict_basis(const LoopVerdict& v) {
  if (v.verdict == "error") return "No verdict: " + v.error + ".";
  if (!v.judged()) return "";
  return "The loop's verdict rests on `diagnose --auto` from `linear`, as a sweep runs it, which "
         "ends at `" +
         v.model + "`.";
}

namespace {

// The size of the fitted friction (the final model's, the whole-record fit's or the cycle's).
std::string stiction_fit_text(const FrictionSize& f) {
  if (std::isfinite(f.band_percent) && std::isfinite(f.jump_percent)) {
    std::string s = strprintf("stiction:  %.2f %% of valve travel (He's fs), slip jump %.2f %%",
                              f.band_percent, f.jump_percent);
    if (std::isfinite(f.band_lo_percent) && f.band_hi_open)
      s += strprintf(
          "; the data fit fs %.2f %% or more as well (95 %%): they do not bound it from above, it "
          "fits up to the record's OP span, %.2f %%",
          f.band_lo_percent, f.band_hi_percent);
    else if (std::isfinite(f.band_lo_percent))
      s += strprintf("; the data fit fs %.2f-%.2f %% as well (95 %%)", f.band_lo_percent,
                     f.band_hi_percent);
    return s + "\n";
  }
  if (std::isfinite(f.band_percent))
    return strprintf("stiction:  %.2f %% of valve travel (apparent, from the limit cycle)\n",
                     f.band_percent);
  return "";
}

}  // namespace

std::string stiction_text(const FrictionSize& f) {
  std::string refit;
  if (std::isfinite(f.prediction_band_percent))
    refit = strprintf(
        "           refitted to predict PV one step ahead (what ranked it): %.2f %% of valve "
        "travel, slip jump %.2f %%\n",
        f.prediction_band_percent, f.prediction_jump_percent);
  return stiction_fit_text(f) + refit;
}

std::string verdict_text(const LoopVerdict& v, bool basis) {
  std::string s = "verdict:   " + v.verdict;
  if (v.verdict == "not-enough-data") s += ": " + v.reason;
  s += "\n";
  if (const std::string b = verdict_basis(v); basis && !b.empty()) s += "           " + b + "\n";
  return s + stiction_text(v.stiction);
}

void add_verdict_json(nlohmann::json& j, const LoopVerdict& v) {
  j["verdict"] = v.verdict;
  j["verdict_reason"] = v.verdict == "error" ? v.error : v.reason;
  j["verdict_model"] = v.model;
  j["stiction_percent"] = json_number(v.stiction.band_percent);
  j["slip_jump_percent"] = json_number(v.stiction.jump_percent);
  j["stiction_lo_percent"] = json_number(v.stiction.band_lo_percent);
  j["stiction_hi_percent"] = json_number(v.stiction.band_hi_percent);
  j["stiction_hi_open"] = v.stiction.band_hi_open;
  j["prediction_stiction_percent"] = json_number(v.stiction.prediction_band_percent);
  j["prediction_slip_jump_percent"] = json_number(v.stiction.prediction_jump_percent);
  j["split_check"] = split_check_json(v.split_verdicts);
}

}  // namespace valvediag::cli
