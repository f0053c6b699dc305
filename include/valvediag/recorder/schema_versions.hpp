// Versions of the tables each component keeps in a site database. The recorder and the sweep
// store share one SQLite file, so PRAGMA user_version (one per file) cannot version them: each
// component has a row in schema_versions. A component migrates its own tables when it opens the
// file and refuses tables newer than it reads, so nothing recorded is lost or misread.
#pragma once

#include <string>

struct sqlite3;

namespace valvediag {

// One component's tables: its row's name, a table of its first release (files written before
// versioning have it but no row), what messages call the tables, and the version this build
// writes and reads.
struct SchemaTables {
  const char* component;
  const char* first_table;
  const char* name;
  int version;
};

// The version of `t`'s tables in `db`: its row in schema_versions; without one, 1 when
// t.first_table exists and 0 when the file holds none of its tables. Reads only. Throws
// std::runtime_error naming `path` when SQLite fails or when the tables are newer than
// t.version (a newer valvediag's tables may mean something this one does not know).
int known_schema_version(sqlite3* db, const std::string& path, const SchemaTables& t);

// Records that `t`'s tables are at t.version, creating schema_versions when needed. Call inside
// the transaction that brought the tables there.
void set_schema_version(sqlite3* db, const std::string& path, const SchemaTables& t);

}  // namespace valvediag
