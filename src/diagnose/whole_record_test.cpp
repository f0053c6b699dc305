#include "valvediag/whole_record_test.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>

namespace valvediag {

namespace {

std::string fmt(const char* f, double a = 0, double b = 0, double c = 0) {
  char buf[256];
  std::snprintf(buf, sizeof buf, f, a, b, c);
  return buf;
}

double param(const ModelFit& fit, const char* effect, const char* name) {
  for (const auto& e : fit.effects)
    if (e.name == effect)
      for (const auto& p : e.parameters)
        if (p.name == name) return p.value;
  return std::nan("");
}

bool is_memory(const std::string& effect) {
  return effect == "stiction" || effect == "deadband" || effect == "preisach";
}

}  // namespace

WholeRecordTest whole_record_test(const std::vector<double>& u, const std::vector<double>& y,
                                  double Ts, const ModelSpec& start, ModelFitOptions fit,
                                  const WholeRecordOptions& opt) {
  WholeRecordTest w;
  for (const auto& e : start.effects)
    if (is_memory(e.name)) return w;  // the start model has memory already
  fit.validation_fraction = 0.0;
  fit.validation_start = 0;
  // The trial fits preferred one variant on a part of the record; on the whole record another
  // may explain the slips (a band learnt from one slip), so all are fitted.
  std::vector<ModelSpec> specs{start};
  for (const char* m : {"stiction", "stiction:kano", "stiction:stenman", "deadband"})
    specs.push_back(add_effect(start, m));
  const std::vector<ModelFit> fits = fit_models(u, y, Ts, specs, fit);
  const ModelFit& base = fits[0];
  w.start_fitness = base.fitness_percent;
  // No stable start model counts as predicting the mean (fitness 0), as in the diagnosis.
  const double f0 = std::isfinite(base.fitness_percent) ? std::max(base.fitness_percent, 0.0) : 0.0;
  const ModelFit* mem = nullptr;
  for (std::size_t i = 1; i < fits.size(); ++i)
    if (std::isfinite(fits[i].fitness_percent) &&
        (!mem || fits[i].fitness_percent > mem->fitness_percent))
      mem = &fits[i];
  w.tested = true;
  if (!mem) {
    w.summary = "no valve model with memory has a stable fit on the whole record";
    return w;
  }
  w.memory_model = to_string(mem->spec);
  w.memory_fitness = mem->fitness_percent;
  for (const auto& e : mem->effects)
    if (is_memory(e.name)) w.memory_effects.push_back(e);
  const double gain = w.memory_fitness - f0;
  w.relative_gain = gain / std::max(100.0 - f0, 1.0);
  const std::string start_name = to_string(start);
  const std::string head = "on the whole record `" + w.memory_model + "` explains " +
                           fmt("%.0f %% of the error `", 100 * w.relative_gain) + start_name +
                           fmt("` leaves (%+.1f points)", gain);
  if (!(gain >= opt.min_gain_percent && w.relative_gain >= opt.min_relative_gain)) {
    w.summary = head + fmt(": under the %.0f %% a valve with memory must explain",
                           100 * opt.min_relative_gain);
    return w;
  }

  // The load, charged by BIC for its knots against the friction parameters.
  const bool with_load = !start.has("disturbance");
  if (with_load) {
    const ModelFit load = fit_models(u, y, Ts, {add_effect(start, "disturbance")}, fit).front();
    w.load_fitness = load.fitness_percent;
    const double n = static_cast<double>(y.size() - std::min(y.size(), mem->first_sample));
    const double h = param(load, "disturbance", "knot_spacing") / Ts;
    double k_mem = 0;
    for (const auto& e : w.memory_effects) k_mem += static_cast<double>(e.parameters.size());
    if (std::isfinite(load.fitness_percent) && h > 0 && n > 0) {
      const double k_load = n / h + 1.0;
      const double r_mem = std::max(1.0 - w.memory_fitness / 100.0, 1e-9);
      const double r_load = std::max(1.0 - load.fitness_percent / 100.0, 1e-9);
      // BIC = n ln(RSS / n) + k ln n; RSS scales with the square of (1 - fitness).
      w.load_bic_margin = 2.0 * n * std::log(r_load / r_mem) + (k_load - k_mem) * std::log(n);
    } else {
      w.load_bic_margin = std::numeric_limits<double>::infinity();  // no load model fits
    }
    if (!(w.load_bic_margin > 0)) {
      w.summary =
          head +
          fmt(", but a slow load fits it better (%.1f %% against %.1f %%, BIC ", w.load_fitness,
              w.memory_fitness) +
          fmt("%.0f lower even with its %.0f knots charged)", -w.load_bic_margin, n / h + 1.0);
      return w;
    }
  }

  // Every memoryless effect added alone.
  std::vector<ModelSpec> rivals;
  std::vector<std::string> names;
  for (const auto& info : effect_vocabulary()) {
    if (is_memory(info.name) || info.name == "disturbance" || start.has(info.name)) continue;
    try {
      rivals.push_back(add_effect(start, info.name));
      names.push_back(info.name);
    } catch (const ModelSpecError&) {
    }
  }
  const std::vector<ModelFit> rf = fit_models(u, y, Ts, rivals, fit);
  for (std::size_t i = 0; i < rf.size(); ++i)
    if (std::isfinite(rf[i].fitness_percent) && !(rf[i].fitness_percent <= w.rival_fitness)) {
      w.rival_fitness = rf[i].fitness_percent;
      w.rival = names[i];
    }
  if (std::isfinite(w.rival_fitness) && !(w.memory_fitness > w.rival_fitness)) {
    w.summary = head + ", but `" + w.rival + "` without memory fits it as well (" +
                fmt("%.1f %% against %.1f %%)", w.rival_fitness, w.memory_fitness);
    return w;
  }
  w.confirmed = true;
  w.summary = head + ", more than any memoryless effect" +
              (w.rival.empty() ? std::string()
                               : " (best: `" + w.rival + fmt("`, %+.1f)", w.rival_fitness - f0)) +
              (!with_load ? std::string()
               : std::isfinite(w.load_bic_margin)
                   ? fmt(" and than a slow load once its knots are charged (BIC %.0f lower)",
                         w.load_bic_margin)
                   : std::string(" (a slow load has no stable fit)"));
  return w;
}

}  // namespace valvediag
