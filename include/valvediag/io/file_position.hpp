// "<file>:<line>:<column>: <key>: <problem>", leaving out the parts that are unknown (line or
// column 0, empty key): the one format of every config and scenario file error.
#pragma once

#include <string>

namespace valvediag {

inline std::string file_position_message(const std::string& file, int line, int column,
                                         const std::string& key, const std::string& problem) {
  // Appended piece by piece: g++ 12 warns falsely (-Wrestrict) on "literal" + std::string.
  std::string m = file;
  if (line > 0) {
    m += ':';
    m += std::to_string(line);
    if (column > 0) {
      m += ':';
      m += std::to_string(column);
    }
  }
  m += ": ";
  if (!key.empty()) {
    m += key;
    m += ": ";
  }
  m += problem;
  return m;
}

}  // namespace valvediag
