#include "valvediag/diagnose/whole_record_test.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <stdexcept>

#include "valvediag/util/text_stats.hpp"

namespace valvediag {

namespace {

// Parameters the effects of `fit` add to those of `before`.
double added_parameters(const ModelFit& fit, const ModelSpec& before, double Ts) {
  double k = 0;
  for (const auto& e : fit.effects)
    if (!before.has(e.name)) k += effect_parameter_count(e.name, fit, Ts);
  return k;
}

// BIC(rival) - BIC(memory) over the samples both fit; > 0: the memory is preferred. BIC =
// n ln(RSS / n) + k ln n, and RSS scales with the square of (1 - fitness).
double bic_margin(const ModelFit& mem, double k_mem, const ModelFit& rival, double k_rival,
                  std::size_t N) {
  if (!std::isfinite(rival.fitness_percent)) return std::numeric_limits<double>::infinity();
  const double n =
      static_cast<double>(N - std::min(N, std::max(mem.first_sample, rival.first_sample)));
  if (!(n > 1)) return std::numeric_limits<double>::quiet_NaN();
  const double r_mem = std::max(1.0 - mem.fitness_percent / 100.0, 1e-9);
  const double r_rival = std::max(1.0 - rival.fitness_percent / 100.0, 1e-9);
  return 2.0 * n * std::log(r_rival / r_mem) + (k_rival - k_mem) * std::log(n);
}

// The two guards on a fitted memory model against `before`: a slow load and every memoryless
// effect, each charged by BIC for its parameters. Fills w from `head` on; confirmed when both
// hold.
void guards(const std::vector<double>& u, const std::vector<double>& y, double Ts,
            const ModelSpec& before, const ModelFit& mem, const ModelFitOptions& fit,
            const std::string& head, WholeRecordTest& w) {
  const double k_mem = added_parameters(mem, before, Ts);
  const bool with_load = !before.has("disturbance");
  if (with_load) {
    const ModelFit load = fit_models(u, y, Ts, {add_effect(before, "disturbance")}, fit).front();
    const double k_load = added_parameters(load, before, Ts);
    w.load_fitness = load.fitness_percent;
    w.load_bic_margin = bic_margin(mem, k_mem, load, k_load, y.size());
    if (!(w.load_bic_margin > 0)) {
      w.preferred = "disturbance";
      w.summary =
          head +
          strprintf(", but a slow load fits it better (%.1f %% against %.1f %%, BIC ",
                    w.load_fitness, w.memory_fitness) +
          strprintf("%.0f lower even with its %.0f knots charged)", -w.load_bic_margin, k_load);
      return;
    }
  }

  // Every memoryless effect added alone.
  std::vector<ModelSpec> rivals;
  std::vector<std::string> names;
  for (const auto& info : effect_vocabulary()) {
    if (is_memory_effect(info.name) || info.name == "disturbance" || before.has(info.name))
      continue;
    try {
      rivals.push_back(add_effect(before, info.name));
      names.push_back(info.name);
    } catch (const ModelSpecError&) {
    }
  }
  const std::vector<ModelFit> rf = fit_models(u, y, Ts, rivals, fit);
  for (std::size_t i = 0; i < rf.size(); ++i) {
    if (!std::isfinite(rf[i].fitness_percent)) continue;  // no stable fit: not a rival
    const double m = bic_margin(mem, k_mem, rf[i], added_parameters(rf[i], before, Ts), y.size());
    if (!(m >= w.rival_bic_margin)) {
      w.rival_bic_margin = m;
      w.rival = names[i];
      w.rival_fitness = rf[i].fitness_percent;
    }
  }
  const double f0 = std::isfinite(w.start_fitness) ? std::max(w.start_fitness, 0.0) : 0.0;
  if (!w.rival.empty() && !(w.rival_bic_margin > 0)) {
    w.preferred = w.rival;
    w.summary = head + ", but `" + w.rival + "` without memory fits it as well (" +
                strprintf("%.1f %% against %.1f %%, BIC %.0f lower", w.rival_fitness,
                          w.memory_fitness, -w.rival_bic_margin) +
                ")";
    return;
  }
  w.confirmed = true;
  w.summary =
      head + ", more than any memoryless effect" +
      (w.rival.empty() ? std::string()
                       : " (best: `" + w.rival + strprintf("`, %+.1f)", w.rival_fitness - f0)) +
      (!with_load ? std::string()
       : std::isfinite(w.load_bic_margin)
           ? strprintf(" and than a slow load once its knots are charged (BIC %.0f lower)",
                       w.load_bic_margin)
           : std::string(" (a slow load has no stable fit)"));
}

// Start-model and memory figures of w from their whole-record fits; the sentence's head.
std::string describe(const ModelFit& base, const ModelFit& mem, const ModelSpec& start,
                     WholeRecordTest& w) {
  w.start_fitness = base.fitness_percent;
  // No stable start model counts as predicting the mean (fitness 0), as in the diagnosis.
  const double f0 = std::isfinite(base.fitness_percent) ? std::max(base.fitness_percent, 0.0) : 0.0;
  w.memory_model = to_string(mem.spec);
  w.memory_fitness = mem.fitness_percent;
  for (const auto& e : mem.effects)
    if (is_memory_effect(e.name)) w.memory_effects.push_back(e);
  w.memory_coordinates = mem.valve_coordinates;
  const double gain = w.memory_fitness - f0;
  w.relative_gain = gain / std::max(100.0 - f0, 1.0);
  return "on the whole record `" + w.memory_model + "` explains " +
         strprintf("%.0f %% of the error `", 100 * w.relative_gain) + to_string(start) +
         strprintf("` leaves (%+.1f points)", gain);
}

}  // namespace

ModelFitOptions whole_record_fit_options(ModelFitOptions fit) {
  fit.validation_fraction = 0.0;
  fit.validation_start = 0;
  return fit;
}

WholeRecordTest whole_record_test(const std::vector<double>& u, const std::vector<double>& y,
                                  double Ts, const ModelSpec& start, ModelFitOptions fit,
                                  const WholeRecordOptions& opt) {
  WholeRecordTest w;
  if (has_memory_effect(start)) return w;  // the start model has memory already
  fit = whole_record_fit_options(fit);
  // The trial fits preferred one variant on a part of the record; on the whole record another
  // may explain the slips (a band learnt from one slip), so all are fitted.
  std::vector<ModelSpec> specs{start};
  for (const char* m : {"stiction", "stiction:kano", "stiction:stenman", "deadband"})
    specs.push_back(add_effect(start, m));
  const std::vector<ModelFit> fits = fit_models(u, y, Ts, specs, fit);
  const ModelFit* mem = nullptr;
  for (std::size_t i = 1; i < fits.size(); ++i)
    if (std::isfinite(fits[i].fitness_percent) &&
        (!mem || fits[i].fitness_percent > mem->fitness_percent))
      mem = &fits[i];
  w.tested = true;
  if (!mem) {
    w.start_fitness = fits[0].fitness_percent;
    w.summary = "no valve model with memory has a stable fit on the whole record";
    return w;
  }
  const std::string head = describe(fits[0], *mem, start, w);
  const double f0 = std::isfinite(w.start_fitness) ? std::max(w.start_fitness, 0.0) : 0.0;
  if (!(w.memory_fitness - f0 >= opt.min_gain_percent &&
        w.relative_gain >= opt.min_relative_gain)) {
    w.summary = head + strprintf(": under the %.0f %% a valve with memory must explain",
                                 100 * opt.min_relative_gain);
    return w;
  }
  guards(u, y, Ts, start, *mem, fit, head, w);
  return w;
}

}  // namespace valvediag
