// Now, UTC, ISO 8601 ("2026-11-29T18:43:11Z"): the time stamps of recordings, model histories,
// reports and sweeps. Header-only so the recorder and the report libraries share it.
#pragma once

#include <ctime>
#include <string>

namespace valvediag {

inline std::string utc_timestamp(std::time_t t = std::time(nullptr)) {
  std::tm tm{};
  gmtime_r(&t, &tm);
  char b[32];
  std::strftime(b, sizeof b, "%Y-%m-%dT%H:%M:%SZ", &tm);
  return b;
}

}  // namespace valvediag
