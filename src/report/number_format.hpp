// Numbers as the reports print them: fixed decimals, a word for NaN and infinities. Private to
// src/report.
#pragma once

#include <cmath>
#include <cstdio>
#include <string>

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

}  // namespace valvediag::report_format
