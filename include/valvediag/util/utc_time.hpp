// Now, UTC, ISO 8601 ("2026-11-29T18:43:11Z"): the time stamps of recordings, model histories,
// reports and sweeps. Header-only so the recorder and the report libraries share it.
#pragma once

#include <cstdio>
#include <ctime>
#include <limits>
#include <string>

namespace valvediag {

// t as UTC in a strftime format.
inline std::string utc_text(std::time_t t, const char* format) {
  std::tm tm{};
  gmtime_r(&t, &tm);
  char b[64];
  return std::strftime(b, sizeof b, format, &tm) > 0 ? std::string(b) : std::string();
}

inline std::string utc_timestamp(std::time_t t = std::time(nullptr)) {
  return utc_text(t, "%Y-%m-%dT%H:%M:%SZ");
}

// Seconds since 1970 of a stamp utc_timestamp() wrote; NaN for any other text.
inline double utc_seconds(const std::string& stamp) {
  std::tm tm{};
  char z = 0;
  int used = 0;
  if (std::sscanf(stamp.c_str(), "%4d-%2d-%2dT%2d:%2d:%2d%c%n", &tm.tm_year, &tm.tm_mon,
                  &tm.tm_mday, &tm.tm_hour, &tm.tm_min, &tm.tm_sec, &z, &used) != 7 ||
      z != 'Z' || static_cast<std::size_t>(used) != stamp.size() || tm.tm_mon < 1 ||
      tm.tm_mon > 12 || tm.tm_mday < 1 || tm.tm_mday > 31 || tm.tm_hour < 0 || tm.tm_hour > 23 ||
      tm.tm_min < 0 || tm.tm_min > 59 || tm.tm_sec < 0 || tm.tm_sec > 60)
    return std::numeric_limits<double>::quiet_NaN();
  tm.tm_year -= 1900;
  tm.tm_mon -= 1;
  return static_cast<double>(timegm(&tm));
}

}  // namespace valvediag
