// The recorder: polls every loop of a site at its sample period on a monotonic clock through the
// bus interface and stores one row per sample tick per loop in SQLite (WAL mode, one transaction
// per commit interval, so a kill -9 loses at most that interval and leaves an intact database).
// Each value carries a quality flag; gaps are marked, never filled. Reads only.
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "valvediag/drivers/bus.hpp"
#include "valvediag/drivers/site_config.hpp"
#include "valvediag/io/csv_reader.hpp"  // kDefaultMaxRows
#include "valvediag/io/loop_data.hpp"
#include "valvediag/recorder/schema_versions.hpp"

namespace valvediag {

// Version of the recording tables this build writes and reads (schema_versions.hpp); a
// database with newer ones is refused rather than misread.
inline constexpr int kRecorderSchemaVersion = 1;
inline constexpr SchemaTables kRecordingTables{"recorder", "samples", "recording",
                                               kRecorderSchemaVersion};

// One stored sample tick of one loop.
struct SampleRow {
  std::int64_t loop_id = 0;
  std::int64_t tick = 0;  // t = tick * sample period since the run's start
  double wall = 0.0;      // Unix time of the read, s
  double lateness = 0.0;  // read started this long after the tick's due time, s
  std::array<PointValue, kPointCount> values;
};

// Ticks [first_tick, last_tick] of a loop without good OP and PV, with the first problem seen.
struct GapRow {
  std::int64_t loop_id = 0, first_tick = 0, last_tick = 0;
  std::string reason;
};

// Another connection holds SQLite's write lock longer than the busy timeout. SQLite cannot say
// which process holds it; the message names the file and says so. Nothing was written.
class DatabaseBusyError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// The SQLite file: schema, batched inserts, and reading a loop back. Throws DatabaseBusyError
// when another process holds the write lock past the busy timeout, std::runtime_error naming the
// file and what to do on any other SQLite failure.
class RecordingDb {
 public:
  // `defer_if_busy`: a database busy for a quarter second leaves the tables to open_tables()
  // (the recorder polls meanwhile) instead of DatabaseBusyError after 5 s.
  explicit RecordingDb(const std::string& path, bool create = true, bool defer_if_busy = false);
  ~RecordingDb();
  RecordingDb(const RecordingDb&) = delete;
  RecordingDb& operator=(const RecordingDb&) = delete;

  // started_utc: "" for now.
  std::int64_t begin_run(const std::string& config_file, const std::string& started_utc = "");
  void end_run(std::int64_t run, const std::string& status);
  // Marks `interrupted` the runs left `recording` by a recorder that was killed or aborted;
  // returns their ids. Call only while holding the database's RecorderLock (recorder_lock.hpp):
  // then no run is being recorded.
  std::vector<std::int64_t> mark_interrupted_runs();
  std::int64_t add_loop(std::int64_t run, const LoopConfigEntry& loop);
  // All rows and gaps in one transaction: stored together or (busy, error) not at all.
  void insert(const std::vector<SampleRow>& rows, const std::vector<GapRow>& gaps = {});
  void add_gap(std::int64_t loop_id, std::int64_t first_tick, std::int64_t last_tick,
               const std::string& reason);
  std::string integrity_check();  // "ok" when intact
  // How long a statement waits for another connection's write lock before DatabaseBusyError.
  void set_busy_timeout(double seconds);
  const std::string& path() const { return path_; }
  // False while tables deferred by a busy database wait for open_tables().
  bool tables_open() const { return !tables_pending_; }
  // Schema check or migration, once the file is open; DatabaseBusyError while it is busy.
  void open_tables(bool create = true);
  struct Impl;

 private:
  bool tables_pending_ = false;
  std::string path_;
  std::unique_ptr<Impl> impl_;
};

// A loop's recording read back for export and fitting.
class RecordingGapError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};
// A run of a recording as readers see it.
struct RunInfo {
  std::int64_t id = 0;
  std::string started_utc;
  // completed, stopped, imported, interrupted; `recording` only while its recorder holds the
  // database's lock (a run left so by a killed recorder reads as interrupted).
  std::string status;
};
struct RecordedLoop {
  LoopData data;  // t from the run's start (s); sp when every sp is good
  std::int64_t run = 0;
  RunInfo run_info;           // the run read
  std::vector<RunInfo> runs;  // every run that recorded the loop, oldest first
  double sample_period = 0.0;
  std::size_t rows = 0;
  std::vector<std::string> notes;  // e.g. "sp left out: 3 ticks without a good sp"
  std::size_t bridged_gaps = 0;    // gaps filled by interpolation (read_recorded_loop's bridge)
};
// Reads loop `name` of run `run` (0: the latest run that recorded it) from `from_s` to `to_s`
// (seconds since the run's start; nullopt: all). Throws RecordingGapError when OP or PV is not
// good on some tick in the range, listing the gaps and the longest clean stretch to ask for
// instead; std::runtime_error when the file, loop or run does not exist.
// With `bridge_ticks` > 0, a gap of at most that many ticks between good samples is first filled
// by linear interpolation (with a note): one missed poll on a loaded machine must not cost the
// analysis most of a window. With `longest_clean`, a range with gaps left gives its longest clean
// stretch instead (with a note). The recording itself is never changed.
// As a CSV file: more than `max_rows` rows in the range (memory), or a value no instrument
// gives (beyond +-1e12, data_checks.hpp), is a DataError naming the run, loop and tick.
RecordedLoop read_recorded_loop(const std::string& db_path, const std::string& name,
                                std::optional<double> from_s = std::nullopt,
                                std::optional<double> to_s = std::nullopt, std::int64_t run = 0,
                                bool longest_clean = false, std::size_t bridge_ticks = 0,
                                std::size_t max_rows = kDefaultMaxRows);
// The names of the loops recorded in `db_path` (any run), sorted. Opens it read-only; throws
// std::runtime_error naming the file when it does not exist or holds no recordings.
std::vector<std::string> recorded_loops(const std::string& db_path);
// The short gaps the analysis commands bridge (a loop's dynamics span many samples; two
// interpolated samples are within the noise of identification).
inline constexpr std::size_t kBridgedTicks = 2;

struct RecorderOptions {
  std::string db_path;
  std::vector<std::string> loops;    // names to record; empty: every loop of the site
  std::optional<double> duration_s;  // stop after this long; nullopt: until stop is set
  double commit_interval_s = 0.5;    // at most this much is lost on a kill -9 or a power cut
  // Due time of tick 0 (a moment after run() is called); default: when run() starts. Lets a
  // caller put the polls between the steps of a simulated PLC.
  std::optional<std::chrono::steady_clock::time_point> start;
  double status_interval_s = 1.0;
  // While another process holds the database's write lock, samples wait in memory (about
  // busy_limit_s of rows at most) and are stored once it is released. Designed for locks of up to
  // a minute; a longer one stops the run with an error saying how many samples were not stored.
  double busy_limit_s = 90.0;
};

struct LoopCounts {
  std::string name;
  std::uint64_t rows = 0, good = 0, comm_error = 0, stale = 0, missed = 0, invalid = 0;
  std::uint64_t gaps = 0;
};

struct RecorderStatus {
  std::int64_t run = 0;  // the run being recorded; 0 until the database took it
  double elapsed_s = 0.0;
  std::uint64_t rows = 0;       // rows produced
  std::uint64_t committed = 0;  // rows in the database
  std::uint64_t bad_rows = 0;   // rows with op or pv not good
  std::uint64_t missed = 0;     // ticks the recorder could not poll in time
  double lateness_p50_s = 0.0, lateness_p99_s = 0.0, lateness_max_s = 0.0;
  std::vector<LoopCounts> loops;
  std::vector<std::pair<std::string, BusStats>> buses;
  std::string last_error;
  // Database busy (another process holding SQLite's write lock): rows waiting in memory.
  std::uint64_t waiting = 0, waiting_peak = 0;  // rows not yet stored while it was busy
  double busy_s = 0.0;                          // busy this long now (0: not busy)
  double busy_longest_s = 0.0;
  std::uint64_t busy_times = 0;
  std::string busy_message;  // the last one: the file, and that SQLite cannot name the process
  bool errors() const { return bad_rows > 0 || missed > 0; }
};

using BusFactory =
    std::function<std::unique_ptr<Bus>(const BusConfig&, std::vector<LoopConfigEntry>)>;

class Recorder {
 public:
  // Checks the loop selection against the site, builds the buses through `factory`, takes the
  // database's recorder lock, then opens (creates) the database (a busy one: database_ready());
  // throws std::invalid_argument
  // for an unknown loop name, DatabaseInUseError when another recorder holds the lock,
  // std::runtime_error when a bus cannot exist (no SocketCAN) or the database cannot be opened.
  // Nothing is sent on any bus before run().
  Recorder(SiteConfig site, RecorderOptions options, BusFactory factory);
  ~Recorder();
  // Records until `stop` is set or the duration is over; calls `on_status` about every
  // status_interval_s from the calling thread. Returns the final status (all rows committed).
  RecorderStatus run(const std::atomic<bool>& stop,
                     const std::function<void(const RecorderStatus&)>& on_status = {});
  std::int64_t run_id() const;
  // Runs a killed or aborted recorder had left `recording`, marked `interrupted` on opening (or,
  // when the database was busy then, once it is free: look again after run()).
  const std::vector<std::int64_t>& interrupted_runs() const;
  // False while a busy database (another process's write lock) keeps the recorder from setting
  // up its tables: run() then polls at once and holds the samples in memory until it is free.
  bool database_ready() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace valvediag
