#include "time_parse.hpp"

#include <array>
#include <cctype>

namespace valvediag::detail {
namespace {

constexpr std::array<std::string_view, 12> kMonths = {
    "january", "february", "march",     "april",   "may",      "june",
    "july",    "august",   "september", "october", "november", "december"};

bool is_leap(std::int64_t y) {
  return (y % 4 == 0 && y % 100 != 0) || y % 400 == 0;
}

unsigned days_in_month(std::int64_t y, unsigned m) {
  static constexpr unsigned kDays[] = {31, 28, 31, 30, 31, 30, 31, 31, 30, 31, 30, 31};
  return m == 2 && is_leap(y) ? 29 : kDays[m - 1];
}

char lower(char c) {
  return static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
}
bool is_digit(char c) {
  return c >= '0' && c <= '9';
}
bool is_blank(char c) {
  return c == ' ' || c == '\t';
}

// Reads min_digits..max_digits digits at text[pos].
bool read_int(std::string_view text, std::size_t& pos, int min_digits, int max_digits, int& out) {
  int n = 0;
  int v = 0;
  while (n < max_digits && pos < text.size() && is_digit(text[pos])) {
    v = v * 10 + (text[pos] - '0');
    ++pos;
    ++n;
  }
  out = v;
  return n >= min_digits;
}

// A fraction of a second: at least one digit; digits past the 18th are below any clock's
// resolution and only checked to be digits.
bool read_fraction(std::string_view text, std::size_t& pos, double& out) {
  std::int64_t num = 0;
  double scale = 1.0;
  int n = 0;
  while (pos < text.size() && is_digit(text[pos])) {
    if (n < 18) {
      num = num * 10 + (text[pos] - '0');
      scale *= 10.0;
    }
    ++pos;
    ++n;
  }
  out = static_cast<double>(num) / scale;
  return n > 0;
}

// English month name, full or first three letters, any case.
bool read_month_name(std::string_view text, std::size_t& pos, int& month) {
  for (std::size_t m = 0; m < kMonths.size(); ++m) {
    const std::string_view name = kMonths[m];
    std::size_t k = 0;
    while (k < name.size() && pos + k < text.size() && lower(text[pos + k]) == name[k]) ++k;
    if (k == name.size() ||
        (k == 3 &&
         !(pos + k < text.size() && std::isalpha(static_cast<unsigned char>(text[pos + k]))))) {
      pos += k;
      month = static_cast<int>(m) + 1;
      return true;
    }
  }
  return false;
}

struct Fields {
  int year = 1970, month = 1, day = 1, hour = 0, minute = 0, second = 0;
  double fraction = 0.0;
  int pm = -1;  // -1: no %p, 0: AM, 1: PM
  bool hour12 = false;
};

}  // namespace

std::string expand_time_format(std::string_view format) {
  std::string out;
  for (std::size_t i = 0; i < format.size(); ++i) {
    if (format[i] == '%' && i + 1 < format.size() &&
        (format[i + 1] == 'F' || format[i + 1] == 'T')) {
      out += format[i + 1] == 'F' ? "%Y-%m-%d" : "%H:%M:%S";
      ++i;
    } else {
      out += format[i];
    }
  }
  return out;
}

namespace {

bool parse_fields(std::string_view text, std::string_view format, Fields& f, std::string& why) {
  std::size_t pos = 0;
  for (std::size_t i = 0; i < format.size(); ++i) {
    const char fc = format[i];
    if (fc == ' ') {  // one blank in the format matches any run of blanks
      if (pos >= text.size() || !is_blank(text[pos])) {
        why = "expected a space at character " + std::to_string(pos + 1);
        return false;
      }
      while (pos < text.size() && is_blank(text[pos])) ++pos;
      continue;
    }
    if (fc != '%') {
      if (pos >= text.size() || text[pos] != fc) {
        why = std::string("expected '") + fc + "' at character " + std::to_string(pos + 1);
        return false;
      }
      ++pos;
      continue;
    }
    if (i + 1 >= format.size()) {
      why = "the time format ends with a lone '%'";
      return false;
    }
    const char d = format[++i];
    const std::size_t start = pos;
    bool ok = true;
    switch (d) {
      case 'Y':
        ok = read_int(text, pos, 4, 4, f.year);
        break;
      case 'y':
        ok = read_int(text, pos, 2, 2, f.year);
        f.year += f.year < 69 ? 2000 : 1900;  // the POSIX pivot
        break;
      case 'm':
        ok = read_int(text, pos, 1, 2, f.month);
        break;
      case 'd':
      case 'e':
        ok = read_int(text, pos, 1, 2, f.day);
        break;
      case 'H':
        ok = read_int(text, pos, 1, 2, f.hour);
        break;
      case 'I':
        ok = read_int(text, pos, 1, 2, f.hour);
        f.hour12 = true;
        break;
      case 'M':
        ok = read_int(text, pos, 1, 2, f.minute);
        break;
      case 'S': {
        ok = read_int(text, pos, 1, 2, f.second);
        // "%S.%f" names the fraction itself; otherwise an optional fraction follows %S.
        const bool explicit_f = i + 3 < format.size() &&
                                (format[i + 1] == '.' || format[i + 1] == ',') &&
                                format[i + 2] == '%' && format[i + 3] == 'f';
        if (ok && !explicit_f && pos + 1 < text.size() && (text[pos] == '.' || text[pos] == ',') &&
            is_digit(text[pos + 1])) {
          ++pos;
          read_fraction(text, pos, f.fraction);
        }
        break;
      }
      case 'f':
        ok = read_fraction(text, pos, f.fraction);
        break;
      case 'p':
        if (pos + 1 < text.size() && (lower(text[pos]) == 'a' || lower(text[pos]) == 'p') &&
            lower(text[pos + 1]) == 'm') {
          f.pm = lower(text[pos]) == 'p' ? 1 : 0;
          pos += 2;
        } else {
          ok = false;
        }
        break;
      case 'b':
      case 'B':
      case 'h':
        ok = read_month_name(text, pos, f.month);
        break;
      case '%':
        ok = pos < text.size() && text[pos] == '%';
        if (ok) ++pos;
        break;
      default:  // rejected by check_time_format
        ok = false;
        break;
    }
    if (!ok) {
      why = "expected %" + std::string(1, d) + " at character " + std::to_string(start + 1);
      return false;
    }
  }
  if (pos != text.size()) {
    why = "unexpected text after the time stamp at character " + std::to_string(pos + 1);
    return false;
  }
  return true;
}

}  // namespace

std::int64_t days_from_civil(std::int64_t y, unsigned m, unsigned d) {
  // H. Hinnant's days_from_civil, public-domain algorithm for the proleptic Gregorian calendar.
  y -= m <= 2;
  const std::int64_t era = (y >= 0 ? y : y - 399) / 400;
  const unsigned yoe = static_cast<unsigned>(y - era * 400);
  const unsigned doy = (153 * (m + (m > 2 ? -3 : 9)) + 2) / 5 + d - 1;
  const unsigned doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
  return era * 146097 + static_cast<std::int64_t>(doe) - 719468;
}

std::string check_time_format(std::string_view format) {
  const std::string f = expand_time_format(format);
  int directives = 0;
  bool has_hour12 = false, has_pm = false, has_f = false;
  for (std::size_t i = 0; i < f.size(); ++i) {
    if (f[i] != '%') continue;
    if (i + 1 >= f.size()) return "it ends with a lone '%'";
    const char d = f[++i];
    if (std::string_view("YymdeHIMSfpbBh%").find(d) == std::string_view::npos)
      return std::string("%") + d +
             " is not supported (use %Y %y %m %d %e %H %I %M %S %f %p %b %B %F %T %%)";
    if (d != '%') ++directives;
    has_hour12 |= d == 'I';
    has_pm |= d == 'p';
    has_f |= d == 'f';
  }
  if (directives == 0) return "it has no % directive (use \"seconds\" for numeric time)";
  if (has_hour12 != has_pm) return "%I and %p go together (12-hour clock with AM/PM)";
  if (has_f && f.find("%S.%f") == std::string::npos && f.find("%S,%f") == std::string::npos)
    return "%f must follow %S as %S.%f or %S,%f";
  return {};
}

bool parse_time_stamp(std::string_view text, std::string_view format, TimeStamp& out,
                      std::string& why) {
  Fields f;
  if (!parse_fields(text, format, f, why)) return false;
  if (f.hour12) {
    if (f.hour < 1 || f.hour > 12) {
      why = "hour " + std::to_string(f.hour) + " is not 1-12 on a 12-hour clock";
      return false;
    }
    f.hour = f.hour % 12 + (f.pm == 1 ? 12 : 0);
  }
  if (f.month < 1 || f.month > 12) {
    why = "month " + std::to_string(f.month) + " does not exist";
    return false;
  }
  if (f.day < 1 || static_cast<unsigned>(f.day) > days_in_month(f.year, f.month)) {
    why = "day " + std::to_string(f.day) + " does not exist in month " + std::to_string(f.month) +
          " of " + std::to_string(f.year);
    return false;
  }
  if (f.hour > 23 || f.minute > 59 || f.second > 59) {
    why = "time of day " + std::to_string(f.hour) + ":" + std::to_string(f.minute) + ":" +
          std::to_string(f.second) + " is out of range";
    return false;
  }
  out.seconds =
      days_from_civil(f.year, static_cast<unsigned>(f.month), static_cast<unsigned>(f.day)) *
          86400 +
      f.hour * 3600 + f.minute * 60 + f.second;
  out.fraction = f.fraction;
  return true;
}

}  // namespace valvediag::detail
