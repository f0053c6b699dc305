#include "valvediag/sweep/loop_assessment.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <utility>

namespace valvediag {

double severity(const LoopAssessment& a) {
  double s = 0.0;
  if (a.verdict == "stiction")
    s = 6;
  else if (a.verdict == "deadband")
    s = 5;
  else if (a.verdict == "other-nonlinearity")
    s = 3;
  else if (a.verdict == "no-valve-problem")
    s = 1;
  else if (a.verdict != "not-enough-data")  // not-enough-data 0: its oscillation still counts
    return -1;
  if (a.health.oscillating) s += 1;
  if (std::isfinite(a.stiction_percent)) s += std::clamp(a.stiction_percent / 2.0, 0.0, 3.0);
  return s;
}

std::pair<int, int> split_agreement(const LoopAssessment& a) {
  return split_agreement(a.verdict, a.split_verdicts);
}

void rank(std::vector<LoopAssessment>& loops) {
  auto size = [](const LoopAssessment& a) {
    return std::isfinite(a.stiction_percent) ? a.stiction_percent : -1.0;
  };
  std::stable_sort(loops.begin(), loops.end(), [&](const auto& x, const auto& y) {
    if (x.severity != y.severity) return x.severity > y.severity;
    if (size(x) != size(y)) return size(x) > size(y);
    return x.loop < y.loop;
  });
}

LoopAssessment assess_loop(const LoopData& d, const std::string& name, const AssessOptions& opt,
                           Diagnosis* diagnosis) {
  const auto t0 = std::chrono::steady_clock::now();
  LoopVerdict v = loop_verdict(d, opt);
  LoopAssessment a;
  a.loop = name;
  a.source = d.source;
  a.tag = d.tag;
  a.health = v.health;
  a.verdict = v.verdict;
  a.reason = v.reason;
  a.error = v.error;
  a.lead_in = v.lead_in;
  a.analysed_from_s = v.analysed_from_s;
  a.stiction_percent = v.stiction.band_percent;
  a.slip_jump_percent = v.stiction.jump_percent;
  a.stiction_lo_percent = v.stiction.band_lo_percent;
  a.stiction_hi_percent = v.stiction.band_hi_percent;
  a.stiction_hi_open = v.stiction.band_hi_open;
  a.prediction_stiction_percent = v.stiction.prediction_band_percent;
  a.split_verdicts = v.split_verdicts;
  if (v.judged()) {
    const Diagnosis& dg = v.diagnosis;
    const ModelFit& best = dg.last().fit;
    a.valve_travel = dg.valve_travel;
    a.limit_cycle = dg.limit_cycle;
    a.whole_record = dg.whole_record;
    a.model = v.model;
    a.fitness_percent = best.fitness_percent;
    a.validation_fitness_percent = best.validation_fitness_percent;
    for (const auto& s : dg.steps)
      a.ladder.push_back(
          {to_string(s.fit.spec), s.fit.fitness_percent, s.fit.validation_fitness_percent});
    if (dg.steps.size() > 1) {
      for (const auto& e : dg.steps[1].fit.spec.effects)  // the first effect the climb added
        if (!dg.steps[0].fit.spec.has(e.name)) a.first_missing = e.name;
    } else if (!dg.steps.front().findings.empty() && dg.steps.front().findings.front().supported) {
      a.first_missing = dg.steps.front().findings.front().effect;
    }
    if (diagnosis) *diagnosis = std::move(v.diagnosis);
  }
  a.severity = severity(a);
  a.elapsed_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return a;
}

}  // namespace valvediag
