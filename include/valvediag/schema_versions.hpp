// Versions of the tables each component keeps in a site database. The recorder and the sweep
// store share one SQLite file, so PRAGMA user_version (one per file) cannot version them: each
// component has a row in schema_versions. A component migrates its own tables when it opens the
// file and refuses tables newer than it reads, so nothing recorded is lost or misread.
#pragma once

#include <string>

struct sqlite3;

namespace valvediag {

// The version of `component`'s tables in `db`: its row in schema_versions; without one, 1 when
// `first_table` (a table of the component's first release) exists, as in files written before
// versioning, and 0 when the file holds none of its tables. Reads only. Throws
// std::runtime_error naming `path` when SQLite fails.
int schema_version(sqlite3* db, const std::string& path, const std::string& component,
                   const std::string& first_table);

// Records that `component`'s tables are at `version`, creating schema_versions when needed.
// Call inside the transaction that brought the tables there.
void set_schema_version(sqlite3* db, const std::string& path, const std::string& component,
                        int version);

// Throws std::runtime_error naming `path` when `found` is newer than `supported`: tables a newer
// valvediag wrote may mean something this one does not know. `tables` names them ("sweep").
void require_known_schema(const std::string& path, const std::string& tables, int found,
                          int supported);

}  // namespace valvediag
