#include <doctest/doctest.h>

#include "time_parse.hpp"

using valvediag::detail::check_time_format;
using valvediag::detail::days_from_civil;
using valvediag::detail::expand_time_format;
using valvediag::detail::parse_time_stamp;
using valvediag::detail::TimeStamp;

namespace {

// Seconds since 1970 of `text` under `format`; fails the test when it does not parse.
TimeStamp parse(const char* text, const char* format) {
  TimeStamp ts;
  std::string why;
  REQUIRE(check_time_format(format) == "");
  const bool ok = parse_time_stamp(text, expand_time_format(format), ts, why);
  INFO(text, " / ", format, ": ", why);
  REQUIRE(ok);
  return ts;
}

std::string reject(const char* text, const char* format) {
  TimeStamp ts;
  std::string why;
  REQUIRE(check_time_format(format) == "");
  CHECK_FALSE(parse_time_stamp(text, expand_time_format(format), ts, why));
  return why;
}

}  // namespace

TEST_CASE("days_from_civil matches the Gregorian calendar") {
  // Reference values from Python's datetime.date arithmetic.
  CHECK(days_from_civil(1970, 1, 1) == 0);
  CHECK(days_from_civil(1969, 12, 31) == -1);
  CHECK(days_from_civil(2000, 1, 1) == 10957);
  CHECK(days_from_civil(2024, 2, 29) == 19782);
  CHECK(days_from_civil(2024, 3, 1) == 19783);
  CHECK(days_from_civil(1600, 3, 1) == -135080);
  CHECK(days_from_civil(9999, 12, 31) == 2932896);
  CHECK(days_from_civil(1, 1, 1) == -719162);
}

TEST_CASE("time stamps in the usual historian formats") {
  const TimeStamp a = parse("2024-10-03 21:55:00", "%Y-%m-%d %H:%M:%S");
  CHECK(a.seconds == 1727992500);
  CHECK(a.fraction == 0.0);
  CHECK(parse("2024-10-03T21:55:00", "%FT%T").seconds == 1727992500);
  CHECK(parse("10/03/2024 21:55:00", "%m/%d/%Y %H:%M:%S").seconds == 1727992500);
  CHECK(parse("3/10/2024 9:55:00 PM", "%d/%m/%Y %I:%M:%S %p").seconds == 1727992500);
  CHECK(parse("03-Oct-24 21:55:00", "%d-%b-%y %H:%M:%S").seconds == 1727992500);
  CHECK(parse("3 October 2024 21:55:00", "%e %B %Y %T").seconds == 1727992500);
  CHECK(parse("20241003215500", "%Y%m%d%H%M%S").seconds == 1727992500);
  // Runs of blanks match one blank in the format.
  CHECK(parse("2024-10-03   21:55:00", "%F %T").seconds == 1727992500);
  // 12 AM is midnight, 12 PM noon.
  CHECK(parse("01/01/1970 12:00:00 AM", "%m/%d/%Y %I:%M:%S %p").seconds == 0);
  CHECK(parse("01/01/1970 12:00:00 pm", "%m/%d/%Y %I:%M:%S %p").seconds == 43200);
}

TEST_CASE("fractional seconds") {
  const TimeStamp a = parse("2024-10-03 21:55:00.250", "%Y-%m-%d %H:%M:%S");
  CHECK(a.seconds == 1727992500);
  CHECK(a.fraction == doctest::Approx(0.25).epsilon(1e-15));
  CHECK(parse("2024-10-03 21:55:07,5", "%F %T").fraction == doctest::Approx(0.5));
  const TimeStamp b = parse("2024-10-03 21:55:07.123456", "%Y-%m-%d %H:%M:%S.%f");
  CHECK(b.seconds == 1727992507);
  CHECK(b.fraction == doctest::Approx(0.123456).epsilon(1e-15));
}

TEST_CASE("impossible or malformed stamps are refused with a reason") {
  CHECK(reject("2023-02-29 00:00:00", "%F %T") == "day 29 does not exist in month 2 of 2023");
  CHECK(reject("2024-13-01 00:00:00", "%F %T") == "month 13 does not exist");
  CHECK(reject("2024-04-31 00:00:00", "%F %T") == "day 31 does not exist in month 4 of 2024");
  CHECK(reject("2024-01-01 24:00:00", "%F %T") == "time of day 24:0:0 is out of range");
  CHECK(reject("2024-01-01 00:00:00 X", "%F %T") ==
        "unexpected text after the time stamp at character 20");
  CHECK(reject("2024/01/01 00:00:00", "%F %T") == "expected '-' at character 5");
  CHECK(reject("24-01-01 00:00:00", "%F %T") == "expected %Y at character 1");
  CHECK(reject("01/01/2024 13:00:00 PM", "%m/%d/%Y %I:%M:%S %p") ==
        "hour 13 is not 1-12 on a 12-hour clock");
  CHECK(reject("", "%F %T") == "expected %Y at character 1");
}

TEST_CASE("unusable time formats are explained") {
  CHECK(check_time_format("%Y-%m-%d %H:%M:%S") == "");
  CHECK(check_time_format("%Y-%m-%d %Q") ==
        "%Q is not supported (use %Y %y %m %d %e %H %I %M %S %f %p %b %B %F %T %%)");
  CHECK(check_time_format("%Y %") == "it ends with a lone '%'");
  CHECK(check_time_format("yyyy-MM-dd") ==
        "it has no % directive (use \"seconds\" for numeric time)");
  CHECK(check_time_format("%d/%m/%Y %I:%M") == "%I and %p go together (12-hour clock with AM/PM)");
  CHECK(check_time_format("%H:%M:%f") == "%f must follow %S as %S.%f or %S,%f");
}
