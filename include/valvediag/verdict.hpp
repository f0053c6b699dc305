// The verdict a plant engineer wants first: "stiction", "deadband", "other-nonlinearity" or
// "no-valve-problem", read from a diagnosis. (The fifth, "not-enough-data", is given before any
// model is fitted, when the record cannot tell: unusable_reason() in loop_health.hpp, applied by
// assess_loop() in loop_assessment.hpp.)
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

#include "valvediag/diagnosis.hpp"

namespace valvediag {

std::string verdict(const Diagnosis& d);
// The same, or "not-enough-data" when `unusable` (unusable_reason() of the record) is not empty:
// what diagnose and report say of a record a sweep would not fit, while showing their fits.
std::string verdict(const Diagnosis& d, const std::string& unusable);

}  // namespace valvediag
