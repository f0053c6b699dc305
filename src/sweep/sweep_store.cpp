#include "valvediag/sweep/sweep_store.hpp"

#include <sqlite3.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>

#include "valvediag/recorder/recorder.hpp"
#include "valvediag/recorder/schema_versions.hpp"

namespace valvediag {

namespace {

// Version 1 of the sweep tables, as the first release wrote them. Later versions are reached by
// the migrations in migrate(), so a fresh database and an old one take the same path.
const char* kSchemaV1 = R"sql(
CREATE TABLE IF NOT EXISTS sweeps(
  id INTEGER PRIMARY KEY,
  started_utc TEXT NOT NULL,
  finished_utc TEXT,
  source TEXT,
  shard TEXT,
  window_s REAL,
  status TEXT NOT NULL DEFAULT 'running');
CREATE TABLE IF NOT EXISTS sweep_results(
  sweep_id INTEGER NOT NULL REFERENCES sweeps(id),
  loop TEXT NOT NULL,
  verdict TEXT NOT NULL,
  severity REAL,
  stiction_percent REAL,
  slip_jump_percent REAL,
  model TEXT,
  fitness_percent REAL,
  validation_fitness_percent REAL,
  first_missing TEXT,
  oscillating INTEGER,
  period_s REAL,
  op_reversals_per_hour REAL,
  op_travel_percent_per_hour REAL,
  time_at_limits_percent REAL,
  error TEXT,
  result_json TEXT NOT NULL,
  PRIMARY KEY(sweep_id, loop));
)sql";

sqlite3* open_db(const std::string& path, int flags) {
  sqlite3* db = nullptr;
  if (sqlite3_open_v2(path.c_str(), &db, flags, nullptr) != SQLITE_OK) {
    const std::string msg = db ? sqlite3_errmsg(db) : "out of memory";
    sqlite3_close(db);
    throw std::runtime_error(path + ": cannot open the database: " + msg);
  }
  sqlite3_busy_timeout(db, 5000);  // a recorder may be writing to the same file
  return db;
}

}  // namespace

struct SweepStore::Impl {
  sqlite3* db = nullptr;
  std::string path;
  bool no_tables = false;  // opened read-only on a file without sweep tables
  void fail(const std::string& what) const {
    throw std::runtime_error(path + ": " + what + ": " + sqlite3_errmsg(db) +
                             " (is the disk full or the file read-only?)");
  }
  void exec(const char* sql) const {
    char* err = nullptr;
    if (sqlite3_exec(db, sql, nullptr, nullptr, &err) != SQLITE_OK) {
      const std::string m = err ? err : "error";
      sqlite3_free(err);
      throw std::runtime_error(path + ": " + m);
    }
  }
  sqlite3_stmt* prepare(const char* sql) const {
    sqlite3_stmt* s = nullptr;
    if (sqlite3_prepare_v2(db, sql, -1, &s, nullptr) != SQLITE_OK) fail("SQL");
    return s;
  }
  void migrate() const;
};

// Brings the sweep tables to kSweepSchemaVersion inside one transaction: two sweeps opening an
// old database at once migrate it once, and a failed step leaves it as it was.
void SweepStore::Impl::migrate() const {
  exec("BEGIN IMMEDIATE");
  try {
    const int v = known_schema_version(db, path, kSweepTables);
    if (v < 1) exec(kSchemaV1);
    // Version 2: the share of each record held out for scoring (sweep --validate). Sweeps
    // before the option all held out 0.3.
    if (v < 2)
      exec("ALTER TABLE sweeps ADD COLUMN validate REAL; UPDATE sweeps SET validate = 0.3");
    if (v < kSweepSchemaVersion) set_schema_version(db, path, kSweepTables);
    exec("COMMIT");
  } catch (...) {
    sqlite3_exec(db, "ROLLBACK", nullptr, nullptr, nullptr);
    throw;
  }
}

SweepStore::SweepStore(const std::string& db_path, Access access)
    : impl_(std::make_unique<Impl>()) {
  impl_->path = db_path;
  const bool read_only = access == Access::ReadOnly;
  impl_->db = open_db(
      db_path, read_only ? SQLITE_OPEN_READONLY : SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE);
  try {
    if (read_only) {
      const int v = known_schema_version(impl_->db, db_path, kSweepTables);
      impl_->no_tables = v == 0;  // nothing assessed yet: empty answers, not an error
      if (v > 0 && v < kSweepSchemaVersion)
        throw std::runtime_error(
            db_path + ": its sweep tables are version " + std::to_string(v) +
            ", from an older valvediag; the next sweep into it brings them to version " +
            std::to_string(kSweepSchemaVersion) + " (or run this on a writable copy)");
    } else {
      impl_->exec("PRAGMA journal_mode=WAL");
      impl_->migrate();
    }
  } catch (...) {
    sqlite3_close(impl_->db);
    throw;
  }
}

SweepStore::~SweepStore() {
  sqlite3_close(impl_->db);
}

std::int64_t SweepStore::begin_sweep(const SweepInfo& info) {
  sqlite3_stmt* s = impl_->prepare(
      "INSERT INTO sweeps(started_utc, source, shard, window_s, validate) "
      "VALUES(?, ?, ?, ?, ?)");
  sqlite3_bind_text(s, 1, info.started_utc.c_str(), -1, SQLITE_TRANSIENT);
  sqlite3_bind_text(s, 2, info.source.c_str(), -1, SQLITE_TRANSIENT);
  sqlite3_bind_text(s, 3, info.shard.c_str(), -1, SQLITE_TRANSIENT);
  sqlite3_bind_double(s, 4, info.window_s);
  sqlite3_bind_double(s, 5, info.validation_fraction);
  const int rc = sqlite3_step(s);
  sqlite3_finalize(s);
  if (rc != SQLITE_DONE) impl_->fail("cannot start the sweep");
  return sqlite3_last_insert_rowid(impl_->db);
}

void SweepStore::add_result(std::int64_t sweep, const LoopAssessment& a) {
  sqlite3_stmt* s = impl_->prepare(
      "INSERT OR REPLACE INTO sweep_results(sweep_id, loop, verdict, severity, stiction_percent, "
      "slip_jump_percent, model, fitness_percent, validation_fitness_percent, first_missing, "
      "oscillating, period_s, op_reversals_per_hour, op_travel_percent_per_hour, "
      "time_at_limits_percent, error, result_json) "
      "VALUES(?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)");
  auto real = [&](int i, double v) {
    if (std::isfinite(v))
      sqlite3_bind_double(s, i, v);
    else
      sqlite3_bind_null(s, i);
  };
  auto text = [&](int i, const std::string& v) {
    sqlite3_bind_text(s, i, v.c_str(), -1, SQLITE_TRANSIENT);
  };
  sqlite3_bind_int64(s, 1, sweep);
  text(2, a.loop);
  text(3, a.verdict);
  real(4, a.severity);
  real(5, a.stiction_percent);
  real(6, a.slip_jump_percent);
  text(7, a.model);
  real(8, a.fitness_percent);
  real(9, a.validation_fitness_percent);
  text(10, a.first_missing);
  sqlite3_bind_int(s, 11, a.health.oscillating ? 1 : 0);
  real(12, a.health.oscillating ? a.health.period_s : LoopAssessment::kNaN);
  real(13, a.health.op_reversals_per_hour);
  real(14, a.health.op_travel_percent_per_hour);
  real(15, a.health.time_at_limits_percent);
  text(16, a.error);
  text(17, assessment_json(a).dump());
  const int rc = sqlite3_step(s);
  sqlite3_finalize(s);
  if (rc != SQLITE_DONE) impl_->fail("cannot store the result of loop " + a.loop);
}

void SweepStore::end_sweep(std::int64_t sweep, const SweepInfo& info, const std::string& status) {
  sqlite3_stmt* s = impl_->prepare("UPDATE sweeps SET finished_utc = ?, status = ? WHERE id = ?");
  sqlite3_bind_text(s, 1, info.finished_utc.c_str(), -1, SQLITE_TRANSIENT);
  sqlite3_bind_text(s, 2, status.c_str(), -1, SQLITE_TRANSIENT);
  sqlite3_bind_int64(s, 3, sweep);
  const int rc = sqlite3_step(s);
  sqlite3_finalize(s);
  if (rc != SQLITE_DONE) impl_->fail("cannot close the sweep");
}

std::vector<TrendPoint> SweepStore::trend(const std::string& loop, int last) {
  if (impl_->no_tables) return {};
  sqlite3_stmt* s = impl_->prepare(
      "SELECT r.sweep_id, w.started_utc, r.result_json, w.validate FROM sweep_results r "
      "JOIN sweeps w ON w.id = r.sweep_id WHERE r.loop = ? ORDER BY r.sweep_id DESC LIMIT ?");
  sqlite3_bind_text(s, 1, loop.c_str(), -1, SQLITE_TRANSIENT);
  sqlite3_bind_int(s, 2, last);
  std::vector<TrendPoint> out;
  while (sqlite3_step(s) == SQLITE_ROW) {
    TrendPoint p;
    p.sweep = sqlite3_column_int64(s, 0);
    p.started_utc = reinterpret_cast<const char*>(sqlite3_column_text(s, 1));
    p.validation_fraction = sqlite3_column_double(s, 3);
    const auto* js = reinterpret_cast<const char*>(sqlite3_column_text(s, 2));
    try {
      p.result = assessment_from_json(nlohmann::json::parse(js ? js : ""));
    } catch (const std::exception& e) {
      sqlite3_finalize(s);
      throw std::runtime_error(impl_->path + ": sweep " + std::to_string(p.sweep) + ", loop " +
                               loop + ": stored result unreadable: " + e.what());
    }
    out.push_back(std::move(p));
  }
  sqlite3_finalize(s);
  return {out.rbegin(), out.rend()};
}

std::vector<std::string> SweepStore::assessed_loops() {
  if (impl_->no_tables) return {};
  sqlite3_stmt* s = impl_->prepare("SELECT DISTINCT loop FROM sweep_results ORDER BY loop");
  std::vector<std::string> out;
  while (sqlite3_step(s) == SQLITE_ROW)
    out.emplace_back(reinterpret_cast<const char*>(sqlite3_column_text(s, 0)));
  sqlite3_finalize(s);
  return out;
}

std::optional<double> recorded_end_s(const std::string& db_path, const std::string& loop,
                                     std::int64_t run) {
  const std::unique_ptr<sqlite3, int (*)(sqlite3*)> db(open_db(db_path, SQLITE_OPEN_READONLY),
                                                       sqlite3_close);
  // A database without recordings (only sweep results) has recorded nothing.
  if (known_schema_version(db.get(), db_path, kRecordingTables) == 0) return std::nullopt;
  sqlite3_stmt* s = nullptr;
  const char* sql =
      "SELECT l.sample_period, (SELECT MAX(tick) FROM samples WHERE loop_id = l.id) FROM loops l "
      "WHERE l.name = ?1 AND (?2 = 0 OR l.run_id = ?2) ORDER BY l.run_id DESC LIMIT 1";
  if (sqlite3_prepare_v2(db.get(), sql, -1, &s, nullptr) != SQLITE_OK)
    throw std::runtime_error(db_path + ": " + sqlite3_errmsg(db.get()) +
                             " (is this a valvediag recording?)");
  sqlite3_bind_text(s, 1, loop.c_str(), -1, SQLITE_TRANSIENT);
  sqlite3_bind_int64(s, 2, run);
  std::optional<double> end;
  if (sqlite3_step(s) == SQLITE_ROW && sqlite3_column_type(s, 1) != SQLITE_NULL)
    end = (static_cast<double>(sqlite3_column_int64(s, 1)) + 1.0) * sqlite3_column_double(s, 0);
  sqlite3_finalize(s);
  return end;
}

std::optional<RecordedLoop> read_latest_window(const std::string& db_path, const std::string& loop,
                                               double window_s, std::size_t max_rows,
                                               std::int64_t run) {
  const auto end = recorded_end_s(db_path, loop, run);
  if (!end) return std::nullopt;
  return read_recorded_loop(db_path, loop, std::max(0.0, *end - window_s), *end, run,
                            /*longest_clean=*/true, kBridgedTicks, max_rows);
}

}  // namespace valvediag
