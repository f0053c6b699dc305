#include "valvediag/recorder/recording_history.hpp"

#include <sqlite3.h>

#include <cmath>
#include <filesystem>
#include <stdexcept>

#include "valvediag/recorder/recorder.hpp"

namespace valvediag {

namespace {

const char* kHistorySchema = R"sql(
CREATE TABLE IF NOT EXISTS model_history(
  id INTEGER PRIMARY KEY,
  run_id INTEGER NOT NULL,
  loop TEXT NOT NULL,
  reading TEXT NOT NULL,
  model TEXT NOT NULL,
  time_utc TEXT NOT NULL,
  entry TEXT NOT NULL);
CREATE INDEX IF NOT EXISTS model_history_key ON model_history(run_id, loop, reading, id);
)sql";

// One connection, closed however the function ends.
struct Connection {
  sqlite3* c = nullptr;
  std::string path;
  Connection(const std::string& p, int flags) : path(p) {
    if (!std::filesystem::exists(p))
      throw std::runtime_error(p + ": no such database; record one with valvediag record --db " +
                               p);
    if (sqlite3_open_v2(p.c_str(), &c, flags, nullptr) != SQLITE_OK) {
      const std::string m = c ? sqlite3_errmsg(c) : "out of memory";
      sqlite3_close(c);
      c = nullptr;
      throw std::runtime_error(p + ": cannot open the database: " + m);
    }
  }
  ~Connection() { sqlite3_close(c); }
  Connection(const Connection&) = delete;
  Connection& operator=(const Connection&) = delete;

  [[noreturn]] void fail(const std::string& what, int rc) const {
    if (rc == SQLITE_BUSY || rc == SQLITE_LOCKED)
      throw DatabaseBusyError(path + ": database busy (locked by another process) while " + what);
    if (rc == SQLITE_READONLY || rc == SQLITE_CANTOPEN || rc == SQLITE_PERM)
      throw std::runtime_error(path + ": read-only (" + sqlite3_errmsg(c) + ") while " + what);
    throw std::runtime_error(path + ": " + what + ": " + sqlite3_errmsg(c));
  }
  void exec(const char* sql, const std::string& what) {
    const int rc = sqlite3_exec(c, sql, nullptr, nullptr, nullptr);
    if (rc != SQLITE_OK) fail(what, rc);
  }
  sqlite3_stmt* prepare(const char* sql, const std::string& what) {
    sqlite3_stmt* s = nullptr;
    const int rc = sqlite3_prepare_v2(c, sql, -1, &s, nullptr);
    if (rc != SQLITE_OK) fail(what, rc);
    return s;
  }
  void bind_key(sqlite3_stmt* s, const RecordingHistoryKey& k) {
    sqlite3_bind_int64(s, 1, k.run);
    sqlite3_bind_text(s, 2, k.loop.c_str(), -1, SQLITE_TRANSIENT);
    sqlite3_bind_text(s, 3, k.reading.c_str(), -1, SQLITE_TRANSIENT);
  }
  std::size_t count(const RecordingHistoryKey& k, const std::string& what) {
    sqlite3_stmt* s = prepare(
        "SELECT COUNT(*) FROM model_history WHERE run_id = ?1 AND loop = ?2 AND reading = ?3",
        what);
    bind_key(s, k);
    const int rc = sqlite3_step(s);
    const auto n = rc == SQLITE_ROW ? static_cast<std::size_t>(sqlite3_column_int64(s, 0)) : 0;
    sqlite3_finalize(s);
    if (rc != SQLITE_ROW) fail(what, rc);
    return n;
  }
};

}  // namespace

std::vector<std::string> load_recording_history(const std::string& db_path,
                                                const RecordingHistoryKey& key) {
  Connection db(db_path, SQLITE_OPEN_READONLY);
  sqlite3_busy_timeout(db.c, 5000);
  if (known_schema_version(db.c, db_path, kModelHistoryTables) == 0) return {};
  const std::string what = "reading the model history";
  sqlite3_stmt* s = db.prepare(
      "SELECT entry FROM model_history WHERE run_id = ?1 AND loop = ?2 AND reading = ?3 "
      "ORDER BY id",
      what);
  db.bind_key(s, key);
  std::vector<std::string> out;
  int rc = 0;
  while ((rc = sqlite3_step(s)) == SQLITE_ROW) {
    const unsigned char* t = sqlite3_column_text(s, 0);
    out.emplace_back(t ? reinterpret_cast<const char*>(t) : "");
  }
  sqlite3_finalize(s);
  if (rc != SQLITE_DONE) db.fail(what, rc);
  return out;
}

std::size_t append_recording_history(const std::string& db_path, const RecordingHistoryKey& key,
                                     const std::vector<StoredHistoryEntry>& entries,
                                     double busy_s) {
  Connection db(db_path, SQLITE_OPEN_READWRITE);
  if (sqlite3_db_readonly(db.c, "main") == 1)
    throw std::runtime_error(db_path + ": read-only (the file is write-protected)");
  sqlite3_busy_timeout(db.c, static_cast<int>(std::lround(busy_s * 1e3)));
  const std::string what = "adding to the model history";
  db.exec("PRAGMA synchronous=FULL", what);  // as the recorder: a committed entry stays
  db.exec("BEGIN IMMEDIATE", what);
  try {
    if (known_schema_version(db.c, db_path, kModelHistoryTables) < 1) {
      db.exec(kHistorySchema, what);
      set_schema_version(db.c, db_path, kModelHistoryTables);
    }
    sqlite3_stmt* s = db.prepare(
        "INSERT INTO model_history(run_id, loop, reading, model, time_utc, entry) "
        "VALUES(?1, ?2, ?3, ?4, ?5, ?6)",
        what);
    for (const StoredHistoryEntry& e : entries) {
      db.bind_key(s, key);
      sqlite3_bind_text(s, 4, e.model.c_str(), -1, SQLITE_TRANSIENT);
      sqlite3_bind_text(s, 5, e.time.c_str(), -1, SQLITE_TRANSIENT);
      sqlite3_bind_text(s, 6, e.json.c_str(), -1, SQLITE_TRANSIENT);
      const int rc = sqlite3_step(s);
      sqlite3_reset(s);
      if (rc != SQLITE_DONE) {
        sqlite3_finalize(s);
        db.fail(what, rc);
      }
    }
    sqlite3_finalize(s);
    const std::size_t n = db.count(key, what);
    db.exec("COMMIT", what);
    return n;
  } catch (...) {
    sqlite3_exec(db.c, "ROLLBACK", nullptr, nullptr, nullptr);
    throw;
  }
}

}  // namespace valvediag
