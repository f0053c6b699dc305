#include "valvediag/io/csv_writer.hpp"

#include <cerrno>
#include <charconv>
#include <cstdio>
#include <stdexcept>
#include <system_error>

#include "valvediag/io/atomic_file.hpp"

namespace valvediag {
namespace {

std::string quoted_name(const std::string& name) {
  if (name.find_first_of(",\"\r\n") == std::string::npos && !name.empty() && name[0] != '#')
    return name;
  std::string q = "\"";
  for (char c : name) {
    q += c;
    if (c == '"') q += '"';
  }
  return q + "\"";
}

[[noreturn]] void fail(const std::string& path, const std::string& what) {
  throw std::runtime_error("cannot write " + path + ": " + what);
}

void write_table(const std::string& path, const std::vector<std::string>& names,
                 const std::vector<const std::vector<double>*>& columns) {
  if (names.size() != columns.size())
    fail(path, std::to_string(names.size()) + " names for " + std::to_string(columns.size()) +
                   " columns");
  if (columns.empty()) fail(path, "no columns to write");
  const std::size_t rows = columns[0]->size();
  for (std::size_t c = 0; c < columns.size(); ++c)
    if (columns[c]->size() != rows)
      fail(path, "column '" + names[c] + "' has " + std::to_string(columns[c]->size()) +
                     " values, column '" + names[0] + "' has " + std::to_string(rows));

  AtomicFile f(path);  // whole or absent, never through a planted link
  std::string out;
  for (std::size_t c = 0; c < names.size(); ++c) {
    if (c) out += ',';
    out += quoted_name(names[c]);
  }
  out += '\n';
  char buf[32];
  for (std::size_t r = 0; r < rows; ++r) {
    for (std::size_t c = 0; c < columns.size(); ++c) {
      if (c) out += ',';
      // Shortest text that reads back to the same double.
      const auto res = std::to_chars(buf, buf + sizeof buf, (*columns[c])[r]);
      out.append(buf, res.ptr);
    }
    out += '\n';
    if (out.size() >= (1u << 20)) {
      f.write(out);
      out.clear();
    }
  }
  f.write(out);
  f.commit();
}

}  // namespace

void write_loop_csv(const std::string& path, const LoopData& data) {
  std::vector<std::string> names = {"t", "op", "pv"};
  std::vector<const std::vector<double>*> cols = {&data.t, &data.op, &data.pv};
  if (data.has_sp()) {
    names.push_back("sp");
    cols.push_back(&data.sp);
  }
  if (data.has_mv()) {
    names.push_back("mv");
    cols.push_back(&data.mv);
  }
  write_table(path, names, cols);
}

void write_columns_csv(const std::string& path, const std::vector<std::string>& names,
                       const std::vector<std::vector<double>>& columns) {
  std::vector<const std::vector<double>*> cols;
  for (const auto& c : columns) cols.push_back(&c);
  write_table(path, names, cols);
}

}  // namespace valvediag
