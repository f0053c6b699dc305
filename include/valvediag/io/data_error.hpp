// The one exception type for unusable input data. The CLI maps it to exit status 2, so its
// message must say where the problem is and what the user can do about it.
#pragma once

#include <cstddef>
#include <stdexcept>
#include <string>
#include <string_view>

namespace valvediag {

class DataError : public std::runtime_error {
 public:
  // what() reads "file:line: column 'name' (role): problem"; line 0 and an empty column are
  // left out. role is the meaning of the column (t, op, pv, sp, mv), shown when it differs from
  // the column's own name.
  DataError(std::string file, std::size_t line, std::string column, const std::string& problem,
            std::string_view role = {});

  // The same error rebuilt elsewhere (e.g. sent from the child process that read the file):
  // what() is taken as composed, not composed again.
  static DataError rebuilt(std::string file, std::size_t line, std::string column,
                           const std::string& what);

  std::string file;    // file (or data source) name as given by the caller
  std::size_t line;    // 1-based line in the file, 0 when the problem is not on one line
  std::string column;  // column name in the file, empty when the problem is not in one column

 private:
  struct Composed {};
  DataError(Composed, const std::string& what, std::string file, std::size_t line,
            std::string column);
};

}  // namespace valvediag
