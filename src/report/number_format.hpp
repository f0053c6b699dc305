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

}  // namespace valvediag::report_format
