#include "valvediag/io/data_checks.hpp"

#include <algorithm>
#include <cmath>
#include <string>

#include "valvediag/io/data_error.hpp"
#include "valvediag/util/text_stats.hpp"

namespace valvediag {
namespace {

void check_finite(const LoopData& d, const std::vector<double>& v, const char* name) {
  for (std::size_t i = 0; i < v.size(); ++i)
    if (!std::isfinite(v[i]))
      throw DataError(d.source, 0, name,
                      "sample " + std::to_string(i + 1) + " is " + num6g(v[i]) +
                          " (NaN or infinite values cannot be used)");
}

void check_signal(const LoopData& d, const std::vector<double>& v, const char* name) {
  for (std::size_t i = 0; i < v.size(); ++i)
    if (const std::string why = signal_value_problem(v[i]); !why.empty())
      throw DataError(d.source, 0, name, "sample " + std::to_string(i + 1) + ": " + why);
}

}  // namespace

std::string signal_value_problem(double v, std::string_view shown) {
  const std::string value = shown.empty() ? num6g(v) : std::string(shown);
  if (!std::isfinite(v)) return value + " is NaN or infinite (remove the row or fill it in)";
  if (std::abs(v) > kMaxSignalMagnitude)
    return value +
           " is no measurement (beyond +-1e12 in any unit: a historian's bad-value marker or a "
           "corrupt cell; remove the row or fill it in)";
  return {};
}

void check_loop_data(const LoopData& d) {
  const std::size_t n = d.t.size();
  auto same_size = [&](const std::vector<double>& v, const char* name, bool optional) {
    if (v.size() == n || (optional && v.empty())) return;
    throw DataError(d.source, 0, name,
                    std::to_string(v.size()) + " samples, but t has " + std::to_string(n) +
                        " (the series must be aligned)");
  };
  same_size(d.op, "op", false);
  same_size(d.pv, "pv", false);
  same_size(d.sp, "sp", true);
  same_size(d.mv, "mv", true);
  check_finite(d, d.t, "t");
  check_signal(d, d.op, "op");
  check_signal(d, d.pv, "pv");
  check_signal(d, d.sp, "sp");
  check_signal(d, d.mv, "mv");
  for (std::size_t i = 1; i < n; ++i)
    if (!(d.t[i] > d.t[i - 1]))
      throw DataError(d.source, 0, "t",
                      "time does not increase at sample " + std::to_string(i + 1) +
                          " (t = " + num6g(d.t[i]) + " s after " + num6g(d.t[i - 1]) + " s)");
}

void check_identifiable_data(const LoopData& d, std::size_t min_samples, std::string_view model) {
  check_loop_data(d);
  const std::string what = model.empty() ? "the requested model" : "model " + std::string(model);
  if (d.size() < min_samples)
    throw DataError(d.source, 0, "",
                    "only " + std::to_string(d.size()) + " samples, but " + what +
                        " needs at least " + std::to_string(min_samples) +
                        " (use a longer record or a model with fewer parameters)");
  auto constant = [&](const std::vector<double>& v, const char* name, const std::string& hint) {
    if (v.empty()) return;
    const auto [lo, hi] = std::minmax_element(v.begin(), v.end());
    if (*lo == *hi)
      throw DataError(d.source, 0, name,
                      "constant at " + num6g(*lo) + " in all " + std::to_string(v.size()) +
                          " samples: nothing to identify (" + hint + ")");
  };
  constant(d.op, "op", "the controller output must move; is it the right column?");
  constant(d.pv, "pv", "a dead sensor or the wrong column?");
}

}  // namespace valvediag
