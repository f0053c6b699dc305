// Date-time stamps for the CSV reader: a small strftime-like parser (internal to valvediag_io).
// std::get_time is locale-dependent and slow, and std::chrono::parse is missing in g++ 12.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>

namespace valvediag::detail {

struct TimeStamp {
  std::int64_t seconds = 0;  // whole seconds since 1970-01-01 00:00:00 of the naive stamp
  double fraction = 0.0;     // 0 <= fraction < 1
};

// Empty string when `format` is usable, else what is wrong with it.
std::string check_time_format(std::string_view format);

// Replaces the shorthands %F (%Y-%m-%d) and %T (%H:%M:%S); parse_time_stamp needs this form.
std::string expand_time_format(std::string_view format);

// Parses `text` (already trimmed) with an expanded format that passed check_time_format. Returns
// false and sets `why` when the text does not match or names an impossible date or time.
bool parse_time_stamp(std::string_view text, std::string_view format, TimeStamp& out,
                      std::string& why);

// Days from 1970-01-01 to the given proleptic Gregorian date (negative before).
std::int64_t days_from_civil(std::int64_t year, unsigned month, unsigned day);

}  // namespace valvediag::detail
