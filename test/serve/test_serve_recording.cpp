// valvediag serve on a recording, over HTTP, against the simulated PLC (in this process, on a
// free loopback port, 100 times real time): `serve --db` serves the recorded loops' latest
// window and keeps their models in the recording's table model_history, writing nothing else;
// `serve --config --db` records the site while it serves it: the trends grow, the bus status is
// the recorder's, a job fits the latest seconds, Ctrl-C stores every sample, and no write request
// ever reaches the PLC.
#include <doctest/doctest.h>
#include <sqlite3.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <thread>

#include "../bus/bus_test_util.hpp"
#include "../common/run_cli.hpp"
#include "../common/sqlite_exec.hpp"
#include "valvediag/drivers/sim_plc.hpp"

// Last: it includes <httplib.h> (its `_res` macro breaks Eigen headers included after it).
#include "serve_process.hpp"

namespace fs = std::filesystem;
using nlohmann::json;
using valvediag::test::run_cli;
using valvediag::test::slurp;
using Clock = std::chrono::steady_clock;

namespace {

const fs::path kRecTmp = VALVEDIAG_TMP;
const std::string kSimSite = std::string(VALVEDIAG_CONFIG_DIR) + "/sim-site.toml";

std::string fresh(const std::string& name) {
  const fs::path p = kRecTmp / name;
  for (const char* suffix : {"", "-wal", "-shm", ".lock"}) fs::remove(p.string() + suffix);
  return p.string();
}

// A site of the PLC on `port`: FIC101 (paper Example 1, He stiction) every 5 ms and LIC201
// (deadband) every 10 ms: the simulated 0.5 s and 1 s at 100 times real time.
std::string write_site(const std::string& name, int port) {
  const fs::path p = kRecTmp / name;
  std::ofstream f(p);
  f << "[[bus]]\nname = \"plc\"\nprotocol = \"modbus-tcp\"\ncontroller = \"tcp://127.0.0.1:" << port
    << "\"\ntimeout = \"100ms\"\nretries = 0\nreconnect_max = \"500ms\"\n"
    << "[[loop]]\nname = \"FIC101\"\nbus = \"plc\"\nsample_period = 0.005\n"
    << "op = { register = \"holding\", address = 0, type = \"FLOAT32\" }\n"
    << "pv = { register = \"holding\", address = 2, type = \"FLOAT32\" }\n"
    << "sp = { register = \"holding\", address = 4, type = \"FLOAT32\" }\n"
    << "[[loop]]\nname = \"LIC201\"\nbus = \"plc\"\nsample_period = 0.01\n"
    << "op = { register = \"holding\", address = 10, type = \"FLOAT32\", byte_order = \"CDAB\" }\n"
    << "pv = { register = \"holding\", address = 12, type = \"FLOAT32\", byte_order = \"CDAB\" }\n"
    << "sp = { register = \"holding\", address = 14, type = \"FLOAT32\", byte_order = \"CDAB\" }\n";
  return p.string();
}

double scalar(const std::string& db, const std::string& sql, std::string* text = nullptr) {
  return valvediag::test::query_scalar(db, sql, text);
}

struct RecordingServer : valvediag::test::ServeProcess {
  RecordingServer(std::vector<std::string> args, const std::string& tag,
                  const std::vector<std::string>& env = {})
      : ServeProcess(VALVEDIAG_BIN, with_serve(std::move(args)), kRecTmp, tag, 60.0, env) {}
  static std::vector<std::string> with_serve(std::vector<std::string> args) {
    args.insert(args.begin(), "serve");
    return args;
  }
};

json get(httplib::Client& c, const std::string& path) {
  const auto r = c.Get(path);
  REQUIRE_MESSAGE(r, "GET " << path << ": no answer");
  INFO(r->body);
  REQUIRE(r->status == 200);
  return json::parse(r->body);
}

// Posts a job and waits (bounded) for it to finish.
json run_recording_job(httplib::Client& c, const json& job, std::size_t loop = 0) {
  const auto r =
      c.Post("/api/loops/" + std::to_string(loop) + "/jobs", job.dump(), "application/json");
  REQUIRE(r);
  REQUIRE_MESSAGE(r->status == 202, r->body);
  const std::string url = json::parse(r->body)["url"];
  const auto end = Clock::now() + std::chrono::seconds(300);
  for (;;) {
    const json st = get(c, url);
    if (st["state"] != "queued" && st["state"] != "running") return st;
    REQUIRE(Clock::now() < end);
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
}

// The recording every --db case serves: 3 s of both loops (made once).
std::string recording(valvediag::SimPlc& plc) {
  static const std::string db = [&] {
    const std::string path = fresh("serve_rec.sqlite");
    const auto r = run_cli(VALVEDIAG_BIN,
                           {"record", "--config", write_site("serve_rec.toml", plc.port()), "--db",
                            path, "--duration", "3s", "--quiet"},
                           kRecTmp, 60.0);
    INFO(r.out);
    REQUIRE((r.status == 0 || r.status == 4));  // 4: a tick missed on a loaded machine
    return path;
  }();
  return db;
}

// Every row of every table but model_history, as text: what serve --db must leave as it was.
std::string recorded_rows(const std::string& db) {
  std::string all;
  sqlite3* c = nullptr;
  REQUIRE(sqlite3_open_v2(db.c_str(), &c, SQLITE_OPEN_READONLY, nullptr) == SQLITE_OK);
  for (const char* table : {"runs", "loops", "samples", "gaps", "schema_versions"}) {
    sqlite3_stmt* s = nullptr;
    // The history's own version row comes with its table.
    const std::string sql =
        std::string("SELECT * FROM ") + table +
        (table == std::string("schema_versions") ? " WHERE component != 'model_history'" : "");
    if (sqlite3_prepare_v2(c, sql.c_str(), -1, &s, nullptr) != SQLITE_OK) continue;
    while (sqlite3_step(s) == SQLITE_ROW)
      for (int i = 0; i < sqlite3_column_count(s); ++i) {
        const unsigned char* t = sqlite3_column_text(s, i);
        all += (t ? reinterpret_cast<const char*>(t) : "NULL") + std::string(i ? "," : "|");
      }
    sqlite3_finalize(s);
  }
  sqlite3_close(c);
  return all;
}

}  // namespace

TEST_CASE("serve --db: the recorded loops, their models in the recording's model_history") {
  valvediag::SimPlc plc(valvediag::load_site_config(kSimSite), valvediag::SimPlcOptions{100.0, 0});
  plc.start();
  const std::string db = recording(plc);
  const std::string rows = recorded_rows(db);
  REQUIRE(rows.size() > 10000);
  const fs::path state = kRecTmp / ("serve_rec_state_" + std::to_string(::getpid()));
  fs::remove_all(state);
  const std::vector<std::string> env{"XDG_STATE_HOME=" + state.string()};
  {
    RecordingServer s({"--db", db, "--port", "0"}, "rec_db", env);
    auto c = s.client();
    const json loops = get(c, "/api/loops")["loops"];
    REQUIRE(loops.size() == 2);
    CHECK(loops[0]["name"] == "FIC101");
    CHECK(loops[1]["name"] == "LIC201");
    CHECK(loops[0]["live"] == false);
    // 3 s at 5 ms: about 600 samples, the longest clean stretch. A missed first tick leaves 599;
    // on a loaded machine (CI's tests side by side) ticks missed later split the record, and the
    // longest stretch is served: at least a few hundred samples.
    const std::string fic = "(SELECT id FROM loops WHERE name = 'FIC101')";
    const double holes =
        scalar(db,
               "SELECT max(tick) + 1 - count(*) FROM samples WHERE q_op = 0 AND q_pv = 0 "
               "AND loop_id = " +
                   fic) +
        scalar(db, "SELECT count(*) FROM gaps WHERE loop_id = " + fic);
    INFO("ticks missed or flagged: " << holes);
    CHECK(loops[0]["samples"].get<int>() >= (holes <= 1 ? 550 : 200));
    CHECK(loops[0]["samples"].get<int>() <= 600);
    CHECK(loops[0]["sample_period_s"].get<double>() == doctest::Approx(0.005));
    const std::string lic = "(SELECT id FROM loops WHERE name = 'LIC201')";
    const double lic_holes =
        scalar(db,
               "SELECT max(tick) + 1 - count(*) FROM samples WHERE q_op = 0 AND q_pv = 0 "
               "AND loop_id = " +
                   lic) +
        scalar(db, "SELECT count(*) FROM gaps WHERE loop_id = " + lic);
    CHECK(loops[1]["samples"].get<int>() >= (lic_holes <= 1 ? 270 : 100));
    const json series = get(c, "/api/loops/0/series?buckets=3");
    CHECK(series["samples"] == loops[0]["samples"]);
    CHECK(series["op"]["max"].size() == 3);
    const json fit = run_recording_job(c, {{"action", "fit"}, {"model", "linear"}});
    REQUIRE_MESSAGE(fit["state"] == "done", fit.dump());
    CHECK(fit["result"]["history"]["entries"] == 1);
    CHECK(fit["result"]["history"]["where"] == db + " (table model_history)");
    const json add =
        run_recording_job(c, {{"action", "add"}, {"effect", "stiction"}, {"validate", 0.4}});
    REQUIRE_MESSAGE(add["state"] == "done", add.dump());
    CHECK(add["result"]["history"]["entries"] == 2);
    CHECK(add["result"]["data"]["validate"] == 0.4);
    CHECK(get(c, "/api/status") == json{{"live", false}});
    CHECK(s.stop() == 0);
    // Both models under the key of the samples served; the printed ladder command lists them
    // (with --bridge-gaps 2 when the window's short gaps were filled: missed ticks under load).
    const std::string out = slurp(s.out);
    INFO(out);
    CHECK(scalar(db, "SELECT COUNT(*) FROM model_history WHERE run_id = 1 AND loop = 'FIC101'") ==
          2);
    CHECK(scalar(db, "SELECT COUNT(DISTINCT reading) FROM model_history") == 1);
    const auto at = out.find("valvediag ladder --db " + db + " --loop FIC101");
    REQUIRE(at != std::string::npos);
    {
      const std::string cmd = out.substr(at, out.find(')', at) - at);
      std::vector<std::string> args;
      std::istringstream words(cmd.substr(std::string("valvediag ").size()));
      for (std::string w; words >> w;) args.push_back(w);
      const auto lad = run_cli(VALVEDIAG_BIN, args, kRecTmp, 60.0, env);
      INFO(lad.out);
      CHECK(lad.status == 0);
      CHECK(lad.out.find("linear") != std::string::npos);
      CHECK(lad.out.find("stiction") != std::string::npos);
    }
  }
  // The recording is as it was, but for its table model_history; the state directory is empty.
  const bool unchanged = recorded_rows(db) == rows;  // (not printed: thousands of rows)
  CHECK(unchanged);
  CHECK(scalar(db, "SELECT COUNT(*) FROM model_history") == 2);
  CHECK(scalar(db, "SELECT COUNT(*) FROM model_history WHERE loop = 'FIC101'") == 2);
  CHECK((!fs::exists(state) || fs::is_empty(state)));
  // --no-history and --loops: one loop, and not a byte of the file changed.
  const std::string bytes = slurp(db);
  {
    RecordingServer s(
        {"--db", db, "--port", "0", "--loops", "LIC*", "--window", "1s", "--no-history"},
        "rec_db_nohist", env);
    auto c = s.client();
    const json loops = get(c, "/api/loops")["loops"];
    REQUIRE(loops.size() == 1);
    CHECK(loops[0]["name"] == "LIC201");
    // The latest second: 100 samples at 10 ms (the window's ends on ticks).
    CHECK(loops[0]["samples"].get<int>() >= 99);
    CHECK(loops[0]["samples"].get<int>() <= 101);
    const json fit = run_recording_job(c, {{"action", "fit"}, {"model", "linear"}});
    CHECK(fit["state"] == "failed");  // 100 samples: too few to fit, and said so
    CHECK(fit["error"].get<std::string>().find("200") != std::string::npos);
    CHECK(s.stop() == 0);
  }
  CHECK(slurp(db) == bytes);
  CHECK(plc.write_requests() == 0);
}

TEST_CASE("serve --db: a missing file, not a recording, no loop matching, an empty loop: exit 2") {
  valvediag::SimPlc plc(valvediag::load_site_config(kSimSite), valvediag::SimPlcOptions{100.0, 0});
  plc.start();
  const std::string db = recording(plc);
  const auto serve = [](const std::vector<std::string>& args) {
    std::vector<std::string> full{"serve", "--port", "0"};
    full.insert(full.end(), args.begin(), args.end());
    return run_cli(VALVEDIAG_BIN, full, kRecTmp, 60.0);
  };
  const std::string missing = (kRecTmp / "no-such.sqlite").string();
  auto r = serve({"--db", missing});
  CHECK(r.status == 2);
  CHECK(r.out.find(missing + ": no such database") != std::string::npos);
  CHECK(!fs::exists(missing));  // not created
  const fs::path junk = kRecTmp / "serve_junk.sqlite";
  std::ofstream(junk) << "t,op,pv\n0,1,2\n";
  r = serve({"--db", junk.string()});
  CHECK(r.status == 2);
  CHECK(r.out.find(junk.string() + ": ") != std::string::npos);
  CHECK(r.out.find("not a database") != std::string::npos);
  r = serve({"--db", db, "--loops", "FIC101,TIC*"});
  CHECK(r.status == 2);
  CHECK(r.out.find("no loop 'TIC*' in " + db + "; its loops: FIC101, LIC201") != std::string::npos);
  r = serve({"--db", db, "--window", "soon"});
  CHECK(r.status == 2);
  CHECK(r.out.find("--window 'soon'") != std::string::npos);
  r = serve({"loop.csv", "--window", "1h"});
  CHECK(r.status == 2);
  CHECK(r.out.find("--loops and --window go with --db") != std::string::npos);
  r = serve({"--config", write_site("serve_nodb.toml", plc.port())});
  CHECK(r.status == 2);
  CHECK(r.out.find("--config needs --db") != std::string::npos);
  // A site gives each loop's OP span: --op-range beside it is refused, as sweep --config does.
  const std::string site = write_site("serve_range.toml", plc.port());
  r = serve({"--config", site, "--db", fresh("serve_range.sqlite"), "--op-range", "0:50"});
  CHECK(r.status == 2);
  CHECK(r.out.find("op_range = [min, max] in " + site) != std::string::npos);
  CHECK(r.out.find("serving") == std::string::npos);
  // A loop whose every request failed (nothing listens on port 1): its recording has no good
  // sample; serve names it and says what to do.
  const std::string dead = fresh("serve_dead.sqlite");
  const auto rec = run_cli(VALVEDIAG_BIN,
                           {"record", "--config", write_site("serve_dead.toml", 1), "--db", dead,
                            "--duration", "0.5s", "--quiet"},
                           kRecTmp, 60.0);
  REQUIRE_MESSAGE(rec.status == 4, rec.out);
  r = serve({"--db", dead});
  CHECK(r.status == 2);
  CHECK(r.out.find("loop FIC101") != std::string::npos);
  CHECK(r.out.find("--loops") != std::string::npos);
  CHECK(r.out.find("serving") == std::string::npos);
}

TEST_CASE(
    "serve --config --db: live trends, the bus status, the latest seconds fitted, Ctrl-C "
    "keeps every sample, nothing written to the PLC") {
  valvediag::SimPlc plc(valvediag::load_site_config(kSimSite), valvediag::SimPlcOptions{100.0, 0});
  plc.start();
  const std::string site = write_site("serve_live.toml", plc.port());
  const std::string db = fresh("serve_live.sqlite");
  const fs::path state = kRecTmp / ("serve_live_state_" + std::to_string(::getpid()));
  fs::remove_all(state);
  const std::vector<std::string> env{"XDG_STATE_HOME=" + state.string()};
  RecordingServer s({"--config", site, "--db", db, "--port", "0"}, "live", env);
  auto c = s.client();
  const auto samples = [&](std::size_t loop) {
    return get(c, "/api/loops")["loops"][loop]["samples"].get<int>();
  };
  json loops = get(c, "/api/loops")["loops"];
  REQUIRE(loops.size() == 2);
  CHECK(loops[0]["name"] == "FIC101");
  CHECK(loops[0]["live"] == true);
  // The trends grow as the recorder stores: 400 samples (2 s) come within a bounded wait.
  REQUIRE(valvediag::test::wait_for([&] { return samples(0) >= 400; }, 30.0));
  const json a = get(c, "/api/loops/0/series?buckets=10");
  std::this_thread::sleep_for(std::chrono::milliseconds(1200));
  const json b = get(c, "/api/loops/0/series?buckets=10");
  CHECK(b["samples"].get<int>() > a["samples"].get<int>() + 100);
  CHECK(b["to"].get<double>() > a["to"].get<double>() + 0.5);
  // The bus status: the recorder's own counters.
  const json st = get(c, "/api/status");
  INFO(st.dump());
  CHECK(st["live"] == true);
  CHECK(st["recording"] == true);
  CHECK(st["run"] == 1);
  CHECK(st["db"] == db);
  REQUIRE(st["buses"].size() == 1);
  CHECK(st["buses"][0]["name"] == "plc");
  CHECK(st["buses"][0]["connected"] == true);
  CHECK(st["buses"][0]["requests"].get<int>() > 400);
  CHECK(st["buses"][0]["errors"] == 0);
  CHECK(st["buses"][0]["reconnects"] == 0);
  CHECK(st["lateness_p99_s"].get<double>() >= st["lateness_p50_s"].get<double>());
  CHECK(st["stored"].get<int>() > 400);
  REQUIRE(st["loops"].size() == 2);
  CHECK(st["loops"][0]["name"] == "FIC101");
  CHECK(st["loops"][0]["rows"].get<int>() > 400);
  // "Fit the last second": 201 samples of 5 ms, the latest when the job started.
  const int before = samples(0);
  const json fit = run_recording_job(c, {{"action", "fit"}, {"model", "linear"}, {"last_s", 1.0}});
  REQUIRE_MESSAGE(fit["state"] == "done", fit.dump());
  const json& data = fit["result"]["data"];
  CHECK(data["samples"] == 201);
  CHECK(data["to_s"].get<double>() - data["from_s"].get<double>() == doctest::Approx(1.0));
  CHECK(data["to_s"].get<double>() >= 0.005 * (before - 2));
  CHECK(fit["result"]["history"]["where"] == db + " (table model_history)");
  // Ctrl-C: the server and the recorder stop, every sample taken is stored, the run ends.
  CHECK(s.stop() == 0);
  const std::string out = slurp(s.out);
  INFO(out);
  const auto at = out.find(": ", out.find("(run 1)"));
  REQUIRE(at != std::string::npos);
  const int stored = std::stoi(out.substr(at + 2));
  CHECK(stored == scalar(db, "SELECT COUNT(*) FROM samples"));
  CHECK(stored > before);
  std::string status;
  scalar(db, "SELECT status FROM runs WHERE id = 1", &status);
  CHECK(status == "stopped");
  // The model is in the run's history of the loop: the key `fit --db DB --loop FIC101` uses.
  CHECK(scalar(db,
               "SELECT COUNT(*) FROM model_history WHERE run_id = 1 AND loop = 'FIC101' AND "
               "reading = '' AND model = 'linear'") == 1);
  CHECK(scalar(db, "SELECT COUNT(*) FROM model_history") == 1);
  // Reads only: the PLC received read requests and not one write.
  CHECK(plc.write_requests() == 0);
  const auto fc = plc.function_counts();
  CHECK(fc[3] > 400);
  for (std::size_t f = 0; f < fc.size(); ++f)
    if (f != 3 && f != 4) CHECK_MESSAGE(fc[f] == 0, "function code " << f);
}
