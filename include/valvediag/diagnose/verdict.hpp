// The rule that reads a verdict from a diagnosis: "stiction", "deadband", "other-nonlinearity" or
// "no-valve-problem". A loop's verdict is this rule applied to one analysis, loop_verdict() in
// loop_verdict.hpp, which every command calls; the fifth word, "not-enough-data", is given there
// before any model is fitted, when the record cannot tell (unusable_reason() in loop_health.hpp).
//
// In order of weight:
//  1. The recorded valve position, when there is one (valve_travel.hpp): friction measured on
//     OP -> MV outweighs what the closed-loop models suggest.
//  2. The valve part of the climbed ladder's final model (or, without a climb, the top supported
//     finding): a memory (stiction, preisach; deadband) confirmed on held-out data.
//  3. A stick-slip limit cycle (limit_cycle.hpp), which trial fits can miss.
//  4. The whole-record test (whole_record_test.hpp): a valve that slips once or twice, which the
//     held-out tail cannot confirm.
//  5. A static valve nonlinearity in the final model (saturation, characteristic):
//     other-nonlinearity; else no-valve-problem. An actuator lag is neither: it is linear, and
//     OP and PV cannot tell it from one more process lag (the recorded valve position can).
#pragma once

#include <string>

#include "valvediag/diagnose/diagnosis.hpp"

namespace valvediag {

std::string verdict(const Diagnosis& d);

// What a verdict word means for the valve and what an engineer does about it, in one or two
// sentences (the sweep's page, the README's table); empty for a word that is not a verdict.
std::string verdict_advice(const std::string& verdict);

}  // namespace valvediag
