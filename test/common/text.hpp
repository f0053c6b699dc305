// Text helpers the tests share: a file's bytes as a string, and whether a text contains a part.
#pragma once

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

namespace valvediag::test {

// The whole file; "" when it cannot be read (the test's CHECK on the text then fails).
inline std::string slurp(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

inline bool has(const std::string& text, const std::string& part) {
  return text.find(part) != std::string::npos;
}

}  // namespace valvediag::test
