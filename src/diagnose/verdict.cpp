// The verdict a plant engineer wants first, from a diagnosis or from a recorded loop.
#include "valvediag/verdict.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <exception>
#include <stdexcept>

#include "valvediag/identifiability.hpp"
#include "valvediag/model_fit.hpp"
#include "valvediag/text_stats.hpp"

namespace valvediag {

namespace {
std::string model_verdict(const Diagnosis& d);
}

std::string verdict(const Diagnosis& d) {
  const std::string from_model = model_verdict(d);
  const ValveTravel& t = d.valve_travel;
  if (!t.decided) return from_model;
  // The measured position shows the friction itself; when it shows none, a memory the closed-loop
  // models found lies outside the valve, and a static curve (flow against travel) may still hold.
  if (t.verdict == "stiction" || t.verdict == "deadband") return t.verdict;
  return from_model == "stiction" || from_model == "deadband" ? "no-valve-problem" : from_model;
}

namespace {
std::string model_verdict(const Diagnosis& d) {
  // The valve part of the final model (the climbed ladder), or the top supported finding.
  ModelSpec m = d.last().fit.spec;
  if (d.steps.size() == 1 && !d.last().findings.empty()) {
    const auto& f = d.last().findings.front();
    if (f.supported) m = f.trial_spec;
  }
  if (m.has("stiction") || m.has("preisach")) return "stiction";
  if (m.has("deadband")) return "deadband";
  // A stick-slip limit cycle outweighs a static nonlinearity or none: in a sustained cycle the
  // valve slips at each OP reversal, which leaves a fitted friction threshold no margin, while
  // a static curve cannot make the loop cycle by itself.
  if (d.limit_cycle.stick_slip) return "stiction";
  // A valve with memory that explains the whole record better than any memoryless model and a
  // load (whole_record_test.hpp) outweighs a static nonlinearity the held-out fits preferred.
  if (d.whole_record.confirmed) {
    const auto& e = d.whole_record.memory_effects;
    const bool backlash = !e.empty() && e.front().name == "deadband";
    return backlash ? "deadband" : "stiction";
  }
  if (m.has("saturation") || m.has("characteristic") || m.has("actuator-lag"))
    return "other-nonlinearity";
  return "no-valve-problem";
}
}  // namespace

namespace {

double param(const std::vector<FittedEffect>& effects, const char* effect, const char* name) {
  for (const auto& e : effects)
    if (e.name == effect)
      for (const auto& p : e.parameters)
        if (p.name == name) return p.value;
  return std::nan("");
}

bool is_hysteresis(const std::string& effect) {
  return effect == "stiction" || effect == "preisach" || effect == "deadband";
}

LoopVerdict not_enough(LoopVerdict v, std::string why) {
  v.verdict = "not-enough-data";
  v.reason = std::move(why);
  return v;
}

// Step 4: no hysteresis evidence. Another valve nonlinearity when the diagnosis supports one.
std::string without_hysteresis(const VerdictFigures& f, std::string* reason,
                               const std::string& why) {
  if (f.finding_supported && !is_hysteresis(f.finding) &&
      (f.finding == "saturation" || f.finding == "characteristic" || f.finding == "actuator-lag")) {
    if (reason)
      *reason = why + "; the diagnosis supports `" + f.finding + "` (" +
                strprintf("%+.1f", f.finding_gain) + " points on estimation and held-out data)";
    return "other-nonlinearity";
  }
  if (reason) {
    *reason = why;
    if (f.finding_supported && is_hysteresis(f.finding))
      *reason += "; the diagnosis's `" + f.finding + "` (" + strprintf("%+.1f", f.finding_gain) +
                 " points) is not confirmed on the whole record";
  }
  return "no-valve-problem";
}

}  // namespace

std::string decide_verdict(const VerdictFigures& f, const VerdictOptions& opt,
                           std::string* reason) {
  const bool gain_ok = f.hysteresis_gain >= opt.min_gain_points;
  const bool rel_ok = f.relative_gain >= opt.min_relative_gain;
  if (!(gain_ok && rel_ok))
    return without_hysteresis(
        f, reason,
        "no valve model with memory explains the record clearly better than the linear one (" +
            (f.hysteresis_model.empty() ? std::string("none") : f.hysteresis_model) +
            strprintf(": %+.1f points, %.0f %% of the error linear leaves)", f.hysteresis_gain,
                      100 * f.relative_gain));
  if (std::isnan(f.hysteresis_validation_gain) == false &&
      !(f.hysteresis_validation_gain >= opt.min_validation_gain))
    return without_hysteresis(
        f, reason,
        "a valve model with memory (" + f.hysteresis_model +
            strprintf(") fits the whole record better (%+.1f points) but loses on held-out data "
                      "(%+.1f points): not confirmed",
                      f.hysteresis_gain, f.hysteresis_validation_gain));
  if (!(f.band >= opt.min_band_noise * f.op_noise))
    return without_hysteresis(
        f, reason,
        strprintf(
            "a model with memory fits better (%+.1f points) but the stiction band it implies, "
            "%.2f %% of travel, lies within the OP noise (%.3f %%)",
            f.hysteresis_gain, f.band, f.op_noise));
  const double best_hyst = std::max(f.stiction_fitness, f.preisach_fitness);
  if (f.jump < opt.deadband_jump_fraction * f.band &&
      f.deadband_fitness >= best_hyst - opt.deadband_fit_points) {
    if (reason)
      *reason = strprintf(
          "the valve lags OP by a band of %.2f %% of travel after each reversal, without a slip "
          "jump (deadband fits within %.1f points of the best model with memory, %+.1f points "
          "over linear)",
          f.band, best_hyst - f.deadband_fitness, f.hysteresis_gain);
    return "deadband";
  }
  if (reason)
    *reason = "a valve with memory (" + f.hysteresis_model +
              strprintf(
                  ") explains %.0f %% of the error the linear model leaves (%+.1f points); "
                  "He's fit: OP travels %.2f %% of travel after a reversal before the valve "
                  "moves, ",
                  100 * f.relative_gain, f.hysteresis_gain, f.band) +
              strprintf("then it jumps %.2f %% (fs %.2f, fd %.2f)", f.jump, f.fs, f.fd);
  return "stiction";
}

LoopVerdict loop_verdict(const LoopData& d, const VerdictOptions& opt) {
  return loop_verdict(d.op, d.pv, d.sample_period(), opt);
}

LoopVerdict loop_verdict(const std::vector<double>& u, const std::vector<double>& y, double Ts,
                         const VerdictOptions& opt) {
  LoopVerdict v;
  VerdictFigures& f = v.figures;
  const std::size_t N = std::min(u.size(), y.size());
  f.samples = N;
  const double span = opt.op_max - opt.op_min;
  if (u.size() != y.size()) return not_enough(v, "OP and PV differ in length");
  if (!(Ts > 0) || !(span > 0)) return not_enough(v, "no valid sample period or OP span");
  if (N < opt.min_samples)
    return not_enough(v, strprintf("%.0f samples; at least %.0f are needed", static_cast<double>(N),
                                   static_cast<double>(opt.min_samples)));
  for (std::size_t t = 0; t < N; ++t)
    if (!std::isfinite(u[t]) || !std::isfinite(y[t]))
      return not_enough(v, strprintf("a non-finite sample at index %.0f", static_cast<double>(t)));
  const auto [ylo, yhi] = std::minmax_element(y.begin(), y.end());
  if (!(*yhi > *ylo)) return not_enough(v, "PV is constant: a dead measurement");
  const auto [ulo, uhi] = std::minmax_element(u.begin(), u.end());
  if (!(*uhi > *ulo)) return not_enough(v, "OP is constant: the valve was not moved");

  std::size_t at_end = 0;
  const double margin = opt.saturation_margin * span / 100.0;
  for (double x : u) at_end += x <= opt.op_min + margin || x >= opt.op_max - margin;
  f.saturated = static_cast<double>(at_end) / static_cast<double>(N);
  std::vector<double> du(N - 1);
  for (std::size_t t = 1; t < N; ++t) du[t - 1] = std::abs(u[t] - u[t - 1]);
  // Robust sigma of white OP noise from its increments: median |N(0, 2 s^2)| = 0.954 s.
  f.op_noise = quantile(du, 0.5) / 0.954 * 100.0 / span;
  f.op_range = (quantile(u, 0.95) - quantile(u, 0.05)) * 100.0 / span;
  if (f.saturated >= opt.saturated_fraction)
    return not_enough(v,
                      strprintf("OP is at an end of its span in %.0f %% of the samples (saturated)",
                                100 * f.saturated));
  if (!(f.op_range > opt.min_op_range_noise * f.op_noise))
    return not_enough(v, strprintf("OP moves %.3f %% of travel (5-95 %%), no more than its noise "
                                   "(%.3f %%): the valve was not exercised",
                                   f.op_range, f.op_noise));
  const Identifiability id = analyse_identifiability(PreisachGrid{*ulo, *uhi, 10}, u);
  f.op_reversals = id.reversals;
  if (id.kind == ExcitationKind::Insufficient || id.reversals < opt.min_reversals)
    return not_enough(v, "not identifiable: " + id.summary);

  // Whole-record fits, memoryless and with memory.
  ModelFitOptions fo = opt.fit;
  fo.validation_fraction = 0.0;
  fo.validation_start = 0;
  const char* names[] = {"linear",   "saturation", "characteristic",
                         "stiction", "preisach",   "deadband"};
  std::vector<ModelSpec> specs;
  for (const char* n : names) specs.push_back(parse_model_spec(n));
  std::vector<ModelFit> fits;
  try {
    fits = fit_models(u, y, Ts, specs, fo);
  } catch (const std::invalid_argument& e) {
    return not_enough(v, std::string("the model cannot be fitted: ") + e.what());
  }
  auto fit_of = [&](std::size_t i) {
    const double x = fits[i].fitness_percent;
    return std::isfinite(x) ? x : std::nan("");
  };
  f.linear_fitness = fit_of(0);
  f.saturation_fitness = fit_of(1);
  f.characteristic_fitness = fit_of(2);
  f.stiction_fitness = fit_of(3);
  f.preisach_fitness = fit_of(4);
  f.deadband_fitness = fit_of(5);
  // No stable model counts as predicting the mean (fitness 0).
  double memoryless = 0.0, hysteresis = 0.0;
  f.memoryless_model = "mean";
  for (std::size_t i : {0u, 1u, 2u})
    if (fit_of(i) > memoryless) {
      memoryless = fit_of(i);
      f.memoryless_model = names[i];
    }
  for (std::size_t i : {3u, 4u})
    if (fit_of(i) > hysteresis) {
      hysteresis = fit_of(i);
      f.hysteresis_model = names[i];
    }
  const double linear = std::isfinite(f.linear_fitness) ? std::max(f.linear_fitness, 0.0) : 0.0;
  f.hysteresis_gain = hysteresis - linear;
  f.relative_gain = f.hysteresis_gain / std::max(100.0 - linear, 1.0);
  const double scale = 100.0 / span;
  f.fs = param(fits[3].effects, "stiction", "fs") * scale;
  f.fd = param(fits[3].effects, "stiction", "fd") * scale;
  f.band = f.fs + f.fd;
  f.jump = f.fs - f.fd;

  if (opt.run_diagnosis) {
    try {
      // Its own whole-record fits decide here: the diagnosis's whole-record test is not needed.
      DiagnoseOptions dopt = opt.diagnose;
      dopt.whole_record = false;
      v.diagnosis = diagnose(u, y, Ts, parse_model_spec("linear"), dopt);
      const auto& fl = v.diagnosis.last().findings;
      if (!fl.empty()) {
        f.finding = fl.front().effect;
        f.finding_supported = fl.front().supported;
        f.finding_gain = fl.front().gain_percent;
      }
      for (const auto& x : fl)
        if (is_hysteresis(x.effect) && std::isfinite(x.validation_gain_percent) &&
            !(x.validation_gain_percent <= f.hysteresis_validation_gain))
          f.hysteresis_validation_gain = x.validation_gain_percent;
    } catch (const std::exception&) {
      // The diagnosis needs a held-out part and a stable linear model; without it, step 4 has
      // no finding and the whole-record evidence decides alone.
      v.diagnosis = Diagnosis{};
    }
  }
  v.verdict = decide_verdict(f, opt, &v.reason);
  return v;
}

}  // namespace valvediag
