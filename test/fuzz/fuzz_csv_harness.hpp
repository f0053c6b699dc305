// Shared by the libFuzzer target and test_io (which replays the seed corpus and every saved
// crash input): the first two bytes choose reader options, the rest is the file text.
#pragma once

#include <cmath>
#include <optional>
#include <string>
#include <string_view>

#include "valvediag/io/csv_reader.hpp"
#include "valvediag/io/data_checks.hpp"
#include "valvediag/io/data_error.hpp"

namespace valvediag::fuzz {

inline CsvOptions options_from(std::string_view& data) {
  const unsigned char a = data.size() > 0 ? static_cast<unsigned char>(data[0]) : 0;
  const unsigned char b = data.size() > 1 ? static_cast<unsigned char>(data[1]) : 0;
  data.remove_prefix(data.size() < 2 ? data.size() : 2);
  static const char* const kDelimiters[] = {"auto", ",", ";", "tab", "space", "|", "auto", ","};
  static const char* const kFormats[] = {"seconds", "%Y-%m-%d %H:%M:%S", "%m/%d/%Y %I:%M:%S %p",
                                         "%d-%b-%y %T"};
  // t, op, pv, sp, mv: default names, column numbers, wildcards (as for historian tags), no time.
  static const char* const kColumns[4][5] = {{"t", "op", "pv", "", ""},
                                             {"1", "2", "3", "4", ""},
                                             {"t*", "*op*", "*.p?", "", "none"},
                                             {"none", "op", "pv", "", ""}};
  const auto& c = kColumns[(b >> 4) & 3];
  std::optional<double> period;
  if ((a >> 6) & 1) period = (a >> 7) & 1 ? 0.25 : 1.0;
  if (c[0] == std::string_view("none") && !period) period = 0.5;
  // Built in one initializer: g++ 12 warns falsely (-Wrestrict) on assigning short literals.
  return CsvOptions{.format = (b >> 7) & 1 ? "auto" : "plain",  // bit 7: sniff the layout
                    .delimiter = kDelimiters[a & 7],
                    .skip_lines = b & 3u,
                    .skip_after_header = ((b >> 2) & 1u) * 2,  // 2 as in the plant-loop exports
                    .time_format = kFormats[(a >> 3) & 3],
                    .t_column = c[0],
                    .op_column = c[1],
                    .pv_column = c[2],
                    .sp_column = c[3],
                    .mv_column = c[4],
                    .resample = ((a >> 5) & 1) != 0,
                    .sample_period = period,
                    .decimal = (b >> 3) & 1 ? ',' : '.',
                    .max_rows = (b >> 6) & 1 ? 4u : kDefaultMaxRows};
}

// "" when the input parsed into consistent data or was refused with a DataError; otherwise what
// is wrong. Any other exception escapes: that is a bug too.
inline std::string run_csv(std::string_view data) {
  const CsvOptions o = options_from(data);
  LoopData d;
  try {
    d = parse_loop_csv(data, o, "fuzz.csv");
  } catch (const DataError& e) {
    if (std::string_view(e.what()).substr(0, 8) != "fuzz.csv") return "message without file name";
    return "";
  }
  const std::size_t n = d.t.size();
  if (n < 2) return "fewer than 2 samples accepted";
  if (d.op.size() != n || d.pv.size() != n) return "op/pv length differs from t";
  if (!(d.sp.empty() || d.sp.size() == n) || !(d.mv.empty() || d.mv.size() == n))
    return "sp/mv length differs from t";
  if (!o.resample && n > o.max_rows) return "more rows than max_rows accepted";
  for (std::size_t i = 0; i < n; ++i) {
    if (!std::isfinite(d.t[i]) || !std::isfinite(d.op[i]) || !std::isfinite(d.pv[i]))
      return "non-finite value accepted";
    if ((!d.sp.empty() && !std::isfinite(d.sp[i])) || (!d.mv.empty() && !std::isfinite(d.mv[i])))
      return "non-finite sp/mv accepted";
    // A historian's bad-value marker (1e308, DBL_MAX) is no measurement.
    if (std::fabs(d.op[i]) > kMaxSignalMagnitude || std::fabs(d.pv[i]) > kMaxSignalMagnitude)
      return "op/pv beyond kMaxSignalMagnitude accepted";
    if (i > 0 && !(d.t[i] > d.t[i - 1])) return "time not increasing";
  }
  bool constant = true;
  for (std::size_t i = 1; i < n; ++i) constant = constant && d.op[i] == d.op[0];
  if (constant) return "constant op accepted";
  // Accepted data is uniformly sampled to within the tolerance (exactly so after resampling).
  const double period = d.t[1] - d.t[0];
  for (std::size_t i = 1; i < n; ++i) {
    const double step = d.t[i] - d.t[i - 1];
    if (std::fabs(step - period) > 2.5 * kSamplingTolerance * period + 1e-9 * std::fabs(d.t[i]))
      return "irregular sampling accepted";
  }
  return "";
}

}  // namespace valvediag::fuzz
