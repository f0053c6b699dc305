// The data options every analysis command takes: a CSV file with its layout (column remapping,
// historian layout) or a recorded loop (--db/--loop/--from/--to), registered once here and
// turned into LoopData.
#pragma once

#include <CLI/CLI.hpp>
#include <memory>
#include <string>
#include <vector>

#include "valvediag/csv_reader.hpp"
#include "valvediag/loop_data.hpp"

namespace valvediag::cli {

struct DataOptions {
  std::string data;  // a CSV file; empty when the loop comes from --db
  CsvOptions csv;
  std::string sample_period;
  std::string decimal = ".";
  std::string db, loop, from, to;  // a recorded loop (valvediag record) instead of a file
};

// Adds the positional DATA, --db/--loop/--from/--to and the CSV layout options (group "Input").
void add_data_options(CLI::App* cmd, DataOptions& d);
// Reads the data from the file or the recording; notes (columns used, time origin, resampling)
// go to `notes`. Wrong combinations (both or neither source, --loop without --db) are
// UsageErrors.
LoopData load_data(DataOptions& d, std::vector<std::string>& notes);
// What the data is called in messages and which name its model history hangs off:
// the file, or "site.sqlite.FIC101" for a recorded loop.
std::string data_name(const DataOptions& d);

}  // namespace valvediag::cli
