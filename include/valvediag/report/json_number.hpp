// A number in JSON output: NaN and infinities, which JSON cannot hold, become null.
#pragma once

#include <cmath>
#include <nlohmann/json.hpp>

namespace valvediag {

inline nlohmann::json json_number(double v) {
  return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json();
}

}  // namespace valvediag
