// Writes loop data and result series as comma-separated text that read_loop_csv reads back
// bit for bit (numbers are written in the shortest form that round-trips).
#pragma once

#include <string>
#include <vector>

#include "valvediag/io/loop_data.hpp"

namespace valvediag {

// Columns t,op,pv then sp and mv when present. Throws std::runtime_error naming the path when
// the file cannot be written or the series lengths differ.
void write_loop_csv(const std::string& path, const LoopData& data);

// One column per series under the given header names; all series must have the same length.
// Names holding a comma, quote or line break are quoted. Throws std::runtime_error as above.
void write_columns_csv(const std::string& path, const std::vector<std::string>& names,
                       const std::vector<std::vector<double>>& columns);

}  // namespace valvediag
