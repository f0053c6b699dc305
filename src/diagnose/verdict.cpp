// The verdict a plant engineer wants first, from a diagnosis.
#include "valvediag/diagnose/verdict.hpp"

namespace valvediag {

namespace {

std::string model_verdict(const Diagnosis& d) {
  // The valve part of the final model (the climbed ladder), or the top supported finding.
  const ModelSpec m = verdict_model(d);
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
  // Not an actuator lag alone: it is linear, and with no valve nonlinearity beside it it
  // commutes with the process lags, so OP and PV cannot place it in the valve (measured: it
  // won the climb on 6 of 8 third-order processes with ideal valves).
  if (m.has("saturation") || m.has("characteristic")) return "other-nonlinearity";
  return "no-valve-problem";
}
}  // namespace

std::string verdict(const Diagnosis& d) {
  const std::string from_model = model_verdict(d);
  const ValveTravel& t = d.valve_travel;
  if (!t.decided) return from_model;
  // The measured position shows the friction itself; when it shows none, a memory the closed-loop
  // models found lies outside the valve, and a static curve (flow against travel) may still hold.
  if (t.verdict == "stiction" || t.verdict == "deadband") return t.verdict;
  return from_model == "stiction" || from_model == "deadband" ? "no-valve-problem" : from_model;
}

std::string verdict_advice(const std::string& verdict) {
  if (verdict == "stiction")
    return "The valve sticks: it holds while OP moves, then jumps. Plan maintenance (packing, "
           "actuator, positioner) and confirm with a valve travel test; less integral action "
           "calms the cycle meanwhile.";
  if (verdict == "deadband")
    return "Play in the linkage or positioner: after a reversal OP must travel a band before the "
           "valve follows, without a jump. Check the linkage and the positioner.";
  if (verdict == "other-nonlinearity")
    return "Not sticky, but the valve's response is not linear: it reaches a travel limit or its "
           "flow characteristic curves. Check the sizing and the characteristic.";
  if (verdict == "no-valve-problem")
    return "Nothing in the data points at the valve. If the loop performs poorly, look at the "
           "tuning, the process and its loads.";
  if (verdict == "not-enough-data")
    return "The record cannot decide: too short, too flat or too few OP reversals. Record longer, "
           "or while the loop moves (set-point changes); the note says what was missing.";
  if (verdict == "error") return "The record could not be read or analysed; the note says why.";
  return "";
}

}  // namespace valvediag
