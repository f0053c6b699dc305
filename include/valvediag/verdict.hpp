// The verdict a plant engineer wants first from a diagnosis: "stiction", "deadband",
// "other-nonlinearity", "no-valve-problem".
#pragma once

#include <string>

#include "valvediag/diagnosis.hpp"

namespace valvediag {

std::string verdict(const Diagnosis& d);

}  // namespace valvediag
