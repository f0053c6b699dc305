// Runs SQL on a database file as another program (or an older release) would: tests write
// tables the way earlier versions did, or tamper with a version row.
#pragma once

#include <doctest/doctest.h>
#include <sqlite3.h>

#include <cmath>
#include <filesystem>
#include <string>

namespace valvediag::test {

inline void exec_sql(const std::filesystem::path& db, const std::string& sql) {
  sqlite3* h = nullptr;
  REQUIRE(sqlite3_open(db.c_str(), &h) == SQLITE_OK);
  char* err = nullptr;
  const int rc = sqlite3_exec(h, sql.c_str(), nullptr, nullptr, &err);
  const std::string msg = err ? err : "";
  sqlite3_free(err);
  sqlite3_close(h);
  REQUIRE_MESSAGE(rc == SQLITE_OK, msg);
}

// One number (and, when asked, its text) of a query: NaN when the file cannot be opened or the
// query gives no row. Read-only unless told: a test that checks a file is left as it was must not
// open it for writing.
inline double query_scalar(const std::string& db, const std::string& sql,
                           std::string* text = nullptr, bool read_only = true) {
  sqlite3* c = nullptr;
  double v = std::nan("");
  if (sqlite3_open_v2(db.c_str(), &c, read_only ? SQLITE_OPEN_READONLY : SQLITE_OPEN_READWRITE,
                      nullptr) == SQLITE_OK) {
    sqlite3_busy_timeout(c, 2000);
    sqlite3_stmt* s = nullptr;
    if (sqlite3_prepare_v2(c, sql.c_str(), -1, &s, nullptr) == SQLITE_OK &&
        sqlite3_step(s) == SQLITE_ROW) {
      v = sqlite3_column_double(s, 0);
      if (text && sqlite3_column_text(s, 0))
        *text = reinterpret_cast<const char*>(sqlite3_column_text(s, 0));
    }
    sqlite3_finalize(s);
  }
  sqlite3_close(c);
  return v;
}

}  // namespace valvediag::test
