#include "valvediag/diagnosis.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>

namespace valvediag {

namespace {

std::string fmt(const char* f, double a = 0, double b = 0, double c = 0) {
  char buf[256];
  std::snprintf(buf, sizeof buf, f, a, b, c);
  return buf;
}

double param(const std::vector<NamedValue>& p, const char* name, double fallback = std::nan("")) {
  for (const auto& v : p)
    if (v.name == name) return v.value;
  return fallback;
}

ModelFitOptions fit_options(const DiagnoseOptions& opt) {
  ModelFitOptions fo = opt.fit;
  if (fo.validation_fraction <= 0 && fo.validation_start == 0)
    fo.validation_fraction = opt.validation_fraction;
  return fo;
}

// One plain line an engineer can act on, with the trial fit's figures.
std::string explain(const std::string& effect, const ModelFit& trial,
                    const std::vector<NamedValue>& p) {
  const double Ts = 1.0;
  (void)Ts;
  if (effect == "stiction") {
    const double fs = param(p, "fs"), fd = param(p, "fd");
    if (std::isfinite(fs))
      return fmt(
          "valve sticks: OP must travel about %.1f %% after a reversal before it moves, then it "
          "jumps about "
          "%.1f %%: add `stiction`",
          fs, std::isfinite(fd) ? fs - fd : 0.0);
    return "valve sticks after reversals and then jumps: add `stiction`";
  }
  if (effect == "deadband") {
    const double d = param(p, "d");
    return std::isfinite(d) ? fmt("play in the valve linkage: OP must travel about %.1f %% after a "
                                  "reversal before "
                                  "the valve follows, without a jump: add `deadband`",
                                  d)
                            : "play in the valve linkage after reversals: add `deadband`";
  }
  if (effect == "preisach")
    return "friction depends on the valve position or the direction of travel (asymmetric "
           "hysteresis); a "
           "two-parameter stiction model is not enough: add `preisach`";
  if (effect == "saturation") {
    const double lo = param(p, "lower"), hi = param(p, "upper");
    return fmt(
        "the valve stops responding beyond its travel limits (about %.1f .. %.1f %% of OP): add "
        "`saturation`",
        lo, hi);
  }
  if (effect == "characteristic") {
    const double r = param(p, "R");
    return std::isfinite(r)
               ? fmt("the process gain changes with the valve opening (installed characteristic, "
                     "rangeability about %.0f): add `characteristic`",
                     r)
               : "the process gain changes with the valve opening: add `characteristic`";
  }
  if (effect == "actuator-lag") {
    const double tau = param(p, "tau");
    return std::isfinite(tau)
               ? fmt("the actuator follows OP with a lag of about %.1f s: check the positioner and "
                     "supply air; add `actuator-lag`",
                     tau)
               : "the actuator follows OP with a lag: add `actuator-lag`";
  }
  if (effect == "delay")
    return fmt("the dead time is longer than modelled: about %.0f samples: add `delay`",
               static_cast<double>(trial.structure.nk + 1));
  if (effect == "order")
    return fmt(
        "the process has more lags than modelled (na = %.0f, nb = %.0f fit better): add `order`",
        static_cast<double>(trial.structure.na), static_cast<double>(trial.structure.nb));
  if (effect == "integrator")
    return "PV integrates the flow through the valve (a level or pressure in a closed vessel): add "
           "`integrator`";
  if (effect == "disturbance")
    return "a slow unmeasured load moves PV, not explained by OP: add `disturbance` (and look for "
           "its source)";
  return "add `" + effect + "`";
}

// Region kinds that localize each effect's signature.
bool region_fits(const std::string& effect, const std::string& kind) {
  if (effect == "stiction" || effect == "deadband")
    return kind == "since-reversal" || kind == "direction";
  if (effect == "preisach") return kind == "op-level" || kind == "direction";
  if (effect == "saturation" || effect == "characteristic") return kind == "op-level";
  if (effect == "actuator-lag") return kind == "since-reversal";
  return false;
}

double finite_or(double v, double fallback) {
  return std::isfinite(v) ? v : fallback;
}

DiagnosisStep evaluate(const std::vector<double>& u, const std::vector<double>& y, double Ts,
                       const ModelSpec& model, const DiagnoseOptions& opt) {
  const ModelFitOptions fo = fit_options(opt);
  DiagnosisStep step;
  step.fit = fit_model(u, y, Ts, model, fo);
  ResidualAnalysisOptions ro;
  ro.model_delay = static_cast<std::size_t>(std::max(0, step.fit.structure.nk + 1));
  step.residual =
      analyse_residual(u, y, step.fit.y_sim, step.fit.first_sample, step.fit.estimation_end, ro);

  std::vector<ModelSpec> trials;
  std::vector<std::string> names;
  for (const auto& info : effect_vocabulary()) {
    if (model.has(info.name)) continue;
    if (!opt.candidates.empty() &&
        std::find(opt.candidates.begin(), opt.candidates.end(), info.name) == opt.candidates.end())
      continue;
    try {
      trials.push_back(add_effect(model, info.name));
      names.push_back(info.name);
    } catch (const ModelSpecError&) {
      // Not combinable with this model (e.g. preisach beside another valve effect).
    }
  }
  const auto fits = fit_models(u, y, Ts, trials, fo);
  const double base_val = finite_or(step.fit.validation_fitness_percent, 0.0);
  const double base_est = finite_or(step.fit.fitness_percent, 0.0);
  for (std::size_t i = 0; i < fits.size(); ++i) {
    const ModelFit& t = fits[i];
    Finding f;
    f.effect = names[i];
    f.trial_spec = trials[i];
    f.trial_fitness_percent = t.fitness_percent;
    f.trial_validation_fitness_percent = t.validation_fitness_percent;
    f.estimation_gain_percent = finite_or(t.fitness_percent, -1e9) - base_est;
    f.validation_gain_percent = finite_or(t.validation_fitness_percent, -1e9) - base_val;
    for (const auto& e : t.effects)
      if (e.name == f.effect) f.parameters = e.parameters;
    for (const auto& test : step.residual.tests)
      if (std::find(test.effects.begin(), test.effects.end(), f.effect) != test.effects.end() &&
          test.score > f.evidence) {
        f.evidence = test.score;
        f.evidence_test = test.name;
      }
    // A true missing effect improves both parts of the record: the smaller gain counts (a flexible
    // model that only wins on one part is fitting something else), relative to the error left.
    f.gain_percent = std::min(f.validation_gain_percent, f.estimation_gain_percent);
    if (!std::isfinite(t.validation_fitness_percent))
      f.gain_percent = std::min(f.gain_percent, -1e9);
    const double rel = f.gain_percent / std::max(100.0 - base_est, 1.0);
    f.score = f.gain_percent > 0 ? 0.6 * std::clamp(rel / 0.3, 0.0, 1.0) + 0.4 * f.evidence
                                 : 0.15 * f.evidence;
    f.supported = f.score >= opt.min_score && f.gain_percent >= opt.min_gain_percent;
    for (const auto& iv : step.residual.intervals)
      if (f.intervals.size() < 3) f.intervals.push_back(iv);
    for (const auto& g : step.residual.regions)
      if (region_fits(f.effect, g.kind) && g.excess >= 1.3 && g.share >= 0.1)
        f.regions.push_back(g);
    f.explanation = explain(f.effect, t, f.parameters);
    step.findings.push_back(std::move(f));
  }
  // Scores saturate when the model leaves much to explain; among near-equal scores the larger
  // gain on both parts of the record ranks first.
  std::stable_sort(step.findings.begin(), step.findings.end(),
                   [](const Finding& a, const Finding& b) {
                     if (std::abs(a.score - b.score) > 0.02) return a.score > b.score;
                     return a.gain_percent > b.gain_percent;
                   });
  // Two effects that the data cannot tell apart: say so rather than pretend.
  if (step.findings.size() >= 2) {
    auto& a = step.findings[0];
    auto& b = step.findings[1];
    if (a.gain_percent >= opt.min_gain_percent && b.gain_percent >= opt.min_gain_percent &&
        std::abs(a.gain_percent - b.gain_percent) < 1.0) {
      a.indistinguishable_from = b.effect;
      b.indistinguishable_from = a.effect;
    }
  }
  return step;
}

std::string conclusion_of(const DiagnosisStep& s, const std::vector<double>& t_axis, double Ts,
                          const std::string& why) {
  const auto& r = s.residual;
  std::string c = why + " What is left: residual RMS " + fmt("%.3g", r.rms) +
                  " against a white-noise level of " + fmt("%.3g", r.noise_level);
  if (r.noise_level > 0) c += fmt(" (%.1f x)", r.rms / r.noise_level);
  if (!r.intervals.empty()) {
    const auto& iv = r.intervals.front();
    const double t0 = t_axis.empty() ? iv.begin * Ts : t_axis[iv.begin];
    const double t1 = t_axis.empty() ? (iv.end - 1) * Ts : t_axis[iv.end - 1];
    c += fmt("; the largest unexplained interval is t %.0f .. %.0f s", t0, t1) +
         fmt(" (%.0f %% of the remaining error)", 100 * iv.share);
  }
  return c + ".";
}

}  // namespace

Diagnosis diagnose(const std::vector<double>& u, const std::vector<double>& y, double Ts,
                   const ModelSpec& model, const DiagnoseOptions& opt) {
  Diagnosis d;
  d.steps.push_back(evaluate(u, y, Ts, model, opt));
  const auto& f = d.last().findings;
  const bool supported = !f.empty() && f.front().supported;
  d.conclusion =
      conclusion_of(d.last(), {}, Ts,
                    supported ? "The most likely missing effect is `" + f.front().effect + "`."
                              : "No candidate effect improves the model by a meaningful margin.");
  return d;
}

Diagnosis diagnose_auto(const std::vector<double>& u, const std::vector<double>& y, double Ts,
                        const ModelSpec& start, const DiagnoseOptions& opt) {
  Diagnosis d;
  ModelSpec model = start;
  std::string why;
  for (int k = 0;; ++k) {
    d.steps.push_back(evaluate(u, y, Ts, model, opt));
    const auto& f = d.last().findings;
    if (k >= opt.max_steps) {
      why = fmt("Stopped after %.0f added effects.", static_cast<double>(k));
      break;
    }
    if (f.empty()) {
      why = "Every effect of the vocabulary is in the model.";
      break;
    }
    const Finding& best = f.front();
    const double gain = best.gain_percent;
    if (best.score < opt.min_score || !(gain >= opt.min_gain_percent)) {
      why = "No further effect improves both estimation and validation fitness by " +
            fmt("%.0f", opt.min_gain_percent) + " points or more (best candidate: `" + best.effect +
            "`, " + fmt("%+.1f", gain) + ").";
      break;
    }
    model = best.trial_spec;
  }
  d.conclusion = conclusion_of(d.last(), {}, Ts, why);
  return d;
}

}  // namespace valvediag
