// The recorder against the simulated PLC over real Modbus TCP on 127.0.0.1: rows per tick,
// quality flags, gaps, faults, a server away at the start and restarted mid-run, read-only.
// Every run is bounded by its --duration.
#include <doctest/doctest.h>
#include <sqlite3.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <functional>
#include <thread>

#include "../bus/bus_test_util.hpp"
#include "../common/sqlite_exec.hpp"
#include "valvediag/drivers/bus_factory.hpp"
#include "valvediag/drivers/sim_plc.hpp"
#include "valvediag/recorder/recorder.hpp"
#include "valvediag/recorder/recorder_lock.hpp"
#include "valvediag/sim/scenarios.hpp"
#include "valvediag/util/utc_time.hpp"

using namespace valvediag;
namespace fs = std::filesystem;

namespace {
const std::string kSimSite = std::string(VALVEDIAG_CONFIG_DIR) + "/sim-site.toml";
constexpr double kPeriod = 0.05;

std::string fresh_db(const std::string& name) {
  const fs::path p = fs::path(VALVEDIAG_TMP) / (name + ".sqlite");
  for (const char* suffix : {"", "-wal", "-shm"}) fs::remove(p.string() + suffix);
  return p.string();
}

// The sim site with every loop polled at 20 Hz.
SiteConfig fast_site(int port) {
  SiteConfig s = test::site_on_port(kSimSite, port);
  for (auto& l : s.loops) l.sample_period_s = kPeriod;
  s.buses[0].timeout_s = 0.1;
  s.buses[0].retries = 0;
  s.buses[0].reconnect_max_s = 0.5;
  return s;
}

// Runs a query returning one number.
double scalar(const std::string& db, const std::string& sql) {
  sqlite3* c = nullptr;
  REQUIRE(sqlite3_open_v2(db.c_str(), &c, SQLITE_OPEN_READONLY, nullptr) == SQLITE_OK);
  sqlite3_stmt* s = nullptr;
  REQUIRE(sqlite3_prepare_v2(c, sql.c_str(), -1, &s, nullptr) == SQLITE_OK);
  double v = std::nan("");
  if (sqlite3_step(s) == SQLITE_ROW) v = sqlite3_column_double(s, 0);
  sqlite3_finalize(s);
  sqlite3_close(c);
  return v;
}

double wall_now() {
  return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
}

// The set-up most cases share (TEST_CASE_FIXTURE): the simulated PLC at 10x, started, and the
// recorder's options.
struct SimRig {
  SimPlc plc{load_site_config(kSimSite), SimPlcOptions{10.0, 0}};
  RecorderOptions o;
  SimRig() { plc.start(); }
  // A fresh database `name` for a run of `duration_s` (nullopt: until stopped) over `loops`
  // (empty: all); its path.
  std::string fresh(const std::string& name, std::optional<double> duration_s,
                    std::vector<std::string> loops = {}) {
    o.db_path = fresh_db(name);
    o.duration_s = duration_s;
    o.loops = std::move(loops);
    return o.db_path;
  }
};

bool no_writes(const SimPlc& plc) {
  const auto c = plc.function_counts();
  for (std::size_t fc = 0; fc < c.size(); ++fc)
    if (c[fc] && fc != 3 && fc != 4) return false;
  return plc.write_requests() == 0;
}
}  // namespace

TEST_CASE_FIXTURE(SimRig, "records one row per tick per loop, all good, and never writes") {
  const std::string db = fresh("basic", 1.0);
  Recorder rec(fast_site(plc.port()), o, make_bus);
  std::atomic<bool> stop{false};
  int statuses = 0;
  const RecorderStatus s = rec.run(stop, [&](const RecorderStatus&) { ++statuses; });
  REQUIRE(s.loops.size() == 3);
  for (const auto& l : s.loops) {
    INFO(l.name);
    CHECK(l.rows == 20);  // ticks 0..19 of 50 ms in 1 s: one row each, late or not
    CHECK(l.comm_error == 0);
    CHECK(l.missed <= 5);  // only a badly overloaded machine misses a 50 ms tick
  }
  CHECK(s.committed == 60);
  CHECK(no_writes(plc));
  CHECK(plc.function_counts()[3] >= 36);  // FIC101 and LIC201, one request per tick each
  CHECK(scalar(db, "SELECT count(*) FROM samples") == 60);
  CHECK(scalar(db, "SELECT count(DISTINCT tick) FROM samples") == 20);
  CHECK(scalar(db, "SELECT count(*) FROM runs WHERE status = 'completed'") == 1);
  const RecordedLoop r = read_recorded_loop(db, "FIC101");
  if (s.loops[0].missed == 0) {
    REQUIRE(r.data.size() == 20);
    CHECK(r.data.t[19] == doctest::Approx(19 * kPeriod));
    CHECK(r.data.has_sp());
    CHECK(r.data.has_mv());  // FIC101 serves the valve position too
    for (std::size_t i = 0; i < r.data.size(); ++i) {
      CHECK(r.data.op[i] >= 0.0);
      CHECK(r.data.op[i] <= 100.0);
      CHECK(std::fabs(r.data.pv[i] - 50.0) < 20.0);  // paper-ex1 runs around PV 50
    }
  }
  CHECK_THROWS_AS(read_recorded_loop(db, "NOPE"), std::runtime_error);
  RecorderOptions unknown;
  unknown.db_path = db;
  unknown.loops = {"NOPE"};
  CHECK_THROWS_AS(Recorder(fast_site(plc.port()), unknown, make_bus), std::invalid_argument);
}

TEST_CASE_FIXTURE(SimRig, "server down at start: comm-error rows, backoff, records once it is up") {
  plc.restart(1.0);  // away for the first second of the recording
  const double t_back = wall_now() + 1.0;
  const std::string db = fresh("down_at_start", 3.0, {"FIC101"});
  Recorder rec(fast_site(plc.port()), o, make_bus);
  std::atomic<bool> stop{false};
  const RecorderStatus s = rec.run(stop);
  REQUIRE(s.loops.size() == 1);
  CHECK(s.loops[0].rows == 60);
  CHECK(s.loops[0].comm_error >= 10);  // about 1 s of 50 ms ticks
  CHECK(s.loops[0].good >= 20);
  CHECK(s.errors());
  CHECK(s.last_error.find("cannot connect to 127.0.0.1") != std::string::npos);
  // Backoff: far fewer connection attempts than ticks while it was away.
  CHECK(s.buses[0].second.connect_attempts <= 12);
  const double first_good = scalar(db, "SELECT min(wall) FROM samples WHERE q_op = 0 AND q_pv = 0");
  MESSAGE("first good read " << first_good - t_back << " s after the server came back");
  CHECK(first_good - t_back < 2.0);
  CHECK(scalar(db, "SELECT count(*) FROM gaps") == 1);
  CHECK(scalar(db, "SELECT first_tick FROM gaps") == 0);
  CHECK(scalar(db, "SELECT count(*) FROM samples WHERE q_op = 2 AND op IS NOT NULL") == 0);
  CHECK(no_writes(plc));
}

TEST_CASE_FIXTURE(
    SimRig,
    "server restarted while recording: keeps running, reconnects, marks the gap, loses nothing") {
  const std::string db = fresh("restart", 4.0);
  Recorder rec(fast_site(plc.port()), o, make_bus);
  std::atomic<bool> stop{false};
  double t_back = 0.0;
  std::thread killer([&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(1000));
    plc.restart(1.0);
    t_back = wall_now() + 1.0;
  });
  const RecorderStatus s = rec.run(stop);
  killer.join();
  for (const auto& l : s.loops) {
    INFO(l.name);
    CHECK(l.rows == 80);  // every tick has its row: nothing lost
    CHECK(l.comm_error >= 10);
    CHECK(l.good >= 30);
    CHECK(l.gaps >= 1);
  }
  CHECK(scalar(db, "SELECT count(*) FROM samples") == 240);
  CHECK(scalar(db, "SELECT count(*) FROM gaps") >= 3);
  // Half-way through the outage every read fails: the first good one after is the reconnection.
  const double back_good = scalar(db, "SELECT min(wall) FROM samples WHERE q_op = 0 AND wall > " +
                                          std::to_string(t_back - 0.5));
  MESSAGE("reconnected " << back_good - t_back << " s after the server came back");
  CHECK(back_good - t_back < 2.0);
  CHECK(s.buses[0].second.reconnects >= 1);
  // Before the restart every row is good: what it had is kept.
  CHECK(scalar(db, "SELECT count(*) FROM samples WHERE tick < 15 AND (q_op != 0 AND q_op != 3)") ==
        0);
  // Export refuses the gap and names the clean stretch.
  try {
    read_recorded_loop(db, "FIC101");
    FAIL("a gap was exported");
  } catch (const RecordingGapError& e) {
    CHECK(std::string(e.what()).find("the longest clean stretch is --from") != std::string::npos);
  }
  CHECK(read_recorded_loop(db, "FIC101", 0.0, 0.5).data.size() == 11);
  CHECK(no_writes(plc));
}

TEST_CASE("timeouts, exceptions and garbled replies are counted and flagged, never a hang") {
  SimPlc plc(load_site_config(kSimSite), SimPlcOptions{10.0, 0});
  FaultConfig timeout;
  timeout.kind = FaultKind::timeout;
  timeout.address = 0;  // FIC101
  timeout.every = 4;
  FaultConfig exception;
  exception.kind = FaultKind::exception;
  exception.address = 12;  // LIC201
  exception.every = 3;
  FaultConfig garble;
  garble.kind = FaultKind::garble;
  garble.address = 21;  // PIC301
  garble.every = 3;
  FaultConfig slow;
  slow.kind = FaultKind::delay;
  slow.delay_s = 0.02;
  slow.address = 21;
  slow.every = 2;
  for (const auto& f : {timeout, exception, garble, slow}) plc.add_fault(f);
  plc.start();
  const std::string db = fresh_db("faults");
  RecorderOptions o;
  o.db_path = db;
  o.duration_s = 2.0;
  Recorder rec(fast_site(plc.port()), o, make_bus);
  std::atomic<bool> stop{false};
  const RecorderStatus s = rec.run(stop);
  const BusStats b = s.buses[0].second;
  CHECK(b.timeouts >= 2);
  CHECK(b.exceptions >= 3);
  CHECK(b.garbled >= 3);
  for (const auto& l : s.loops) {
    INFO(l.name);
    CHECK(l.rows == 40);
    CHECK(l.comm_error + l.missed >= 3);
    CHECK(l.good >= 10);
  }
  CHECK(s.errors());
  // Flagged rows carry no number.
  CHECK(scalar(db, "SELECT count(*) FROM samples WHERE q_pv != 0 AND pv IS NOT NULL") == 0);
  CHECK(scalar(db, "SELECT count(*) FROM samples WHERE q_pv = 2") >= 9);
  CHECK(no_writes(plc));
}

TEST_CASE_FIXTURE(SimRig, "Ctrl-C (the stop flag) ends a run without a duration cleanly") {
  const std::string db = fresh("stop", std::nullopt);
  Recorder rec(fast_site(plc.port()), o, make_bus);
  std::atomic<bool> stop{false};
  std::thread stopper([&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(500));
    stop = true;
  });
  const RecorderStatus s = rec.run(stop);
  stopper.join();
  CHECK(s.rows >= 15);
  CHECK(s.committed == s.rows);
  CHECK(scalar(db, "SELECT count(*) FROM runs WHERE status = 'stopped'") == 1);
}

TEST_CASE_FIXTURE(SimRig, "recorded values equal the simulated loop's samples, tick for tick") {
  // The PLC steps paper-ex1 every 50 ms (10x); the recorder polls every 50 ms half-way between
  // steps, so recorded tick i is simulation step k0 + i, to float32 precision.
  const std::string db = fresh("exact", 1.0, {"FIC101"});
  const auto P = std::chrono::duration<double>(kPeriod);
  const double k0 = std::ceil(
      (std::chrono::steady_clock::now() + std::chrono::milliseconds(200) - plc.started()) / P);
  o.start = plc.started() +
            std::chrono::duration_cast<std::chrono::steady_clock::duration>((k0 + 0.5) * P);
  Recorder rec(fast_site(plc.port()), o, make_bus);
  std::atomic<bool> stop{false};
  const RecorderStatus s = rec.run(stop);
  CHECK(s.loops[0].rows == 20);
  const LoopData sim =
      run_scenario(scenario_by_name("paper-ex1"), 1, static_cast<std::size_t>(k0) + 21);
  const RecordedLoop r = read_recorded_loop(db, "FIC101", std::nullopt, std::nullopt, 0, true);
  // The registers (float32) of simulation step k, as the PLC served them.
  const auto served = [&](std::size_t i, std::size_t k) {
    const auto same = [](double a, double b) { return std::fabs(a - b) <= 1e-5 * std::fabs(b); };
    return same(r.data.op[i], sim.op[k]) && same(r.data.pv[i], sim.pv[k]) &&
           same(r.data.mv[i], sim.mv[k]);
  };
  std::size_t on_tick = 0;
  for (std::size_t i = 0; i < r.data.size(); ++i) {
    const auto k =
        static_cast<std::size_t>(k0) + static_cast<std::size_t>(std::lround(r.data.t[i] / kPeriod));
    INFO("tick ", i, " step ", k);
    // A read due mid-step that a loaded machine delays by half a period finds the next step:
    // a real value, one tick late. Any other value is wrong.
    CHECK((served(i, k) || served(i, k + 1)));
    if (served(i, k)) ++on_tick;
  }
  CHECK(on_tick >= 15);  // all 20 unless the machine stalled for 25 ms
  CHECK(no_writes(plc));
}

TEST_CASE("frozen registers: rows marked stale and counted with stale_after, good without it") {
  // FIC101's PV stops being updated from 0.8 s to 2.0 s of the PLC's run; FIC101 has
  // stale_after 0.3 s, FIC101RAW reads the same registers without it (the default: off).
  SimPlc plc(load_site_config(kSimSite), SimPlcOptions{10.0, 0});
  FaultConfig freeze;
  freeze.kind = FaultKind::freeze;
  freeze.address = 2;
  freeze.start_s = 0.8;
  freeze.duration_s = 1.2;
  plc.add_fault(freeze);
  plc.start();
  SiteConfig site = fast_site(plc.port());
  site.loops.resize(1);
  site.loops[0].points[static_cast<std::size_t>(PointName::pv)].stale_after_s = 0.3;
  LoopConfigEntry raw = load_site_config(kSimSite).loops[0];
  raw.name = "FIC101RAW";
  raw.sample_period_s = kPeriod;
  site.loops.push_back(raw);
  const std::string db = fresh_db("frozen");
  RecorderOptions o;
  o.db_path = db;
  o.duration_s = 3.0;
  Recorder rec(site, o, make_bus);
  std::atomic<bool> stop{false};
  const RecorderStatus s = rec.run(stop);
  REQUIRE(s.loops.size() == 2);
  const LoopCounts& fic = s.loops[0];
  const LoopCounts& plain = s.loops[1];
  // About 1.2 s - 0.3 s = 0.9 s of 50 ms ticks stale; bounds generous for a loaded machine.
  MESSAGE("stale rows " << fic.stale << ", good " << fic.good << ", missed " << fic.missed);
  CHECK(fic.rows == 60);
  CHECK(fic.stale >= 8);
  CHECK(fic.stale <= 24);
  CHECK(fic.good >= 25);
  CHECK(fic.comm_error == 0);
  CHECK(fic.gaps >= 1);
  CHECK(plain.stale == 0);
  CHECK(plain.good + plain.missed == 60);
  CHECK(s.errors());
  CHECK(s.last_error.find("FIC101: FIC101.pv: holding register(s) 2..3 unchanged for") !=
        std::string::npos);
  const std::string fic_id = "(SELECT id FROM loops WHERE name = 'FIC101')";
  CHECK(scalar(db, "SELECT count(*) FROM samples WHERE q_pv = 1 AND loop_id = " + fic_id) ==
        static_cast<double>(fic.stale));
  // A stale row keeps its value (the last one the PLC served), unlike a comm-error row.
  CHECK(scalar(db, "SELECT count(*) FROM samples WHERE q_pv = 1 AND pv IS NULL") == 0);
  CHECK(scalar(db, "SELECT count(DISTINCT pv) FROM samples WHERE q_pv = 1") == 1);
  // Stale rows lie within the frozen stretch: ticks 16..40 of the PLC's clock, which started a
  // moment before the recorder's (so a little earlier in ticks), plus the read's own slack.
  CHECK(scalar(db, "SELECT min(tick) FROM samples WHERE q_pv = 1") >= 16);
  CHECK(scalar(db, "SELECT max(tick) FROM samples WHERE q_pv = 1") <= 42);
  CHECK(no_writes(plc));
}

TEST_CASE("short gaps are bridged by interpolation when asked; long ones still split the range") {
  // One loop at 1 s, op = k, pv = 2k, sp = 3k on tick k: interpolation across a gap is exact.
  const std::string db = fresh_db("bridge");
  {
    RecordingDb rec(db);
    const std::int64_t run = rec.begin_run("test");
    LoopConfigEntry loop{};
    loop.name = "loop-with-short-gaps";  // (a short name trips g++ 12's -Wmaybe-uninitialized)
    loop.sample_period_s = 1.0;
    loop.points[static_cast<std::size_t>(PointName::sp)].present = true;
    const std::int64_t id = rec.add_loop(run, loop);
    std::vector<SampleRow> rows;
    for (std::int64_t k = 0; k < 100; ++k) {
      if (k == 60) continue;  // a row lost (kill -9 before a commit)
      SampleRow r;
      r.loop_id = id;
      r.tick = k;
      const double x = static_cast<double>(k);
      Quality q = Quality::good;
      if (k == 10 || (k >= 40 && k <= 44)) q = Quality::missed;
      if (k == 20 || k == 21) q = Quality::comm_error;
      r.values[0] = {q == Quality::good ? x : std::nan(""), q};
      r.values[1] = {q == Quality::good ? 2 * x : std::nan(""), q};
      r.values[2] = {3 * x, Quality::good};
      rows.push_back(r);
    }
    rec.insert(rows);
    rec.end_run(run, "done");
  }
  auto exact = [](const RecordedLoop& r, std::int64_t first) {
    for (std::size_t i = 0; i < r.data.size(); ++i) {
      const double k = static_cast<double>(first) + static_cast<double>(i);
      if (std::abs(r.data.t[i] - k) > 1e-9 || std::abs(r.data.op[i] - k) > 1e-9 ||
          std::abs(r.data.pv[i] - 2 * k) > 1e-9 || std::abs(r.data.sp[i] - 3 * k) > 1e-9)
        return false;
    }
    return true;
  };
  auto note_with = [](const RecordedLoop& r, const std::string& part) {
    for (const auto& n : r.notes)
      if (n.find(part) != std::string::npos) return true;
    return false;
  };
  // Without bridging: the longest clean stretch is after the lost row.
  const RecordedLoop plain =
      read_recorded_loop(db, "loop-with-short-gaps", std::nullopt, std::nullopt, 0, true);
  CHECK(plain.data.size() == 39);
  CHECK(exact(plain, 61));
  // Bridged: the gaps of 1 and 2 ticks and the lost row are filled; the 5-tick gap is not, so
  // the longest stretch is now 45 .. 99 (with tick 60 interpolated).
  const RecordedLoop b = read_recorded_loop(db, "loop-with-short-gaps", std::nullopt, std::nullopt,
                                            0, true, kBridgedTicks);
  CHECK(b.data.size() == 55);
  CHECK(b.bridged_gaps == 3);
  CHECK(plain.bridged_gaps == 0);
  CHECK(exact(b, 45));
  CHECK(note_with(b, "3 short gap(s) of at most 2 tick(s) (4 in all, at 10, 20, 60 s)"));
  CHECK(note_with(b, "using the longest clean stretch, 45 .. 99 s"));
  // A range whose only gaps are short reads whole without asking for the longest stretch.
  const RecordedLoop head =
      read_recorded_loop(db, "loop-with-short-gaps", 0.0, 39.0, 0, false, kBridgedTicks);
  CHECK(head.data.size() == 40);
  CHECK(exact(head, 0));
  // Bridging never hides a long gap: without longest_clean it is still an error.
  CHECK_THROWS_AS(
      read_recorded_loop(db, "loop-with-short-gaps", std::nullopt, std::nullopt, 0, false, 2),
      RecordingGapError);
  CHECK_THROWS_AS(read_recorded_loop(db, "loop-with-short-gaps", 0.0, 39.0), RecordingGapError);
}

namespace {
using test::exec_sql;

std::string error_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const std::exception& e) {
    return e.what();
  }
  return "";
}
}  // namespace

TEST_CASE("utc_seconds reads back what utc_timestamp writes, and nothing else") {
  for (std::time_t t : {std::time_t{0}, std::time_t{951782400}, std::time_t{1790820000}})
    CHECK(utc_seconds(utc_timestamp(t)) == static_cast<double>(t));
  for (const char* bad : {"", "2026-10-01 02:00:00", "2026-10-01T02:00:00", "2026-13-01T02:00:00Z",
                          "2026-10-01T24:00:00Z", "2026-10-01T02:00:00Zx", "2026-10-01T-1:00:00Z"})
    CHECK_MESSAGE(std::isnan(utc_seconds(bad)), bad);
}

TEST_CASE("recordings from before table versions stay readable; newer tables are refused") {
  const std::string db = fresh_db("versions");
  // The recording tables as the first release wrote them (no schema_versions), with a run.
  exec_sql(db, R"sql(
    CREATE TABLE runs(id INTEGER PRIMARY KEY, started_utc TEXT NOT NULL, ended_utc TEXT,
      config_file TEXT, status TEXT NOT NULL DEFAULT 'recording');
    CREATE TABLE loops(id INTEGER PRIMARY KEY, run_id INTEGER NOT NULL REFERENCES runs(id),
      name TEXT NOT NULL, sample_period REAL NOT NULL, has_sp INTEGER NOT NULL,
      has_mv INTEGER NOT NULL, has_mode INTEGER NOT NULL, UNIQUE(run_id, name));
    CREATE TABLE samples(loop_id INTEGER NOT NULL, tick INTEGER NOT NULL, wall REAL NOT NULL,
      lateness REAL NOT NULL, op REAL, pv REAL, sp REAL, mv REAL, mode REAL,
      q_op INTEGER NOT NULL, q_pv INTEGER NOT NULL, q_sp INTEGER NOT NULL,
      q_mv INTEGER NOT NULL, q_mode INTEGER NOT NULL, PRIMARY KEY(loop_id, tick)) WITHOUT ROWID;
    CREATE TABLE gaps(loop_id INTEGER NOT NULL, first_tick INTEGER NOT NULL,
      last_tick INTEGER NOT NULL, reason TEXT NOT NULL);
    INSERT INTO runs(started_utc, status) VALUES('2026-10-01T02:00:00Z', 'done');
    INSERT INTO loops(run_id, name, sample_period, has_sp, has_mv, has_mode)
      VALUES(1, 'FIC101', 1.0, 0, 0, 0);)sql");
  std::string rows;
  for (int k = 0; k < 50; ++k)
    rows += "INSERT INTO samples VALUES(1, " + std::to_string(k) + ", 0, 0, " +
            std::to_string(k % 7) + ", " + std::to_string(2 * k) + ", NULL, NULL, NULL, 0, 0, 0, " +
            "0, 0);";
  exec_sql(db, rows);
  const RecordedLoop first = read_recorded_loop(db, "FIC101");  // read before any migration
  CHECK(first.rows == 50);
  CHECK(first.data.clock_at_zero_s ==
        1790820000.0);  // t = 0 is the run's start, 2026-10-01T02:00:00Z
  // An imported run started when it was imported: its ticks have no clock.
  exec_sql(db, "UPDATE runs SET status = 'imported'");
  CHECK(std::isnan(read_recorded_loop(db, "FIC101").data.clock_at_zero_s));
  exec_sql(db, "UPDATE runs SET status = 'done'");
  {
    RecordingDb rec(db);  // a new recording into the old file
    const std::int64_t run = rec.begin_run("test");
    CHECK(run == 2);
    rec.end_run(run, "done");
  }
  CHECK(scalar(db, "SELECT version FROM schema_versions WHERE component = 'recorder'") ==
        kRecorderSchemaVersion);
  const RecordedLoop old = read_recorded_loop(db, "FIC101");
  REQUIRE(old.rows == 50);  // nothing recorded before was lost
  CHECK(old.data.pv[49] == 98.0);

  exec_sql(db, "UPDATE schema_versions SET version = 99 WHERE component = 'recorder'");
  for (const std::string& m :
       {error_of([&] { RecordingDb rec(db); }), error_of([&] { RecordingDb rec(db, false); }),
        error_of([&] { read_recorded_loop(db, "FIC101"); })}) {
    CHECK(m.find(db) != std::string::npos);
    CHECK(m.find("recording tables are version 99, written by a newer valvediag") !=
          std::string::npos);
    CHECK(m.find("update valvediag") != std::string::npos);
  }
  CHECK(scalar(db, "SELECT count(*) FROM runs") == 2);  // the refusal wrote nothing

  // A site database that holds sweep results only has no recordings to read.
  const std::string sweeps_only = fresh_db("sweeps-only");
  exec_sql(sweeps_only, "CREATE TABLE sweeps(id INTEGER PRIMARY KEY)");
  const std::string m = error_of([&] { read_recorded_loop(sweeps_only, "FIC101"); });
  CHECK(m.find(sweeps_only + ": holds no recordings; record one with valvediag record") !=
        std::string::npos);
}

namespace {
// Another process's writer: once the recorder has stored `after_samples` samples (0: at once),
// holds SQLite's write lock on `db` for `hold_s`; `taken` says it got it (a thread of the test
// stands in for the other process: SQLite locks per connection).
std::thread hold_write_lock(const std::string& db, double hold_s, std::atomic<bool>& taken,
                            int after_samples = 10) {
  return std::thread([db, hold_s, &taken, after_samples] {
    if (after_samples > 0 &&
        !test::wait_for([&] { return scalar(db, "SELECT count(*) FROM samples") >= after_samples; },
                        10.0))
      return;
    sqlite3* c = nullptr;
    sqlite3_open(db.c_str(), &c);
    sqlite3_busy_timeout(c, 5000);
    const bool ok = sqlite3_exec(c, "BEGIN IMMEDIATE", nullptr, nullptr, nullptr) == SQLITE_OK;
    taken = ok;
    if (ok) {
      std::this_thread::sleep_for(std::chrono::duration<double>(hold_s));
      sqlite3_exec(c, "COMMIT", nullptr, nullptr, nullptr);
    }
    sqlite3_close(c);
  });
}
}  // namespace

TEST_CASE_FIXTURE(SimRig,
                  "a write lock held 8 s by another process: samples wait in memory, nothing is "
                  "lost") {
  // Before, the recorder gave up after SQLite's 5 s busy timeout ("inserting samples: not an
  // error") and kept what it had stored until then. Locks of up to a minute are the designed
  // bound (busy_limit_s, 90 s by default); 8 s exceeds the old timeout without a minute's wait.
  const std::string db = fresh("busy", 11.0, {"FIC101"});
  o.status_interval_s = 0.2;
  Recorder rec(fast_site(plc.port()), o, make_bus);
  std::atomic<bool> stop{false}, taken{false};
  std::thread locker = hold_write_lock(db, 8.0, taken);
  std::uint64_t waiting_max = 0;
  double busy_max = 0.0;
  const RecorderStatus s = rec.run(stop, [&](const RecorderStatus& st) {
    waiting_max = std::max(waiting_max, st.waiting);
    busy_max = std::max(busy_max, st.busy_s);
  });
  locker.join();
  REQUIRE(taken.load());
  MESSAGE("busy " << s.busy_longest_s << " s, up to " << s.waiting_peak << " rows in memory");
  CHECK(s.loops[0].rows == 220);
  CHECK(s.committed == 220);
  CHECK(scalar(db, "SELECT count(*) FROM samples") == 220);
  CHECK(scalar(db, "SELECT max(tick) + 1 - count(*) FROM samples") == 0);  // no hole
  CHECK(scalar(db, "SELECT count(*) FROM runs WHERE status = 'completed'") == 1);
  CHECK(s.busy_times == 1);
  CHECK(s.busy_longest_s >= 7.0);
  CHECK(s.busy_longest_s <= 10.0);
  // 8 s of 50 ms ticks waited in memory, and the status said so while it lasted.
  CHECK(s.waiting_peak >= 140);
  CHECK(s.waiting_peak <= 220);
  CHECK(busy_max >= 7.0);
  CHECK(waiting_max >= 130);
  CHECK(s.busy_message.find(db + ": database busy (locked by another process)") !=
        std::string::npos);
  CHECK(s.busy_message.find("SQLite does not say which process") != std::string::npos);
  CHECK(no_writes(plc));
}

TEST_CASE_FIXTURE(SimRig,
                  "a write lock held past the recorder's limit stops it with a message, never a "
                  "hang") {
  const std::string db = fresh("busy_limit", 30.0, {"FIC101"});
  o.busy_limit_s = 1.5;  // the test's stand-in for the 90 s default
  auto rec = std::make_unique<Recorder>(fast_site(plc.port()), o, make_bus);
  std::atomic<bool> stop{false}, taken{false};
  std::thread locker = hold_write_lock(db, 5.0, taken);
  const auto t0 = std::chrono::steady_clock::now();
  const std::string m = error_of([&] { rec->run(stop); });
  const double took = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  locker.join();
  REQUIRE(taken.load());
  INFO(m);
  CHECK(took < 10.0);  // stopped at the limit, not at the 30 s duration
  CHECK(m.find(db + ": database busy (locked by another process) while inserting samples") !=
        std::string::npos);
  CHECK(m.find("SQLite does not say which process holds the lock") != std::string::npos);
  CHECK(m.find("(the recorder waits up to 2 s): stopped") != std::string::npos);
  CHECK(m.find("sample(s) held in memory not stored") != std::string::npos);
  CHECK(m.find("not an error") == std::string::npos);
  CHECK(scalar(db, "SELECT count(*) FROM samples") >= 10);  // what was stored is kept
  // The aborted run is `recording` no longer once the next recorder opens the database.
  rec.reset();
  Recorder next(fast_site(plc.port()), o, make_bus);
  CHECK(next.interrupted_runs() == std::vector<std::int64_t>{1});
  CHECK(scalar(db, "SELECT count(*) FROM runs WHERE status = 'interrupted' AND id = 1") == 1);
  CHECK(no_writes(plc));
}

TEST_CASE_FIXTURE(SimRig,
                  "a write lock held when the recorder starts: it polls at once and stores all "
                  "later") {
  // Before, the recorder failed after SQLite's 5 s busy timeout and recorded nothing. Now the
  // rows wait in memory from the first tick, as when the database is busy mid-run.
  for (const bool existing : {true, false}) {
    CAPTURE(existing);
    fresh(existing ? "busy_start" : "busy_start_new", 6.0, {"FIC101"});
    if (existing) {
      // A recording with one run left `recording` by a killed recorder.
      RecorderOptions first = o;
      first.duration_s = 0.3;
      Recorder r(fast_site(plc.port()), first, make_bus);
      std::atomic<bool> stop{false};
      r.run(stop);
      exec_sql(o.db_path, "UPDATE runs SET status = 'recording'");
    }
    std::atomic<bool> taken{false};
    std::thread locker = hold_write_lock(o.db_path, 4.0, taken, 0);
    REQUIRE(test::wait_for([&] { return taken.load(); }, 5.0));
    // Two seconds before the lock goes: the run's start must come before it.
    const std::string before_release = utc_timestamp(std::time(nullptr) + 2);
    Recorder rec(fast_site(plc.port()), o, make_bus);
    CHECK_FALSE(rec.database_ready());
    std::atomic<bool> stop{false};
    const auto t0 = std::chrono::steady_clock::now();
    const RecorderStatus s = rec.run(stop);
    const double took =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    locker.join();
    const std::string db = o.db_path;
    const std::string run = std::to_string(rec.run_id());
    CHECK(rec.run_id() == (existing ? 2 : 1));
    CHECK(took < 12.0);
    CHECK(s.loops[0].rows == 120);
    CHECK(s.committed == 120);
    CHECK(s.busy_times == 1);
    CHECK(s.busy_longest_s >= 3.0);
    CHECK(s.waiting_peak >= 60);
    const std::string in_run =
        " FROM samples JOIN loops ON loops.id = samples.loop_id WHERE loops.run_id = " + run;
    CHECK(scalar(db, "SELECT count(*)" + in_run) == 120);
    CHECK(scalar(db, "SELECT min(tick)" + in_run) == 0);  // from the first tick
    // Polled on time from the first tick: the database's set-up (here its busy timeout) does not
    // hold the polls back. Held back by the 4 s lock, some 80 ticks of 50 ms would be marked
    // missed; a loaded machine (ctest -j2 beside the diagnoses) has missed one.
    CHECK(s.missed <= 2);
    CHECK(scalar(db, "SELECT count(*)" + in_run + " AND q_op = 3") == s.missed);
    CHECK(scalar(db, "SELECT max(tick) + 1 - count(*)" + in_run) == 0);
    CHECK(scalar(db, "SELECT count(*) FROM runs WHERE status = 'completed' AND id = " + run) == 1);
    // The run started when the recorder did, not when the lock was released.
    CHECK(scalar(db, "SELECT started_utc <= '" + before_release +
                         "' FROM runs WHERE id = " + run) == 1);
    if (existing) {
      CHECK(rec.interrupted_runs() == std::vector<std::int64_t>{1});
      CHECK(scalar(db, "SELECT count(*) FROM runs WHERE status = 'interrupted' AND id = 1") == 1);
    }
  }
  CHECK(no_writes(plc));
}

TEST_CASE_FIXTURE(SimRig,
                  "a second recorder on a database is refused, naming the first; free once it "
                  "ends") {
  const std::string db = fresh("two", 0.5, {"FIC101"});
  const std::string lock = fs::weakly_canonical(db).string() + ".lock";
  {
    Recorder first(fast_site(plc.port()), o, make_bus);
    CHECK(fs::exists(lock));
    const std::string m = error_of([&] { Recorder second(fast_site(plc.port()), o, make_bus); });
    CHECK(m.find(db + " is being recorded by valvediag pid " + std::to_string(::getpid()) +
                 " on host ") != std::string::npos);
    CHECK(m.find("a second recorder would poll the PLC twice: stop that one first") !=
          std::string::npos);
    CHECK_THROWS_AS(Recorder(fast_site(plc.port()), o, make_bus), DatabaseInUseError);
    std::atomic<bool> stop{false};
    first.run(stop);
    CHECK(first.run_id() == 1);
  }
  CHECK(!fs::exists(lock));  // removed when the recorder ends
  Recorder third(fast_site(plc.port()), o, make_bus);
  std::atomic<bool> stop{false};
  third.run(stop);
  CHECK(third.run_id() == 2);
  CHECK(scalar(db, "SELECT count(*) FROM runs WHERE status = 'completed'") == 2);
  CHECK(no_writes(plc));
}
