// The recorder's timestamps: "2026-11-29T18:43:11Z".
#pragma once

#include <ctime>
#include <string>

namespace valvediag {

inline std::string utc_now() {
  const std::time_t t = std::time(nullptr);
  std::tm tm{};
  gmtime_r(&t, &tm);
  char b[32];
  std::strftime(b, sizeof b, "%Y-%m-%dT%H:%M:%SZ", &tm);
  return b;
}

}  // namespace valvediag
