// Small helpers the diagnosis, io and sim libraries' files shared as private copies: a printf into
// a std::string (and numbers in %.6g and %.10g) for their one-sentence summaries and messages,
// and order statistics for robust noise and span figures. Standard library only.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdarg>
#include <cstddef>
#include <cstdio>
#include <string>
#include <vector>

namespace valvediag {

// printf into a string of the exact length. The format attribute lets the compiler check every
// literal format against its arguments (-Wformat, an error under -Werror).
[[gnu::format(printf, 1, 2)]] inline std::string strprintf(const char* format, ...) {
  std::va_list args;
  va_start(args, format);
  std::va_list again;
  va_copy(again, args);
  const int n = std::vsnprintf(nullptr, 0, format, args);
  va_end(args);
  std::string s(n > 0 ? static_cast<std::size_t>(n) : 0, '\0');
  if (n > 0) std::vsnprintf(s.data(), s.size() + 1, format, again);
  va_end(again);
  return s;
}

// v as printf's "%.6g": the short form in which the readers and data checks quote values.
inline std::string num6g(double v) {
  return strprintf("%.6g", v);
}

// v as printf's "%.10g": a model's parameters in its one-line description, close to exact
// without a round trip's 17 digits.
inline std::string num10g(double v) {
  return strprintf("%.10g", v);
}

// The sample at rank round(p (n - 1)) of v (0 <= p <= 1): no interpolation, so the median of an
// even count is the upper middle sample. NaN for an empty v.
inline double quantile(std::vector<double> v, double p) {
  if (v.empty()) return std::nan("");
  const double last = static_cast<double>(v.size() - 1);
  const auto k = static_cast<std::size_t>(std::llround(std::clamp(p, 0.0, 1.0) * last));
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(k), v.end());
  return v[k];
}

inline double median(std::vector<double> v) {
  return quantile(std::move(v), 0.5);
}

}  // namespace valvediag
