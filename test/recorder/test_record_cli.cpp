// The record, export and fit commands in their own processes: kill -9 of the recorder, exit
// statuses, config errors before any bus traffic. Each child is bounded: killed after a limit.
#include <doctest/doctest.h>
#include <fcntl.h>
#include <signal.h>
#include <sqlite3.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <thread>

#include "../bus/bus_test_util.hpp"
#include "../common/run_cli.hpp"
#include "../common/sqlite_exec.hpp"
#include "valvediag/drivers/sim_plc.hpp"
#include "valvediag/recorder/recorder.hpp"
#include "valvediag/sim/scenarios.hpp"

using namespace valvediag;
namespace fs = std::filesystem;

namespace {
const std::string kSimSiteToml = std::string(VALVEDIAG_CONFIG_DIR) + "/sim-site.toml";
const fs::path kTmp = VALVEDIAG_TMP;

using test::spawn;
using test::wait_child;
using Result = test::CliResult;
Result run(const std::vector<std::string>& args, double limit_s = 60.0) {
  return test::run_cli(VALVEDIAG_BIN, args, kTmp, limit_s);
}

std::string fresh(const std::string& name) {
  const fs::path p = kTmp / name;
  for (const char* suffix : {"", "-wal", "-shm"}) fs::remove(p.string() + suffix);
  return p.string();
}

// A site file for the PLC on `port`: FIC101 alone, polled every `period` s.
std::string write_site(const std::string& name, int port, double period,
                       const std::string& extra = "") {
  const fs::path p = kTmp / name;
  std::ofstream f(p);
  f << "[[bus]]\nname = \"plc\"\nprotocol = \"modbus-tcp\"\ncontroller = \"tcp://127.0.0.1:" << port
    << "\"\ntimeout = \"100ms\"\nretries = 0\nreconnect_max = \"500ms\"\n"
    << "[[loop]]\nname = \"FIC101\"\nbus = \"plc\"\nsample_period = " << period << "\n"
    << "op = { register = \"holding\", address = 0, type = \"FLOAT32\" }\n"
    << "pv = { register = \"holding\", address = 2, type = \"FLOAT32\" }\n"
    << "sp = { register = \"holding\", address = 4, type = \"FLOAT32\" }\n"
    << extra;
  return p.string();
}

double db_scalar(const std::string& db, const std::string& sql, std::string* text = nullptr) {
  return test::query_scalar(db, sql, text, false);
}

double wall_seconds() {
  return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
}
}  // namespace

TEST_CASE("kill -9 of the recorder: database intact, at most 1 s lost") {
  SimPlc plc(load_site_config(kSimSiteToml), SimPlcOptions{10.0, 0});
  plc.start();
  const std::string site = write_site("kill9.toml", plc.port(), 0.05);
  const std::string db = fresh("kill9.sqlite");
  const pid_t pid =
      spawn({VALVEDIAG_BIN, "record", "--config", site, "--db", db, "--quiet", "--duration", "60s"},
            kTmp / "kill9.txt");
  // Wait (bounded) until it has committed a few transactions, then kill it mid-run.
  REQUIRE(
      test::wait_for([&] { return db_scalar(db, "SELECT count(*) FROM samples") >= 30; }, 20.0));
  std::this_thread::sleep_for(std::chrono::milliseconds(700));
  const double killed_at = wall_seconds();
  ::kill(pid, SIGKILL);
  int status = 0;
  ::waitpid(pid, &status, 0);
  CHECK(WIFSIGNALED(status));
  std::string integrity;
  db_scalar(db, "PRAGMA integrity_check", &integrity);
  CHECK(integrity == "ok");
  const double last = db_scalar(db, "SELECT max(wall) FROM samples");
  MESSAGE("kill -9 lost the last " << killed_at - last << " s");
  CHECK(killed_at - last <= 1.0);
  // No hole: every tick up to the last stored one has its row.
  CHECK(db_scalar(db, "SELECT max(tick) + 1 - count(*) FROM samples") == 0);
  CHECK(plc.write_requests() == 0);
}

TEST_CASE("two recorders: the second is refused; kill -9 leaves no block; the run is interrupted") {
  SimPlc plc(load_site_config(kSimSiteToml), SimPlcOptions{10.0, 0});
  plc.start();
  const std::string site = write_site("two.toml", plc.port(), 0.05);
  const std::string db = fresh("two.sqlite");
  const pid_t first =
      spawn({VALVEDIAG_BIN, "record", "--config", site, "--db", db, "--quiet", "--duration", "60s"},
            kTmp / "two-first.txt");
  REQUIRE(
      test::wait_for([&] { return db_scalar(db, "SELECT count(*) FROM samples") >= 10; }, 20.0));
  Result r = run({"record", "--config", site, "--db", db, "--duration", "1s", "--quiet"}, 20.0);
  INFO(r.out);
  CHECK(r.status == 2);
  CHECK(r.out.find("error: " + db + " is being recorded by valvediag pid " + std::to_string(first) +
                   " on host ") != std::string::npos);
  CHECK(r.out.find("(run 1); a second recorder would poll the PLC twice") != std::string::npos);
  CHECK(db_scalar(db, "SELECT count(*) FROM runs") == 1);  // the refused one began no run
  // While it records, a reader sees the run as being recorded.
  const fs::path csv = kTmp / "two.csv";
  r = run({"export", "--db", db, "--loop", "FIC101", "--out", csv.string()});
  CHECK(r.out.find("export: loop FIC101 of run 1 (started ") != std::string::npos);
  CHECK(r.out.find(", recording: still being recorded, read so far)") != std::string::npos);

  ::kill(first, SIGKILL);
  CHECK(wait_child(first, 10.0) == -2);
  const std::string lock = fs::weakly_canonical(db).string() + ".lock";
  CHECK(fs::exists(lock));  // left by the killed recorder, locked by nobody
  std::string status;
  db_scalar(db, "SELECT status FROM runs WHERE id = 1", &status);
  CHECK(status == "recording");
  r = run({"export", "--db", db, "--loop", "FIC101", "--out", csv.string()});
  CHECK(r.out.find("of run 1 (started ") != std::string::npos);
  CHECK(r.out.find(", interrupted)") != std::string::npos);  // read as what it is

  // The stale file does not block the next recorder, which marks the run.
  r = run({"record", "--config", site, "--db", db, "--duration", "1s", "--quiet"}, 20.0);
  CHECK((r.status == 0 || r.status == 4));
  CHECK(r.out.find("note: run 1 in " + db +
                   " was left 'recording' by a recorder that did not end "
                   "cleanly") != std::string::npos);
  db_scalar(db, "SELECT status FROM runs WHERE id = 1", &status);
  CHECK(status == "interrupted");
  db_scalar(db, "SELECT status FROM runs WHERE id = 2", &status);
  CHECK(status == "completed");
  CHECK(!fs::exists(lock));

  // export says which run it takes, names the other, and lists the runs for a wrong --run.
  r = run({"export", "--db", db, "--loop", "FIC101", "--out", csv.string(), "--from", "0.2"});
  CHECK(r.out.find("export: loop FIC101 of run 2 (started ") != std::string::npos);
  CHECK(r.out.find(", completed); other runs with it: 1 (--run ID)") != std::string::npos);
  r = run({"export", "--db", db, "--loop", "FIC101", "--out", csv.string(), "--run", "7"});
  CHECK(r.status == 2);
  CHECK(r.out.find(db + ": no run 7 with loop 'FIC101'; runs with it: 1 (started ") !=
        std::string::npos);
  CHECK(r.out.find(", interrupted), 2 (started ") != std::string::npos);
  CHECK(r.out.find(", completed) (--run ID)") != std::string::npos);
  r = run({"export", "--db", db, "--loop", "FIC101", "--out", csv.string(), "--run", "1", "--to",
           "0.2"});
  CHECK(r.status == 0);
  CHECK(r.out.find("export: loop FIC101 of run 1 (started ") != std::string::npos);
  CHECK(r.out.find("other runs with it: 2 (--run ID)") != std::string::npos);
  CHECK(plc.write_requests() == 0);
}

TEST_CASE("a config error is reported with file and line before any bus traffic") {
  SimPlc plc(load_site_config(kSimSiteToml), SimPlcOptions{10.0, 0});
  plc.start();
  const std::string site =
      write_site("bad.toml", plc.port(), 0.05, "mv = { register = \"coil\", address = 9 }\n");
  const Result r = run({"record", "--config", site, "--db", fresh("bad.sqlite")});
  CHECK(r.status == 2);
  CHECK(r.out.find("bad.toml:15:") != std::string::npos);
  CHECK(r.out.find("must be \"holding\" or \"input\"") != std::string::npos);
  CHECK(plc.connections() == 0);
  CHECK(!fs::exists(kTmp / "bad.sqlite"));
}

TEST_CASE("record on a database busy at its start says so and stores every sample once free") {
  SimPlc plc(load_site_config(kSimSiteToml), SimPlcOptions{10.0, 0});
  plc.start();
  const std::string site = write_site("busy-start.toml", plc.port(), 0.05);
  const std::string db = fresh("busy-start.sqlite");
  std::atomic<bool> taken{false};
  std::thread locker([&] {  // another program's open write transaction, for 3 s
    sqlite3* c = nullptr;
    sqlite3_open(db.c_str(), &c);
    taken = sqlite3_exec(c, "BEGIN IMMEDIATE", nullptr, nullptr, nullptr) == SQLITE_OK;
    std::this_thread::sleep_for(std::chrono::seconds(3));
    sqlite3_exec(c, "COMMIT", nullptr, nullptr, nullptr);
    sqlite3_close(c);
  });
  while (!taken.load()) std::this_thread::sleep_for(std::chrono::milliseconds(10));
  const Result r = run({"record", "--config", site, "--db", db, "--duration", "2s", "--quiet"});
  locker.join();
  INFO(r.out);
  CHECK((r.status == 0 || r.status == 4));
  CHECK(r.out.find("note: " + db + " is busy: another process holds SQLite's write lock") !=
        std::string::npos);
  CHECK(r.out.find("stored once it is free (up to 90 s)") != std::string::npos);
  CHECK(r.out.find("FIC101: 40 samples") != std::string::npos);
  CHECK(db_scalar(db, "SELECT count(*) FROM samples") == 40);
  CHECK(db_scalar(db, "SELECT min(tick) FROM samples") == 0);
}

TEST_CASE("record exits 4 when errors happened, 0 when not; export and fit read the database") {
  SimPlc plc(load_site_config(kSimSiteToml), SimPlcOptions{100.0, 0});
  plc.start();
  // paper-ex1 at 100x: Ts 0.5 s becomes 5 ms; recorded at the same period.
  const std::string site = write_site("clean.toml", plc.port(), 0.005);
  const std::string db = fresh("clean.sqlite");
  Result r = run({"record", "--config", site, "--db", db, "--duration", "3s", "--quiet"});
  INFO(r.out);
  const bool clean = r.out.find(" 0 with errors") != std::string::npos;
  CHECK(r.status == (clean ? 0 : 4));
  CHECK(r.out.find("FIC101: 600 samples") != std::string::npos);
  const fs::path csv = kTmp / "clean.csv";
  fs::remove(csv);
  r = run({"export", "--db", db, "--loop", "FIC101", "--out", csv.string(), "--from", "0.5"});
  if (clean) {
    CHECK(r.status == 0);
    std::ifstream f(csv);
    std::string header;
    std::getline(f, header);
    CHECK(header == "t,op,pv,sp");
    // The reader's bound on rows, which its refusal tells the user to raise, is export's option.
    const fs::path capped = kTmp / "capped.csv";
    fs::remove(capped);
    r = run(
        {"export", "--db", db, "--loop", "FIC101", "--out", capped.string(), "--max-rows", "100"});
    CHECK(r.status == 2);
    CHECK(r.out.find("more than 100 rows in the range") != std::string::npos);
    CHECK(r.out.find("--max-rows") != std::string::npos);
    CHECK_FALSE(fs::exists(capped));
    r = run(
        {"export", "--db", db, "--loop", "FIC101", "--out", capped.string(), "--max-rows", "600"});
    CHECK(r.status == 0);
    CHECK(r.out.find("wrote " + capped.string() + ": 600 samples") != std::string::npos);
    r = run({"fit", "--db", db, "--loop", "FIC101", "--na-max", "1", "--nb-max", "1", "--nk-max",
             "6", "--L-max", "6"});
    CHECK(r.status == 0);
    CHECK(r.out.find("fitness:") != std::string::npos);
    r = run({"diagnose", "--db", db, "--loop", "FIC101", "--candidates", "stiction,deadband"});
    CHECK(r.status == 0);
    CHECK(r.out.find("verdict:") != std::string::npos);
    r = run({"ladder", "--db", db, "--loop", "FIC101"});  // the fit and the diagnosis above
    CHECK(r.status == 0);
    CHECK(r.out.find("linear") != std::string::npos);
  }
  r = run({"export", "--db", db, "--loop", "NOPE", "--out", csv.string()});
  CHECK(r.status == 2);
  CHECK(r.out.find("recorded loops: FIC101") != std::string::npos);
  r = run({"fit", "--db", db});
  CHECK(r.status == 2);
  r = run({"diagnose", "--db", db, "--loop", "NOPE"});
  CHECK(r.status == 2);
  CHECK(r.out.find("recorded loops: FIC101") != std::string::npos);

  // Every request refused: exit status 4 and the exception count in the summary.
  FaultConfig f;
  f.kind = FaultKind::exception;
  plc.add_fault(f);
  r = run({"record", "--config", site, "--db", fresh("refused.sqlite"), "--duration", "0.5s",
           "--quiet"});
  CHECK(r.status == 4);
  CHECK(r.out.find("exceptions") != std::string::npos);
  CHECK(r.out.find("Slave device or server failure") != std::string::npos);
  CHECK(plc.write_requests() == 0);
}

// Nothing listens on port 1: no request is ever sent, so the bus line must say why its loop's
// samples are all comm-errors (it read "0 requests, 0 failed" beside them).
TEST_CASE("record against an unreachable PLC: the summary counts the failed connection attempts") {
  const std::string site = write_site("unreachable.toml", 1, 0.1);
  const Result r = run({"record", "--config", site, "--db", fresh("unreachable.sqlite"),
                        "--duration", "1.5s", "--quiet"});
  INFO(r.out);
  CHECK(r.status == 4);
  CHECK(r.out.find(" 0 good, ") != std::string::npos);
  CHECK(r.out.find("bus plc: 0 requests, 0 failed") != std::string::npos);
  const std::size_t at = r.out.find(" connection attempt(s); not connected at the end");
  REQUIRE(at != std::string::npos);
  // At least the first attempt and one after the backoff (500 ms at most) within 1.5 s.
  const std::size_t from = r.out.rfind(' ', at - 1) + 1;
  CHECK(std::stoi(r.out.substr(from, at - from)) >= 2);
  CHECK(r.out.find("Connection refused") != std::string::npos);
}

TEST_CASE("sim-plc prints its free port, serves the recorder, and reports the function codes") {
  const fs::path out = kTmp / "simplc.txt";
  fs::remove(out);  // else the port of an earlier run may be read before the child truncates it
  const pid_t pid = spawn({VALVEDIAG_BIN, "sim-plc", "--config", kSimSiteToml, "--port", "0",
                           "--speed", "10", "--duration", "4s"},
                          out);
  int port = 0;
  REQUIRE(test::wait_for(
      [&] {
        std::ifstream f(out);
        std::string line;
        while (std::getline(f, line))
          if (line.rfind("port ", 0) == 0) port = std::stoi(line.substr(5));
        return port > 0;
      },
      10.0));
  const std::string site = write_site("simplc.toml", port, 0.05);
  const Result r = run(
      {"record", "--config", site, "--db", fresh("simplc.sqlite"), "--duration", "1s", "--quiet"});
  CHECK(r.out.find("FIC101: 20 samples") != std::string::npos);
  CHECK(wait_child(pid, 15.0) == 0);
  std::ifstream f(out);
  std::stringstream ss;
  ss << f.rdbuf();
  INFO(ss.str());
  CHECK(ss.str().find("requests by function code: 3:") != std::string::npos);
  CHECK(ss.str().find("write requests (refused): 0") != std::string::npos);
}

TEST_CASE("a CAN site on a kernel without SocketCAN: a clear message, exit 2, no file") {
  const std::string db = fresh("can.sqlite");
  const Result r = run({"record", "--config", std::string(VALVEDIAG_CONFIG_DIR) + "/can-site.toml",
                        "--db", db, "--duration", "1s"});
  INFO(r.out);
  CHECK(r.status == 2);
  CHECK((r.out.find("SocketCAN is not available") != std::string::npos ||
         r.out.find("CAN interface 'can0' not found") != std::string::npos));
  CHECK(!fs::exists(db));
}

TEST_CASE("sim-plc serves CAN on a Unix socket; record reads it through interface = unix:PATH") {
  // configs/sim-can-site.toml, moved to this directory: its socket path, its DBC, its port.
  std::string text;
  {
    std::ifstream f(std::string(VALVEDIAG_CONFIG_DIR) + "/sim-can-site.toml");
    std::stringstream ss;
    ss << f.rdbuf();
    text = ss.str();
  }
  const std::string sock = (kTmp / "simcan.sock").string();
  auto replace = [](std::string s, const std::string& from, const std::string& to) {
    const auto at = s.find(from);
    REQUIRE(at != std::string::npos);
    return s.replace(at, from.size(), to);
  };
  text = replace(text, "unix:/tmp/valvediag-sim-can0.sock", "unix:" + sock);
  text = replace(text, "dbc = \"plant.dbc\"",
                 "dbc = \"" + std::string(VALVEDIAG_CONFIG_DIR) + "/plant.dbc\"");
  const fs::path plc_site = kTmp / "simcan-plc.toml";
  std::ofstream(plc_site) << text;

  const fs::path out = kTmp / "simcan-plc.txt";
  fs::remove(out);
  const pid_t pid = spawn({VALVEDIAG_BIN, "sim-plc", "--config", plc_site.string(), "--port", "0",
                           "--speed", "10", "--duration", "8s"},
                          out);
  int port = 0;
  bool serving = false;
  REQUIRE(test::wait_for(
      [&] {
        std::ifstream f(out);
        std::string line;
        while (std::getline(f, line)) {
          if (line.rfind("port ", 0) == 0) port = std::stoi(line.substr(5));
          if (line == "can-socket " + sock) serving = true;
        }
        return port > 0 && serving;
      },
      10.0));
  const fs::path rec_site = kTmp / "simcan-record.toml";
  std::ofstream(rec_site) << replace(text, "tcp://127.0.0.1:5021",
                                     "tcp://127.0.0.1:" + std::to_string(port));
  const std::string db = fresh("simcan.sqlite");
  const Result r =
      run({"record", "--config", rec_site.string(), "--db", db, "--duration", "2s", "--quiet"});
  INFO(r.out);
  CHECK((r.status == 0 || r.status == 4));
  CHECK(r.out.find("FIC101: 40 samples") != std::string::npos);
  CHECK(r.out.find("TIC205: 20 samples") != std::string::npos);
  CHECK(r.out.find("PIC301: 20 samples") != std::string::npos);
  CHECK(r.out.find("bus can0: ") != std::string::npos);
  CHECK(r.out.find(" 0 disconnects") != std::string::npos);
  for (const char* loop : {"FIC101", "TIC205", "PIC301"}) {
    INFO(loop);
    const std::string id = "(SELECT id FROM loops WHERE name = '" + std::string(loop) + "')";
    const double rows = db_scalar(db, "SELECT count(*) FROM samples WHERE loop_id = " + id);
    const double good = db_scalar(
        db, "SELECT count(*) FROM samples WHERE q_op = 0 AND q_pv = 0 AND loop_id = " + id);
    CHECK(rows >= 20);
    CHECK(good >= rows / 2);  // all of them on a quiet machine
    // Plausible: OP within 0..100 %, PV near the loops' operating point 50.
    CHECK(db_scalar(db, "SELECT count(*) FROM samples WHERE q_op = 0 AND q_pv = 0 AND loop_id = " +
                            id + " AND (op < 0 OR op > 100 OR abs(pv - 50) > 25)") == 0);
    CHECK(db_scalar(db,
                    "SELECT count(DISTINCT pv) FROM samples WHERE q_pv = 0 AND loop_id = " + id) >=
          3);  // the values move: it is the simulation, not one frame over and over
  }
  CHECK(db_scalar(db,
                  "SELECT count(*) FROM samples WHERE q_sp = 0 AND abs(sp - 50) < 10 AND "
                  "loop_id = (SELECT id FROM loops WHERE name = 'FIC101')") >= 20);

  CHECK(wait_child(pid, 20.0) == 0);
  std::ifstream f(out);
  std::stringstream ss;
  ss << f.rdbuf();
  INFO(ss.str());
  CHECK(ss.str().find("requests by function code: 3:") != std::string::npos);
  CHECK(ss.str().find("write requests (refused): 0") != std::string::npos);
  CHECK(ss.str().find("CAN: 1 client(s); bytes received from them: 0") != std::string::npos);
  CHECK(!fs::exists(sock));  // removed when sim-plc stops

  // sim-plc gone: the socket is missing, record says so and what to do, before any file.
  const std::string db2 = fresh("simcan-missing.sqlite");
  const Result m = run({"record", "--config", rec_site.string(), "--db", db2, "--duration", "1s"});
  CHECK(m.status == 2);
  CHECK(m.out.find("CAN socket '" + sock + "' does not exist; start the simulated PLC first") !=
        std::string::npos);
  CHECK(!fs::exists(db2));
}

TEST_CASE("sim-plc never puts frames on a real CAN interface; it says how to serve CAN") {
  const Result r = run({"sim-plc", "--config", std::string(VALVEDIAG_CONFIG_DIR) + "/can-site.toml",
                        "--duration", "1s"});
  INFO(r.out);
  CHECK(r.status == 2);
  CHECK(r.out.find("can-site.toml:9: bus 'can0' has interface \"can0\"; the simulated PLC sends "
                   "CAN frames only on a Unix socket") != std::string::npos);
  CHECK(r.out.find("--can-socket PATH") != std::string::npos);
}

TEST_CASE(
    "--bridge-gaps: fit, ladder and export read a recording's short gaps filled, and only with "
    "it") {
  // The paper's Example 1 loop, 1200 samples at 0.5 s, stored as a recording with one row lost
  // (tick 500, a kill -9 before a commit) and two ticks without good OP and PV (700, 701).
  const LoopData ex1 = run_scenario(scenario_by_name("paper-ex1"), 1, 1200);
  REQUIRE(ex1.size() == 1200);
  const std::string db = fresh("bridge_cli.sqlite");
  {
    RecordingDb rec(db);
    const std::int64_t run_id = rec.begin_run("test");
    LoopConfigEntry loop{};
    loop.name = "FIC101";
    loop.sample_period_s = 0.5;
    loop.points[static_cast<std::size_t>(PointName::sp)].present = true;
    const std::int64_t id = rec.add_loop(run_id, loop);
    std::vector<SampleRow> rows;
    for (std::size_t k = 0; k < ex1.size(); ++k) {
      if (k == 500) continue;
      SampleRow row;
      row.loop_id = id;
      row.tick = static_cast<std::int64_t>(k);
      const Quality q = k == 700 || k == 701 ? Quality::comm_error : Quality::good;
      row.values[0] = {q == Quality::good ? ex1.op[k] : std::nan(""), q};
      row.values[1] = {q == Quality::good ? ex1.pv[k] : std::nan(""), q};
      row.values[2] = {ex1.sp[k], Quality::good};
      rows.push_back(row);
    }
    REQUIRE(rows.size() == 1199);
    rec.insert(rows);
    rec.end_run(run_id, "done");
  }
  Result r;
  const std::vector<std::string> small{"--na-max", "1", "--nb-max", "1",
                                       "--nk-max", "6", "--L-max",  "6"};
  auto with = [](std::vector<std::string> a, const std::vector<std::string>& b) {
    a.insert(a.end(), b.begin(), b.end());
    return a;
  };
  // Without it the range is refused: the gaps named, and the option that fills them.
  r = run(with({"fit", "--db", db, "--loop", "FIC101"}, small));
  CHECK(r.status == 2);
  CHECK(r.out.find("gap(s) without good OP and PV") != std::string::npos);
  CHECK(r.out.find("--bridge-gaps N") != std::string::npos);
  // With it: both gaps filled, said where, and the fit runs on all 1200 ticks.
  r = run(with({"fit", "--db", db, "--loop", "FIC101", "--bridge-gaps", "2"}, small));
  INFO(r.out);
  CHECK(r.status == 0);
  CHECK(r.out.find("2 short gap(s) of at most 2 tick(s) (3 in all, at 250, 350 s) filled by "
                   "linear interpolation") != std::string::npos);
  CHECK(r.out.find("1200 samples") != std::string::npos);
  // The model is kept under that reading: ladder finds it with the same option, and only then.
  CHECK(db_scalar(db, "SELECT COUNT(*) FROM model_history WHERE reading = '--bridge-gaps 2'") == 1);
  r = run({"ladder", "--db", db, "--loop", "FIC101", "--bridge-gaps", "2"});
  CHECK(r.status == 0);
  CHECK(r.out.find("preisach") != std::string::npos);  // fit's default model
  r = run({"ladder", "--db", db, "--loop", "FIC101"});
  CHECK(r.status == 2);
  CHECK(r.out.find("--bridge-gaps") != std::string::npos);
  // A gap longer than the option allows stays a gap.
  const fs::path out = kTmp / "bridge_part.csv";
  fs::remove(out);
  r = run({"export", "--db", db, "--loop", "FIC101", "--bridge-gaps", "1", "--out", out.string()});
  CHECK(r.status == 2);
  CHECK(r.out.find("350") != std::string::npos);
  CHECK_FALSE(fs::exists(out));
  r = run({"export", "--db", db, "--loop", "FIC101", "--bridge-gaps", "2", "--out", out.string()});
  CHECK(r.status == 0);
  CHECK(r.out.find("1200 samples") != std::string::npos);
  // A file has no recorded gaps to fill (the export just written).
  r = run({"fit", out.string(), "--bridge-gaps", "2", "--no-history"});
  CHECK(r.status == 2);
  CHECK(r.out.find("--bridge-gaps goes with --db") != std::string::npos);
}
