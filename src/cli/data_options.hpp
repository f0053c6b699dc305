// The data options every analysis command takes (CSV file, column remapping, historian layout),
// registered once here and turned into LoopData.
#pragma once

#include <CLI/CLI.hpp>
#include <memory>
#include <string>
#include <vector>

#include "valvediag/csv_reader.hpp"
#include "valvediag/loop_data.hpp"

namespace valvediag::cli {

struct DataOptions {
  std::string data;
  CsvOptions csv;
  std::string sample_period;
  std::string decimal = ".";
};

// Adds the positional DATA and the input options (group "Input"). DATA may be optional when the
// command has another source (fit --db).
void add_data_options(CLI::App* cmd, DataOptions& d, bool required = true);
// Reads the data; notes (columns used, time origin, resampling) go to `notes`.
LoopData load_data(DataOptions& d, std::vector<std::string>& notes);

}  // namespace valvediag::cli
