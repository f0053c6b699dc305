// Parses CSV text as the file "data.csv", for the reader's and the sniffer's tests.
#pragma once

#include <string>
#include <vector>

#include "valvediag/io/csv_reader.hpp"

namespace valvediag::test {

inline LoopData parse(const std::string& text, const CsvOptions& o = {},
                      std::vector<std::string>* notes = nullptr) {
  return parse_loop_csv(text, o, "data.csv", notes);
}

}  // namespace valvediag::test
