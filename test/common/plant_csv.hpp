// The layout of the historian exports in shared/data/plant-loops, for tests that read them in
// process. The CLI equivalent: --delimiter tab --skip-lines 2 --skip-after-header 2
// --time-format '%Y-%m-%d %H:%M:%S' --t 1 --op '*.MV' --pv '*.PV' --sp '*.SV'.
#pragma once

#include <string>
#include <vector>

#include "valvediag/io/csv_reader.hpp"

namespace valvediag::test {

inline CsvOptions plant_csv_options() {
  CsvOptions o;
  o.delimiter = "tab";
  o.skip_lines = 2;         // title line; column count / sample period / start / row count
  o.skip_after_header = 2;  // descriptions; identification settings
  o.time_format = "%Y-%m-%d %H:%M:%S";
  o.t_column.assign(1, '1');  // column 1; not = "1": GCC 12's -Wrestrict misfires on it
  o.op_column = "*.MV";
  o.pv_column = "*.PV";
  o.sp_column = "*.SV";
  return o;
}

// The same layout as command-line options, appended to `args`.
inline std::vector<std::string> with_plant_layout(std::vector<std::string> args) {
  for (const char* x :
       {"--delimiter", "tab", "--skip-lines", "2", "--skip-after-header", "2", "--time-format",
        "%Y-%m-%d %H:%M:%S", "--t", "1", "--op", "*.MV", "--pv", "*.PV", "--sp", "*.SV"})
    args.push_back(x);
  return args;
}

}  // namespace valvediag::test
