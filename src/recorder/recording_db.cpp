// SQLite storage of recordings. WAL mode with synchronous=FULL: a committed transaction survives
// a killed process and a power cut (NORMAL would keep it through a kill only), and readers
// (export, fit) never block the recorder. Commits come every commit_interval_s, so the extra
// fsync per commit costs little.
#include <sqlite3.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <ctime>
#include <filesystem>
#include <type_traits>

#include "valvediag/io/data_checks.hpp"
#include "valvediag/io/data_error.hpp"
#include "valvediag/recorder/recorder.hpp"
#include "valvediag/recorder/recorder_lock.hpp"
#include "valvediag/recorder/schema_versions.hpp"
#include "valvediag/util/utc_time.hpp"

namespace valvediag {

namespace {
const char* kSchema = R"sql(
CREATE TABLE IF NOT EXISTS runs(
  id INTEGER PRIMARY KEY,
  started_utc TEXT NOT NULL,
  ended_utc TEXT,
  config_file TEXT,
  status TEXT NOT NULL DEFAULT 'recording');
CREATE TABLE IF NOT EXISTS loops(
  id INTEGER PRIMARY KEY,
  run_id INTEGER NOT NULL REFERENCES runs(id),
  name TEXT NOT NULL,
  sample_period REAL NOT NULL,
  has_sp INTEGER NOT NULL, has_mv INTEGER NOT NULL, has_mode INTEGER NOT NULL,
  UNIQUE(run_id, name));
-- One row per sample tick; q_* = 0 good, 1 stale, 2 comm-error, 3 missed, 4 invalid.
CREATE TABLE IF NOT EXISTS samples(
  loop_id INTEGER NOT NULL,
  tick INTEGER NOT NULL,
  wall REAL NOT NULL,
  lateness REAL NOT NULL,
  op REAL, pv REAL, sp REAL, mv REAL, mode REAL,
  q_op INTEGER NOT NULL, q_pv INTEGER NOT NULL, q_sp INTEGER NOT NULL,
  q_mv INTEGER NOT NULL, q_mode INTEGER NOT NULL,
  PRIMARY KEY(loop_id, tick)) WITHOUT ROWID;
-- Ticks [first_tick, last_tick] without good OP and PV, with the first problem seen.
CREATE TABLE IF NOT EXISTS gaps(
  loop_id INTEGER NOT NULL,
  first_tick INTEGER NOT NULL,
  last_tick INTEGER NOT NULL,
  reason TEXT NOT NULL);
)sql";

// Readers need recording tables this build understands.
void require_recording(sqlite3* db, const std::string& path) {
  if (known_schema_version(db, path, kRecordingTables) == 0)
    throw std::runtime_error(
        path + ": holds no recordings; record one with valvediag record --db " + path);
}

}  // namespace

struct RecordingDb::Impl {
  sqlite3* db = nullptr;
  sqlite3_stmt* insert = nullptr;
  std::string path;

  // `rc` and `message` are taken before any ROLLBACK, which resets them ("not an error").
  [[noreturn]] void fail(const std::string& what, int rc, const std::string& message) const {
    if (rc == SQLITE_BUSY || rc == SQLITE_LOCKED)
      throw DatabaseBusyError(path + ": database busy (locked by another process) while " + what +
                              "; SQLite does not say which process holds the lock: look for "
                              "another program writing the file (e.g. fuser " +
                              path + ")");
    throw std::runtime_error(path + ": " + what + ": " + message +
                             " (check the disk has space and the file is writable)");
  }
  [[noreturn]] void fail(const std::string& what, int rc) const {
    fail(what, rc, db ? sqlite3_errmsg(db) : "no database");
  }
  [[noreturn]] void fail(const std::string& what) const {
    fail(what, db ? sqlite3_errcode(db) : SQLITE_ERROR);
  }
  void exec(const char* sql, const char* what = "writing") {
    char* err = nullptr;
    const int rc = sqlite3_exec(db, sql, nullptr, nullptr, &err);
    if (rc != SQLITE_OK) {
      std::string m = err ? err : "?";
      sqlite3_free(err);
      if (rc == SQLITE_BUSY || rc == SQLITE_LOCKED) fail(what, rc, m);
      throw std::runtime_error(path + ": " + m + " (check the disk and the file's permissions)");
    }
  }
  void rollback() { sqlite3_exec(db, "ROLLBACK", nullptr, nullptr, nullptr); }
  sqlite3_stmt* prepare(const char* sql) {
    sqlite3_stmt* s = nullptr;
    if (sqlite3_prepare_v2(db, sql, -1, &s, nullptr) != SQLITE_OK) fail("preparing a statement");
    return s;
  }
};

RecordingDb::RecordingDb(const std::string& path, bool create, bool defer_if_busy)
    : path_(path), impl_(std::make_unique<Impl>()) {
  impl_->path = path;
  if (!create && !std::filesystem::exists(path))
    throw std::runtime_error(path + ": no such database; record one with valvediag record --db " +
                             path);
  const int flags = create ? SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE : SQLITE_OPEN_READWRITE;
  if (sqlite3_open_v2(path.c_str(), &impl_->db, flags, nullptr) != SQLITE_OK) {
    const std::string m = impl_->db ? sqlite3_errmsg(impl_->db) : "out of memory";
    sqlite3_close(impl_->db);
    impl_->db = nullptr;
    throw std::runtime_error(path + ": cannot open the database: " + m);
  }
  sqlite3_busy_timeout(impl_->db, defer_if_busy ? 250 : 5000);
  try {
    open_tables(create);
  } catch (const DatabaseBusyError&) {
    if (defer_if_busy) {
      tables_pending_ = true;
      return;
    }
    sqlite3_close(impl_->db);
    impl_->db = nullptr;
    throw;
  } catch (...) {
    sqlite3_close(impl_->db);
    impl_->db = nullptr;
    throw;
  }
}

void RecordingDb::open_tables(bool create) {
  // Newer tables are refused at once, busy or not (a read).
  if (!create)
    require_recording(impl_->db, path_);
  else
    (void)known_schema_version(impl_->db, path_, kRecordingTables);
  impl_->exec("PRAGMA journal_mode=WAL", "opening the database");
  impl_->exec("PRAGMA synchronous=FULL", "opening the database");
  if (!create) return;
  // One transaction: two recorders creating the tables at once create them once.
  impl_->exec("BEGIN IMMEDIATE", "creating the tables");
  try {
    if (known_schema_version(impl_->db, path_, kRecordingTables) < 1) impl_->exec(kSchema);
    // Files from before versioning get their row too.
    set_schema_version(impl_->db, path_, kRecordingTables);
    impl_->exec("COMMIT", "creating the tables");
  } catch (...) {
    impl_->rollback();
    throw;
  }
  tables_pending_ = false;
}

RecordingDb::~RecordingDb() {
  if (impl_->insert) sqlite3_finalize(impl_->insert);
  if (impl_->db) sqlite3_close(impl_->db);
}

std::int64_t RecordingDb::begin_run(const std::string& config_file,
                                    const std::string& started_utc) {
  sqlite3_stmt* s = impl_->prepare("INSERT INTO runs(started_utc, config_file) VALUES(?, ?)");
  const std::string now = started_utc.empty() ? utc_timestamp() : started_utc;
  sqlite3_bind_text(s, 1, now.c_str(), -1, SQLITE_TRANSIENT);
  sqlite3_bind_text(s, 2, config_file.c_str(), -1, SQLITE_TRANSIENT);
  const int rc = sqlite3_step(s);
  sqlite3_finalize(s);
  if (rc != SQLITE_DONE) impl_->fail("recording the run", rc);
  return sqlite3_last_insert_rowid(impl_->db);
}

void RecordingDb::end_run(std::int64_t run, const std::string& status) {
  sqlite3_stmt* s = impl_->prepare("UPDATE runs SET ended_utc = ?, status = ? WHERE id = ?");
  const std::string now = utc_timestamp();
  sqlite3_bind_text(s, 1, now.c_str(), -1, SQLITE_TRANSIENT);
  sqlite3_bind_text(s, 2, status.c_str(), -1, SQLITE_TRANSIENT);
  sqlite3_bind_int64(s, 3, run);
  const int rc = sqlite3_step(s);
  sqlite3_finalize(s);
  if (rc != SQLITE_DONE) impl_->fail("closing the run", rc);
}

std::vector<std::int64_t> RecordingDb::mark_interrupted_runs() {
  std::vector<std::int64_t> ids;
  impl_->exec("BEGIN IMMEDIATE", "marking interrupted runs");
  try {
    sqlite3_stmt* s = impl_->prepare("SELECT id FROM runs WHERE status = 'recording' ORDER BY id");
    int rc = 0;
    while ((rc = sqlite3_step(s)) == SQLITE_ROW) ids.push_back(sqlite3_column_int64(s, 0));
    sqlite3_finalize(s);
    if (rc != SQLITE_DONE) impl_->fail("reading the runs", rc);
    impl_->exec("UPDATE runs SET status = 'interrupted' WHERE status = 'recording'",
                "marking interrupted runs");
    impl_->exec("COMMIT", "marking interrupted runs");
  } catch (...) {
    impl_->rollback();
    throw;
  }
  return ids;
}

std::int64_t RecordingDb::add_loop(std::int64_t run, const LoopConfigEntry& loop) {
  sqlite3_stmt* s = impl_->prepare(
      "INSERT INTO loops(run_id, name, sample_period, has_sp, has_mv, has_mode) "
      "VALUES(?, ?, ?, ?, ?, ?)");
  sqlite3_bind_int64(s, 1, run);
  sqlite3_bind_text(s, 2, loop.name.c_str(), -1, SQLITE_TRANSIENT);
  sqlite3_bind_double(s, 3, loop.sample_period_s);
  sqlite3_bind_int(s, 4, loop.point(PointName::sp).present);
  sqlite3_bind_int(s, 5, loop.point(PointName::mv).present);
  sqlite3_bind_int(s, 6, loop.point(PointName::mode).present);
  const int rc = sqlite3_step(s);
  sqlite3_finalize(s);
  if (rc != SQLITE_DONE) impl_->fail("recording loop " + loop.name, rc);
  return sqlite3_last_insert_rowid(impl_->db);
}

void RecordingDb::insert(const std::vector<SampleRow>& rows, const std::vector<GapRow>& gaps) {
  if (rows.empty() && gaps.empty()) return;
  if (!impl_->insert)
    impl_->insert = impl_->prepare(
        "INSERT OR REPLACE INTO samples(loop_id, tick, wall, lateness, op, pv, sp, mv, mode, "
        "q_op, q_pv, q_sp, q_mv, q_mode) VALUES(?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)");
  // IMMEDIATE: a busy database shows here, before any row is bound.
  impl_->exec("BEGIN IMMEDIATE", "inserting samples");
  sqlite3_stmt* s = impl_->insert;
  for (const SampleRow& r : rows) {
    sqlite3_bind_int64(s, 1, r.loop_id);
    sqlite3_bind_int64(s, 2, r.tick);
    sqlite3_bind_double(s, 3, r.wall);
    sqlite3_bind_double(s, 4, r.lateness);
    for (std::size_t i = 0; i < kPointCount; ++i) {
      const double v = r.values[i].value;
      if (std::isfinite(v))
        sqlite3_bind_double(s, static_cast<int>(5 + i), v);
      else
        sqlite3_bind_null(s, static_cast<int>(5 + i));  // never a made-up number
      sqlite3_bind_int(s, static_cast<int>(10 + i), static_cast<int>(r.values[i].quality));
    }
    const int rc = sqlite3_step(s);
    sqlite3_reset(s);
    if (rc != SQLITE_DONE) {
      const std::string m = sqlite3_errmsg(impl_->db);
      impl_->rollback();
      impl_->fail("inserting samples", rc, m);
    }
  }
  try {
    for (const GapRow& g : gaps) add_gap(g.loop_id, g.first_tick, g.last_tick, g.reason);
    impl_->exec("COMMIT", "inserting samples");
  } catch (...) {
    impl_->rollback();
    throw;
  }
}

void RecordingDb::add_gap(std::int64_t loop_id, std::int64_t first_tick, std::int64_t last_tick,
                          const std::string& reason) {
  sqlite3_stmt* s =
      impl_->prepare("INSERT INTO gaps(loop_id, first_tick, last_tick, reason) VALUES(?,?,?,?)");
  sqlite3_bind_int64(s, 1, loop_id);
  sqlite3_bind_int64(s, 2, first_tick);
  sqlite3_bind_int64(s, 3, last_tick);
  sqlite3_bind_text(s, 4, reason.c_str(), -1, SQLITE_TRANSIENT);
  const int rc = sqlite3_step(s);
  sqlite3_finalize(s);
  if (rc != SQLITE_DONE) impl_->fail("recording a gap", rc);
}

void RecordingDb::set_busy_timeout(double seconds) {
  sqlite3_busy_timeout(impl_->db, static_cast<int>(std::lround(seconds * 1e3)));
}

std::string RecordingDb::integrity_check() {
  sqlite3_stmt* s = impl_->prepare("PRAGMA integrity_check");
  std::string out;
  while (sqlite3_step(s) == SQLITE_ROW) {
    if (!out.empty()) out += "; ";
    out += reinterpret_cast<const char*>(sqlite3_column_text(s, 0));
  }
  sqlite3_finalize(s);
  return out;
}

namespace {
std::string describe_runs(const std::vector<RunInfo>& runs) {
  std::string s;
  for (const RunInfo& r : runs)
    s += (s.empty() ? "" : ", ") + std::to_string(r.id) + " (started " + r.started_utc + ", " +
         r.status + ")";
  return s;
}

std::string fmt_time(double t) {
  char b[32];
  std::snprintf(b, sizeof b, "%.6g", t);
  return b;
}
}  // namespace

namespace {
// A recording opened read-only for the readers; errors name the file and what to do.
std::unique_ptr<sqlite3, int (*)(sqlite3*)> open_recording(const std::string& db_path) {
  if (!std::filesystem::exists(db_path))
    throw std::runtime_error(
        db_path + ": no such database; record one with valvediag record --db " + db_path);
  sqlite3* c = nullptr;
  if (sqlite3_open_v2(db_path.c_str(), &c, SQLITE_OPEN_READONLY, nullptr) != SQLITE_OK) {
    sqlite3_close(c);
    throw std::runtime_error(db_path + ": cannot open the database");
  }
  std::unique_ptr<sqlite3, int (*)(sqlite3*)> db(c, sqlite3_close);
  sqlite3_busy_timeout(c, 5000);
  require_recording(c, db_path);
  return db;
}
}  // namespace

std::vector<std::string> recorded_loops(const std::string& db_path) {
  const auto db = open_recording(db_path);
  sqlite3* c = db.get();
  sqlite3_stmt* s = nullptr;
  if (sqlite3_prepare_v2(c, "SELECT DISTINCT name FROM loops ORDER BY name", -1, &s, nullptr) !=
      SQLITE_OK)
    throw std::runtime_error(db_path + ": " + sqlite3_errmsg(c) +
                             " (is this a valvediag recording?)");
  std::vector<std::string> names;
  while (sqlite3_step(s) == SQLITE_ROW)
    names.emplace_back(reinterpret_cast<const char*>(sqlite3_column_text(s, 0)));
  sqlite3_finalize(s);
  return names;
}

RecordedLoop read_recorded_loop(const std::string& db_path, const std::string& name,
                                std::optional<double> from_s, std::optional<double> to_s,
                                std::int64_t run, bool longest_clean, std::size_t bridge_ticks,
                                std::size_t max_rows) {
  const auto db = open_recording(db_path);
  sqlite3* c = db.get();
  auto prepare = [&](const char* sql) {
    sqlite3_stmt* s = nullptr;
    if (sqlite3_prepare_v2(c, sql, -1, &s, nullptr) != SQLITE_OK)
      throw std::runtime_error(db_path + ": " + sqlite3_errmsg(c) +
                               " (is this a valvediag recording?)");
    return s;
  };
  RecordedLoop out;
  {
    // The runs with this loop; `recording` without a recorder holding the lock for it was cut
    // short (a reader opens read-only: the next recorder marks it).
    const std::optional<LockHolder> holder = recorder_holding(db_path);
    sqlite3_stmt* s = prepare(
        "SELECT r.id, r.started_utc, r.status FROM runs r JOIN loops l ON l.run_id = r.id "
        "WHERE l.name = ? ORDER BY r.id");
    sqlite3_bind_text(s, 1, name.c_str(), -1, SQLITE_TRANSIENT);
    while (sqlite3_step(s) == SQLITE_ROW) {
      RunInfo r;
      r.id = sqlite3_column_int64(s, 0);
      auto text = [&](int i) {
        const unsigned char* t = sqlite3_column_text(s, i);
        return t ? std::string(reinterpret_cast<const char*>(t)) : std::string("?");
      };
      r.started_utc = text(1);
      r.status = text(2);
      if (r.status == "recording" && !(holder && (holder->run == r.id || holder->run == 0)))
        r.status = "interrupted";
      out.runs.push_back(r);
    }
    sqlite3_finalize(s);
  }
  if (run > 0 && !out.runs.empty() &&
      std::none_of(out.runs.begin(), out.runs.end(), [&](const RunInfo& r) { return r.id == run; }))
    throw std::runtime_error(db_path + ": no run " + std::to_string(run) + " with loop '" + name +
                             "'; runs with it: " + describe_runs(out.runs) + " (--run ID)");
  std::int64_t loop_id = 0;
  bool has_sp = false, has_mv = false;
  {
    sqlite3_stmt* s = prepare(
        run > 0 ? "SELECT id, run_id, sample_period, has_sp, has_mv FROM loops WHERE name = ? AND "
                  "run_id = ?"
                : "SELECT id, run_id, sample_period, has_sp, has_mv FROM loops WHERE name = ? "
                  "ORDER BY run_id DESC LIMIT 1");
    sqlite3_bind_text(s, 1, name.c_str(), -1, SQLITE_TRANSIENT);
    if (run > 0) sqlite3_bind_int64(s, 2, run);
    const bool found = sqlite3_step(s) == SQLITE_ROW;
    if (found) {
      loop_id = sqlite3_column_int64(s, 0);
      out.run = sqlite3_column_int64(s, 1);
      out.sample_period = sqlite3_column_double(s, 2);
      has_sp = sqlite3_column_int(s, 3) != 0;
      has_mv = sqlite3_column_int(s, 4) != 0;
    }
    sqlite3_finalize(s);
    if (!found) {
      std::string names;
      for (const std::string& n : recorded_loops(db_path)) names += (names.empty() ? "" : ", ") + n;
      throw std::runtime_error(db_path + ": no loop '" + name + "'" +
                               (run > 0 ? " in run " + std::to_string(run) : "") +
                               "; recorded loops: " + (names.empty() ? "none" : names));
    }
  }
  const double P = out.sample_period;
  const std::int64_t first = from_s ? static_cast<std::int64_t>(std::ceil(*from_s / P - 1e-9)) : 0;
  const std::int64_t last = to_s ? static_cast<std::int64_t>(std::floor(*to_s / P + 1e-9))
                                 : std::numeric_limits<std::int64_t>::max();
  sqlite3_stmt* s = prepare(
      "SELECT tick, op, pv, sp, q_op, q_pv, q_sp, mv, q_mv FROM samples WHERE loop_id = ? AND tick "
      ">= ? "
      "AND tick <= ? ORDER BY tick");
  sqlite3_bind_int64(s, 1, loop_id);
  sqlite3_bind_int64(s, 2, first);
  sqlite3_bind_int64(s, 3, last);
  struct Gap {
    std::int64_t a, b;
    int q;
  };
  std::vector<Gap> gaps;
  std::vector<std::int64_t> ticks;
  std::vector<double> op, pv, sp;
  bool sp_ok = has_sp;
  std::size_t sp_bad = 0, mv_bad = 0;
  bool mv_ok = has_mv;
  std::vector<double> mv;
  std::int64_t prev = first - 1;
  auto add_gap = [&](std::int64_t a, std::int64_t b, int q) {
    if (!gaps.empty() && gaps.back().b + 1 == a)
      gaps.back().b = b;
    else
      gaps.push_back({a, b, q});
  };
  const std::string where = "run " + std::to_string(out.run) + ", loop " + name + ", tick ";
  std::size_t rows_read = 0;
  // A good value no instrument gives (a corrupt row, a bad-value marker imported as good).
  auto checked = [&](double v, const char* column, std::int64_t k) {
    if (const std::string why = signal_value_problem(v); !why.empty()) {
      sqlite3_finalize(s);
      throw DataError(db_path, 0, column,
                      where + std::to_string(k) + " (t = " + fmt_time(static_cast<double>(k) * P) +
                          " s): " + why);
    }
    return v;
  };
  while (sqlite3_step(s) == SQLITE_ROW) {
    const std::int64_t k = sqlite3_column_int64(s, 0);
    if (++rows_read > max_rows) {
      sqlite3_finalize(s);
      throw DataError(db_path, 0, "",
                      "run " + std::to_string(out.run) + ", loop " + name + ": more than " +
                          std::to_string(max_rows) +
                          " rows in the range, the --max-rows limit that keeps memory bounded "
                          "(about 50 bytes a row); give --max-rows with a larger number to read "
                          "it all, or a shorter range (--from/--to)");
    }
    if (k > prev + 1 && prev >= first) add_gap(prev + 1, k - 1, -1);  // rows lost (kill -9)
    prev = k;
    const int qo = sqlite3_column_int(s, 4), qp = sqlite3_column_int(s, 5);
    if (qo != 0 || qp != 0) {
      add_gap(k, k, qo != 0 ? qo : qp);
      continue;
    }
    ticks.push_back(k);
    op.push_back(checked(sqlite3_column_double(s, 1), "op", k));
    pv.push_back(checked(sqlite3_column_double(s, 2), "pv", k));
    if (has_sp) {
      if (sqlite3_column_int(s, 6) != 0) {
        sp_ok = false;
        ++sp_bad;
        sp.push_back(sqlite3_column_double(s, 3));  // left out below
      } else {
        sp.push_back(checked(sqlite3_column_double(s, 3), "sp", k));
      }
    }
    if (has_mv) {
      if (sqlite3_column_int(s, 8) != 0) {
        mv_ok = false;
        ++mv_bad;
        mv.push_back(sqlite3_column_double(s, 7));
      } else {
        mv.push_back(checked(sqlite3_column_double(s, 7), "mv", k));
      }
    }
  }
  sqlite3_finalize(s);
  if (bridge_ticks > 0 && !gaps.empty()) {
    // Short gaps between good samples: filled by linear interpolation, every signal alike.
    std::vector<Gap> kept;
    std::string bridged;
    std::size_t n_bridged = 0, ticks_bridged = 0;
    std::vector<std::int64_t> t2;
    std::vector<double> op2, pv2, sp2, mv2;
    std::size_t g = 0;
    for (std::size_t i = 0; i < ticks.size(); ++i) {
      if (i > 0) {
        const std::int64_t a = ticks[i - 1], b = ticks[i];
        const auto missing = static_cast<std::size_t>(b - a - 1);
        if (missing > 0 && missing <= bridge_ticks) {
          for (std::int64_t k = a + 1; k < b; ++k) {
            const double w = static_cast<double>(k - a) / static_cast<double>(b - a);
            auto lerp = [&](const std::vector<double>& v) {
              return v[i - 1] + w * (v[i] - v[i - 1]);
            };
            t2.push_back(k);
            op2.push_back(lerp(op));
            pv2.push_back(lerp(pv));
            if (!sp.empty()) sp2.push_back(lerp(sp));
            if (!mv.empty()) mv2.push_back(lerp(mv));
          }
          if (n_bridged < 5)
            bridged += (n_bridged ? ", " : "") + fmt_time(static_cast<double>(a + 1) * P);
          ++n_bridged;
          ticks_bridged += missing;
          // The gaps inside (a, b) are bridged; the rest stay.
          while (g < gaps.size() && gaps[g].b < b) {
            if (gaps[g].a <= a) kept.push_back(gaps[g]);
            ++g;
          }
        }
      }
      t2.push_back(ticks[i]);
      op2.push_back(op[i]);
      pv2.push_back(pv[i]);
      if (!sp.empty()) sp2.push_back(sp[i]);
      if (!mv.empty()) mv2.push_back(mv[i]);
    }
    out.bridged_gaps = n_bridged;
    if (n_bridged > 0) {
      while (g < gaps.size()) kept.push_back(gaps[g++]);
      // Gaps before the first or after the last good sample (or longer ones) are not bridged.
      gaps.swap(kept);
      ticks.swap(t2);
      op.swap(op2);
      pv.swap(pv2);
      sp.swap(sp2);
      mv.swap(mv2);
      out.notes.push_back(std::to_string(n_bridged) + " short gap(s) of at most " +
                          std::to_string(bridge_ticks) + " tick(s) (" +
                          std::to_string(ticks_bridged) + " in all, at " + bridged +
                          (n_bridged > 5 ? ", ..." : "") +
                          " s) filled by linear interpolation between the good samples");
    }
  }
  if (!gaps.empty()) {
    // Longest clean stretch: suggested, or used with `longest_clean`.
    std::int64_t best_a = 0, best_len = 0, run_a = 0, run_len = 0;
    for (std::size_t i = 0; i < ticks.size(); ++i) {
      if (i == 0 || ticks[i] != ticks[i - 1] + 1) {
        run_a = ticks[i];
        run_len = 0;
      }
      if (++run_len > best_len) {
        best_len = run_len;
        best_a = run_a;
      }
    }
    std::string list;
    for (std::size_t i = 0; i < gaps.size() && i < 5; ++i) {
      static const char* const q[] = {"good", "stale", "comm-error", "missed", "invalid"};
      list += (i ? ", " : "") + fmt_time(static_cast<double>(gaps[i].a) * P) + ".." +
              fmt_time(static_cast<double>(gaps[i].b + 1) * P) + " s (" +
              (gaps[i].q < 0 ? "rows missing" : q[std::min(gaps[i].q, 4)]) + ")";
    }
    if (gaps.size() > 5) list += ", and " + std::to_string(gaps.size() - 5) + " more";
    const std::string stretch = fmt_time(static_cast<double>(best_a) * P) + " .. " +
                                fmt_time(static_cast<double>(best_a + best_len - 1) * P) + " s";
    if (!longest_clean || best_len < 2)
      throw RecordingGapError(db_path + ": loop " + name + " has " + std::to_string(gaps.size()) +
                              " gap(s) without good OP and PV in the range: " + list +
                              (best_len >= 2
                                   ? "; the longest clean stretch is --from " +
                                         fmt_time(static_cast<double>(best_a) * P) + " --to " +
                                         fmt_time(static_cast<double>(best_a + best_len - 1) * P)
                                   : "; no clean stretch"));
    const auto i0 =
        static_cast<std::ptrdiff_t>(std::find(ticks.begin(), ticks.end(), best_a) - ticks.begin());
    const auto i1 = i0 + static_cast<std::ptrdiff_t>(best_len);
    auto cut = [&](auto& v) {
      if (v.size() != ticks.size()) return;
      std::remove_reference_t<decltype(v)> part(v.begin() + i0, v.begin() + i1);
      v.swap(part);
    };
    cut(op);
    cut(pv);
    cut(sp);
    cut(mv);
    cut(ticks);
    out.notes.push_back("the range has " + std::to_string(gaps.size()) + " gap(s) (" + list +
                        "); using the longest clean stretch, " + stretch);
  }
  for (const RunInfo& r : out.runs)
    if (r.id == out.run) out.run_info = r;
  out.rows = ticks.size();
  if (ticks.empty())
    throw std::runtime_error(db_path + ": loop " + name + " has no samples in the range");
  LoopData& d = out.data;
  d.source = db_path + " loop " + name + " (run " + std::to_string(out.run) + ")";
  for (auto k : ticks) d.t.push_back(static_cast<double>(k) * P);
  // Tick 0 is the run's start on the recorder's clock; an imported run's start is the import's
  // time, not the data's, so it has none.
  if (out.run_info.status != "imported") d.clock_at_zero_s = utc_seconds(out.run_info.started_utc);
  d.op = std::move(op);
  d.pv = std::move(pv);
  if (has_sp && sp_ok) d.sp = std::move(sp);
  if (has_sp && !sp_ok)
    out.notes.push_back("sp left out: " + std::to_string(sp_bad) + " tick(s) without a good sp");
  if (has_mv && mv_ok) d.mv = std::move(mv);
  if (has_mv && !mv_ok)
    out.notes.push_back("mv left out: " + std::to_string(mv_bad) + " tick(s) without a good mv");
  return out;
}

}  // namespace valvediag
