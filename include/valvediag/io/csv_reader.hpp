// Reads one control loop from a delimited text file (CSV, historian exports).
//
// Layout (format "plain"): `skip_lines` raw lines, then (after blank and `#` comment lines) the
// header row, then `skip_after_header` raw lines (units, descriptions), then one sample per row.
// Blank and `#` lines among the data are ignored. Cells may be quoted ("a,b", "" for a quote). Line
// ends may be LF, CRLF or CR; a UTF-8 byte-order mark is skipped.
//
// The file is read line by line: memory follows the rows kept (CsvOptions::max_rows caps them),
// and a line longer than 1 MiB (binary data, /dev/zero) is refused at its line number.
//
// Format "auto" first sniffs the layout fields the user did not set (CsvOptions::given) from
// the file's first 200 lines (at most 1 MiB); README.md "Data input" says what it looks for.
//
// Every problem throws DataError naming the file, line and column: unreadable file, missing
// column, empty / non-numeric / NaN / infinite cell, a row with too few cells or with more cells
// than the header has names, time not increasing, irregular sampling (without resample), fewer
// than 2 samples, constant OP. Nothing is printed.
#pragma once

#include <cstddef>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "valvediag/io/loop_data.hpp"

namespace valvediag {

// 10 million rows: 115 days at 1 s, more than one analysis needs. Reading holds 32 to 48 bytes
// a row (t, op, pv, optional sp and mv, the row's line number): `fit` peaked at 340 MB refusing
// a file of t, op, pv just beyond the cap, well within a laptop.
inline constexpr std::size_t kDefaultMaxRows = 10'000'000;

// Which layout fields the user set: format "auto" sniffs only the others.
struct CsvGiven {
  bool delimiter = false, skip_lines = false, skip_after_header = false, time_format = false,
       decimal = false, t = false, op = false, pv = false, sp = false;
};

struct CsvOptions {
  // "plain": the layout below as it is. "auto": the fields not marked in `given` are sniffed
  // from the file's first lines: delimiter, lines before the header and between header and data,
  // the time column (or a date and a time-of-day column) and its date-time format, decimal comma,
  // historian tags (*.MV/.OP/.OUT: op,
  // *.PV: pv, *.SV/.SP: sp). A choice it cannot make (two *.PV columns, day/month order) is a
  // DataError naming the option that makes it.
  std::string format = "plain";
  CsvGiven given{};
  // ",", ";", "tab", "space" (runs of blanks), "|", any other single punctuation character, or
  // "auto": tab, ';' or ',' (whichever the header row has most of), else blanks.
  std::string delimiter = "auto";
  std::size_t skip_lines = 0;         // raw lines before the header row
  std::size_t skip_after_header = 0;  // raw lines between the header row and the first data row
  // "seconds": the time column is a number of seconds (kept as is). Otherwise a strftime-like
  // pattern of the time stamps, e.g. "%Y-%m-%d %H:%M:%S" or "%m/%d/%Y %I:%M:%S %p"; %S also takes
  // a fraction (".250"). Supported: %Y %y %m %d %e %H %I %M %S %f %p %b %B %F %T %%. Stamps are
  // read as given (no time zone or daylight-saving shift); t becomes seconds since the first row.
  std::string time_format = "seconds";
  // Column specs: a header name (exact, else unique case-insensitive match, `*` and `?` allowed
  // as wildcards), or a 1-based column number when all digits. sp and mv: empty means "use the
  // column named sp / mv if there is one"; "none" never reads it. t_column "none": there is no
  // time column and rows are `sample_period` seconds apart, starting at t = 0. t_column "A+B"
  // (when no column is named so): a stamp split over a date column A and a time-of-day column B,
  // read as A's cell, a space, B's cell; time_format covers both ("%d.%m.%Y %H:%M:%S").
  std::string t_column = "t";
  std::string op_column = "op";
  std::string pv_column = "pv";
  std::string sp_column;
  std::string mv_column;
  // Irregular time steps (more than 1 % off the median step) are refused unless resample is set;
  // then all signals are linearly interpolated onto a uniform grid from the first time stamp with
  // period sample_period, or the median step when it is not given.
  bool resample = false;
  std::optional<double> sample_period;  // s; without resample it must match the data's period
  char decimal = '.';                   // '.' or ',' (then '.' in a number is an error)
  // More data rows than this are refused (DataError at the first row beyond), so that a huge
  // or endless input cannot exhaust memory; at least 2.
  std::size_t max_rows = kDefaultMaxRows;
};

// Relative deviation of a time step from the median step above which sampling is irregular.
inline constexpr double kSamplingTolerance = 0.01;

// Reads `path`. LoopData::source is set to `path`. When `notes` is given, it receives short
// remarks on what was done (columns used, time origin, resampling) for the user to see.
LoopData read_loop_csv(const std::string& path, const CsvOptions& options,
                       std::vector<std::string>* notes = nullptr);

// The same on text already in memory; name_for_messages stands in for the file name.
LoopData parse_loop_csv(std::string_view text, const CsvOptions& options,
                        const std::string& name_for_messages,
                        std::vector<std::string>* notes = nullptr);

}  // namespace valvediag
