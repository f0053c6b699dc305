// Numbers as the reports print them: fixed decimals, a word for NaN and infinities; a model's
// parameter list. Private to src/report.
#pragma once

#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "valvediag/model/effect_estimators.hpp"

namespace valvediag::report_format {

inline std::string fixed(double v, int prec, const char* missing = "n/a") {
  if (!std::isfinite(v)) return missing;
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.*f", prec, v);
  return buf;
}

inline std::string signed_fixed(double v, int prec = 2, const char* missing = "n/a") {
  if (!std::isfinite(v)) return missing;
  char buf[64];
  std::snprintf(buf, sizeof buf, "%+.*f", prec, v);
  return buf;
}

// A model parameter: whole numbers as such, 3 decimals, or 3 significant digits when that would
// print a small rate (an integrator's PV/s per OP unit) as 0.000.
inline std::string parameter(double v) {
  if (!std::isfinite(v)) return "n/a";
  char buf[64];
  if (v == std::round(v) && std::abs(v) < 1e6)
    std::snprintf(buf, sizeof buf, "%.0f", v);
  else if (std::abs(v) < 0.1)
    std::snprintf(buf, sizeof buf, "%.3g", v);
  else
    std::snprintf(buf, sizeof buf, "%.3f", v);
  return buf;
}

// "fs 8.443 OP, fd 3.602 OP, initial_motion up": a fitted effect's parameters, for text and HTML
// alike. He's starting motion (-1, 0, 1) is a state, so it is named.
inline std::string parameters(const std::vector<NamedValue>& p) {
  std::string s;
  for (const auto& v : p) {
    if (!s.empty()) s += ", ";
    const bool motion = v.name.ends_with("initial_motion");
    s += v.name + " " +
         (motion ? (v.value < -0.5  ? "down"
                    : v.value > 0.5 ? "up"
                                    : "at rest")
                 : parameter(v.value)) +
         (v.unit.empty() ? "" : " " + v.unit);
  }
  return s;
}

}  // namespace valvediag::report_format
