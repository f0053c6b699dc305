// The verdict a plant engineer wants first, from a diagnosis.
#include "valvediag/verdict.hpp"

namespace valvediag {

std::string verdict(const Diagnosis& d) {
  // The valve part of the final model (the climbed ladder), or the top supported finding.
  ModelSpec m = d.last().fit.spec;
  if (d.steps.size() == 1 && !d.last().findings.empty()) {
    const auto& f = d.last().findings.front();
    if (f.supported) m = f.trial_spec;
  }
  if (m.has("stiction") || m.has("preisach")) return "stiction";
  if (m.has("deadband")) return "deadband";
  if (m.has("saturation") || m.has("characteristic") || m.has("actuator-lag"))
    return "other-nonlinearity";
  return "no-valve-problem";
}

}  // namespace valvediag
