#include "valvediag/recorder/schema_versions.hpp"

#include <sqlite3.h>

#include <optional>
#include <stdexcept>

namespace valvediag {

namespace {

// The first integer of the first row of `sql` with `text` bound to ?1, or nullopt for no row.
std::optional<int> first_integer(sqlite3* db, const std::string& path, const char* sql,
                                 const std::string& text) {
  // The first read of a file: a file that is not SQLite fails here.
  auto fail = [&] {
    throw std::runtime_error(path + ": reading the schema versions: " + sqlite3_errmsg(db) +
                             " (is this a valvediag site database?)");
  };
  sqlite3_stmt* s = nullptr;
  if (sqlite3_prepare_v2(db, sql, -1, &s, nullptr) != SQLITE_OK) fail();
  sqlite3_bind_text(s, 1, text.c_str(), -1, SQLITE_TRANSIENT);
  std::optional<int> v;
  const int rc = sqlite3_step(s);
  if (rc == SQLITE_ROW) v = sqlite3_column_int(s, 0);
  sqlite3_finalize(s);
  if (rc != SQLITE_ROW && rc != SQLITE_DONE) fail();
  return v;
}

bool has_table(sqlite3* db, const std::string& path, const std::string& table) {
  return first_integer(db, path, "SELECT 1 FROM sqlite_master WHERE type = 'table' AND name = ?1",
                       table)
      .has_value();
}

}  // namespace

int known_schema_version(sqlite3* db, const std::string& path, const SchemaTables& t) {
  std::optional<int> row;
  if (has_table(db, path, "schema_versions"))
    row = first_integer(db, path, "SELECT version FROM schema_versions WHERE component = ?1",
                        t.component);
  const int v = row ? *row : has_table(db, path, t.first_table) ? 1 : 0;
  if (v > t.version)
    throw std::runtime_error(path + ": its " + t.name + " tables are version " + std::to_string(v) +
                             ", written by a newer valvediag; this one reads up to version " +
                             std::to_string(t.version) + ": update valvediag or use another --db");
  return v;
}

void set_schema_version(sqlite3* db, const std::string& path, const SchemaTables& t) {
  auto fail = [&] {
    throw std::runtime_error(path + ": recording the schema version: " + sqlite3_errmsg(db) +
                             " (check the disk has space and the file is writable)");
  };
  if (sqlite3_exec(db,
                   "CREATE TABLE IF NOT EXISTS schema_versions(component TEXT PRIMARY KEY, "
                   "version INTEGER NOT NULL)",
                   nullptr, nullptr, nullptr) != SQLITE_OK)
    fail();
  sqlite3_stmt* s = nullptr;
  if (sqlite3_prepare_v2(
          db, "INSERT OR REPLACE INTO schema_versions(component, version) VALUES(?1, ?2)", -1, &s,
          nullptr) != SQLITE_OK)
    fail();
  sqlite3_bind_text(s, 1, t.component, -1, SQLITE_TRANSIENT);
  sqlite3_bind_int(s, 2, t.version);
  const int rc = sqlite3_step(s);
  sqlite3_finalize(s);
  if (rc != SQLITE_DONE) fail();
}

}  // namespace valvediag
