#include "valvediag/io/data_error.hpp"

#include <utility>

namespace valvediag {
namespace {

std::string compose(const std::string& file, std::size_t line, const std::string& column,
                    const std::string& problem, std::string_view role) {
  // append() only: g++ 12 reports a false -Wrestrict on "literal" + std::string here.
  std::string m;
  m.append(file.empty() ? "<data>" : file);
  if (line > 0) m.append(":").append(std::to_string(line));
  m.append(": ");
  if (!column.empty()) {
    m.append("column '").append(column).append("'");
    if (!role.empty() && role != column) m.append(" (").append(role).append(")");
    m.append(": ");
  }
  return m.append(problem);
}

}  // namespace

DataError::DataError(std::string file_, std::size_t line_, std::string column_,
                     const std::string& problem, std::string_view role)
    : std::runtime_error(compose(file_, line_, column_, problem, role)),
      file(std::move(file_)),
      line(line_),
      column(std::move(column_)) {}

DataError::DataError(Composed, const std::string& what, std::string file_, std::size_t line_,
                     std::string column_)
    : std::runtime_error(what), file(std::move(file_)), line(line_), column(std::move(column_)) {}

DataError DataError::rebuilt(std::string file, std::size_t line, std::string column,
                             const std::string& what) {
  return DataError(Composed{}, what, std::move(file), line, std::move(column));
}

}  // namespace valvediag
