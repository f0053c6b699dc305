// Issue 34, item 5: the model history lives in the user's state directory (or --history FILE),
// never next to the data, and a report is written only where --out says. Each command runs with
// HOME / XDG_STATE_HOME pointed at an empty folder and the folder trees are compared.
#include <doctest/doctest.h>
#include <sqlite3.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "../common/run_cli.hpp"
#include "../common/text.hpp"
#include "../io/mat_fixtures.hpp"

namespace fs = std::filesystem;

namespace {

const fs::path kRoot = fs::path(VALVEDIAG_TMP) / "history-test";
const std::vector<std::string> kHistoryGrid{"--na-max", "1", "--nb-max", "1",
                                            "--nk-max", "2", "--L-max",  "8"};

// valvediag in `cwd` with `env` ("NAME=VALUE", "-NAME" removes).
valvediag::test::CliResult vd(std::vector<std::string> args, const std::vector<std::string>& env,
                              const fs::path& cwd = kRoot / "cwd") {
  return valvediag::test::run_cli(VALVEDIAG_BIN, args, VALVEDIAG_TMP, 180.0, env, cwd.string());
}

// Every file and folder under `root`, relative to it.
std::set<std::string> tree(const fs::path& root) {
  std::set<std::string> out;
  for (const auto& e : fs::recursive_directory_iterator(root))
    out.insert(fs::relative(e.path(), root).string());
  return out;
}

// The PATH of the line "model history: PATH (N fits)", "" without one.
std::string history_of(const std::string& out) {
  const std::string key = "\nmodel history: ";
  const auto at = ("\n" + out).find(key);
  if (at == std::string::npos) return "";
  const auto from = at + key.size() - 1;
  return out.substr(from, out.find(" (", from) - from);
}

using valvediag::test::slurp;

// A fresh kRoot with data/loop.csv (600 samples of the paper's linear loop), an empty home/ and
// an empty cwd/ to run in.
fs::path fresh_root() {
  std::error_code ec;
  if (fs::exists(kRoot / "data"))  // left read-only by an earlier run
    fs::permissions(kRoot / "data", fs::perms::owner_all, ec);
  fs::remove_all(kRoot);
  for (const char* d : {"data", "home", "cwd", "out"}) fs::create_directories(kRoot / d);
  const auto s = vd({"simulate", "--scenario", "paper-ex1-linear", "--samples", "600", "--out",
                     (kRoot / "data" / "loop.csv").string()},
                    {});
  REQUIRE(s.status == 0);
  return kRoot / "data" / "loop.csv";
}

using valvediag::test::with;

}  // namespace

TEST_CASE("fit, diagnose, report and ladder write only where asked and in the state directory") {
  const std::string csv = fresh_root().string();
  // A read-only data folder (root ignores it: the trees below are the proof).
  fs::permissions(kRoot / "data", fs::perms::owner_read | fs::perms::owner_exec);
  const std::set<std::string> before = tree(kRoot);
  const std::vector<std::string> env{"HOME=" + (kRoot / "home").string(), "-XDG_STATE_HOME"};
  const std::string state = (kRoot / "home" / ".local" / "state" / "valvediag").string();

  const auto lin = vd({"fit", csv, "--model", "linear"}, env);
  INFO(lin.out);
  REQUIRE(lin.status == 0);
  const std::string hist = history_of(lin.out);
  CHECK(hist.starts_with(state + "/history/"));
  CHECK(lin.out.find("model history: " + hist + " (1 fit)") != std::string::npos);
  const auto pre = vd(with({"fit", csv}, kHistoryGrid), env);
  INFO(pre.out);
  CHECK(pre.status == 0);
  CHECK(pre.out.find("model history: " + hist + " (2 fits)") != std::string::npos);
  const auto diag = vd({"diagnose", csv, "--candidates", "stiction"}, env);
  INFO(diag.out);
  CHECK(diag.status == 0);
  CHECK(history_of(diag.out) == hist);
  // No --out: no page beside the data, a user error that says what to give.
  const auto nopage = vd({"report", csv, "--no-plots", "--no-diagnose"}, env);
  CHECK(nopage.status == 2);
  CHECK(nopage.out.find("--out FILE") != std::string::npos);
  const std::string page = (kRoot / "out" / "r.html").string();
  const auto rep = vd({"report", csv, "--no-plots", "--no-diagnose", "--out", page}, env);
  INFO(rep.out);
  CHECK(rep.status == 0);
  CHECK(rep.out.find("(the last model of this data's ladder)") != std::string::npos);
  const auto lad = vd({"ladder", csv}, env);
  CHECK(lad.status == 0);
  CHECK(lad.out.find("linear") != std::string::npos);

  std::set<std::string> added;
  for (const auto& p : tree(kRoot))
    if (!before.contains(p)) added.insert(p);
  const std::string h = fs::relative(hist, kRoot).string();
  CHECK(added == std::set<std::string>{"home/.local", "home/.local/state",
                                       "home/.local/state/valvediag",
                                       "home/.local/state/valvediag/history", h, "out/r.html"});
  CHECK(fs::is_empty(kRoot / "cwd"));
  // The state folder is the user's alone.
  CHECK((fs::status(fs::path(hist).parent_path()).permissions() & fs::perms::all) ==
        fs::perms::owner_all);
  fs::permissions(kRoot / "data", fs::perms::owner_all);
}

TEST_CASE("the history is keyed by the data's content and the options that read it") {
  const std::string csv = fresh_root().string();
  const std::vector<std::string> env{"XDG_STATE_HOME=" + (kRoot / "xdg").string(),
                                     "HOME=" + (kRoot / "home").string()};
  const auto a = vd({"fit", csv, "--model", "linear"}, env);
  REQUIRE(a.status == 0);
  const std::string ha = history_of(a.out);
  CHECK(ha.starts_with((kRoot / "xdg" / "valvediag" / "history").string()));
  // The same file read with another (equivalent) delimiter option: another history.
  const auto b = vd({"fit", csv, "--model", "linear", "--delimiter", ","}, env);
  REQUIRE(b.status == 0);
  CHECK(history_of(b.out) != ha);
  CHECK(b.out.find("(1 fit)") != std::string::npos);
  // A copy of the same data elsewhere: the same history.
  fs::create_directories(kRoot / "copy");
  fs::copy_file(csv, kRoot / "copy" / "other.csv");
  const auto c = vd({"fit", (kRoot / "copy" / "other.csv").string(), "--model", "linear"}, env);
  REQUIRE(c.status == 0);
  CHECK(history_of(c.out) == ha);
  CHECK(c.out.find("(2 fits)") != std::string::npos);
  // --history FILE chooses the file; --no-history writes none.
  const std::string mine = (kRoot / "out" / "mine.json").string();
  const auto d = vd({"fit", csv, "--model", "linear", "--history", mine}, env);
  CHECK(history_of(d.out) == mine);
  CHECK(fs::is_regular_file(mine));
  const auto lad = vd({"ladder", csv, "--history", mine}, env);
  CHECK(lad.status == 0);
  CHECK(lad.out.find("linear") != std::string::npos);
  const std::vector<std::string> env2{"HOME=" + (kRoot / "home").string(), "-XDG_STATE_HOME"};
  const auto e = vd({"fit", csv, "--model", "linear", "--no-history"}, env2);
  CHECK(e.status == 0);
  CHECK(history_of(e.out).empty());
  CHECK(fs::is_empty(kRoot / "home"));
}

TEST_CASE("a junk history or no usable state directory: the fit's summary, exit 0, a warning") {
  const std::string csv = fresh_root().string();
  const fs::path junk = kRoot / "out" / "junk.json";
  std::ofstream(junk) << "not a history {";
  for (const auto& args : {with({"fit", csv}, kHistoryGrid),
                           std::vector<std::string>{"fit", csv, "--model", "linear"}}) {
    const auto r = vd(with(args, {"--history", junk.string()}), {});
    INFO(r.out);
    CHECK(r.status == 0);
    CHECK(r.out.find("fitness:") != std::string::npos);
    CHECK(r.out.find("warning: " + junk.string() + ": not a valvediag model history") !=
          std::string::npos);
    CHECK(r.out.find("the fit above stands") != std::string::npos);
  }
  CHECK(slurp(junk) == "not a history {");  // left for the user to look at
  const std::string page = (kRoot / "out" / "j.html").string();
  const auto rep =
      vd({"report", csv, "--no-plots", "--no-diagnose", "--history", junk.string(), "--out", page},
         {});
  INFO(rep.out);
  CHECK(rep.status == 0);
  CHECK(rep.out.find("not a valvediag model history") != std::string::npos);
  CHECK(fs::is_regular_file(page));

  // A state directory that cannot be made (a file has its parent's name), and none at all.
  std::ofstream(kRoot / "out" / "a-file") << "x";
  const std::set<std::string> before = tree(kRoot);
  const std::vector<std::vector<std::string>> envs{
      {"XDG_STATE_HOME=" + (kRoot / "out" / "a-file").string()},
      {"-HOME", "-XDG_STATE_HOME"},
      {"-HOME", "XDG_STATE_HOME=relative/state"}};  // XDG: a relative path is ignored
  for (const auto& env : envs) {
    const auto r = vd({"fit", csv, "--model", "linear"}, env);
    INFO(env.front(), r.out);
    CHECK(r.status == 0);
    CHECK(r.out.find("fitness:") != std::string::npos);
    CHECK(r.out.find("warning: ") != std::string::npos);
    CHECK(history_of(r.out).empty());
  }
  CHECK(tree(kRoot) == before);
  const auto none = vd({"fit", csv, "--model", "linear"}, {"-HOME", "-XDG_STATE_HOME"});
  CHECK(none.out.find("neither XDG_STATE_HOME nor HOME") != std::string::npos);
  const auto cannot = vd({"fit", csv, "--model", "linear"},
                         {"XDG_STATE_HOME=" + (kRoot / "out" / "a-file").string()});
  CHECK(cannot.out.find("warning: cannot write the model history") != std::string::npos);
  const auto lad = vd({"ladder", csv}, {"-HOME", "-XDG_STATE_HOME"});
  CHECK(lad.status == 2);
  CHECK(lad.out.find("--history FILE") != std::string::npos);
}

namespace {

// The first column of the first row of `sql` in `db`, read-only; -1 when there is none.
long long sql_count(const fs::path& db, const std::string& sql) {
  sqlite3* h = nullptr;
  long long n = -1;
  if (sqlite3_open_v2(db.c_str(), &h, SQLITE_OPEN_READONLY, nullptr) == SQLITE_OK) {
    sqlite3_stmt* s = nullptr;
    if (sqlite3_prepare_v2(h, sql.c_str(), -1, &s, nullptr) == SQLITE_OK &&
        sqlite3_step(s) == SQLITE_ROW)
      n = sqlite3_column_int64(s, 0);
    sqlite3_finalize(s);
  }
  sqlite3_close(h);
  return n;
}

// A recording with loop runs_2 (400 samples of a sticky loop), as `import` stores it.
fs::path recording() {
  fresh_root();
  const std::string mat = (kRoot / "data" / "runs.mat").string();
  valvediag::test::write_runs_file(mat);
  const fs::path db = kRoot / "data" / "site.sqlite";
  const auto i = vd({"import", mat, "--loop", "runs(2)", "--db", db.string()}, {});
  REQUIRE(i.status == 0);
  return db;
}

}  // namespace

TEST_CASE("a recorded loop's history lives in its recording, keyed by run, loop and reading") {
  const fs::path db = recording();
  const std::string d = db.string();
  const std::vector<std::string> env{"HOME=" + (kRoot / "home").string(), "-XDG_STATE_HOME"};
  const std::string table = "model history: " + d + " (table model_history, ";
  const auto lin = vd({"fit", "--db", d, "--loop", "runs_2", "--model", "linear"}, env);
  INFO(lin.out);
  REQUIRE(lin.status == 0);
  CHECK(lin.out.find(table + "1 fit)") != std::string::npos);
  const auto diag =
      vd({"diagnose", "--db", d, "--loop", "runs_2", "--candidates", "stiction"}, env);
  INFO(diag.out);
  CHECK(diag.status == 0);
  const long long after_diag = sql_count(db, "SELECT COUNT(*) FROM model_history");
  CHECK(after_diag >= 2);
  CHECK(diag.out.find(table + std::to_string(after_diag) + " fits)") != std::string::npos);
  // fit --add starts from the recording's last model.
  const auto add = vd({"fit", "--db", d, "--loop", "runs_2", "--add", "deadband"}, env);
  INFO(add.out);
  CHECK(add.out.find("note: starting from the last model of this data") != std::string::npos);
  CHECK(add.out.find("(no history yet)") == std::string::npos);
  const auto lad = vd({"ladder", "--db", d, "--loop", "runs_2"}, env);
  CHECK(lad.status == 0);
  CHECK(lad.out.find("linear") != std::string::npos);
  CHECK(lad.out.find("deadband") != std::string::npos);
  // Another part of the run is another history; "10" and "10.0" are the same part.
  const auto part =
      vd({"fit", "--db", d, "--loop", "runs_2", "--from", "10", "--model", "linear"}, env);
  CHECK(part.out.find(table + "1 fit)") != std::string::npos);
  const auto same =
      vd({"fit", "--db", d, "--loop", "runs_2", "--from", "10.0", "--model", "linear"}, env);
  CHECK(same.out.find(table + "2 fits)") != std::string::npos);
  CHECK(sql_count(db,
                  "SELECT COUNT(*) FROM model_history WHERE reading = '--from 10' AND "
                  "loop = 'runs_2' AND run_id = 1") == 2);
  CHECK(sql_count(db, "SELECT version FROM schema_versions WHERE component = 'model_history'") ==
        1);
  // Nothing in the state directory; --history FILE and --no-history as for any data.
  CHECK(fs::is_empty(kRoot / "home"));
  const long long rows = sql_count(db, "SELECT COUNT(*) FROM model_history");
  const std::string mine = (kRoot / "out" / "mine.json").string();
  const auto f =
      vd({"fit", "--db", d, "--loop", "runs_2", "--model", "linear", "--history", mine}, env);
  CHECK(history_of(f.out) == mine);
  CHECK(
      vd({"fit", "--db", d, "--loop", "runs_2", "--model", "linear", "--no-history"}, env).status ==
      0);
  CHECK(sql_count(db, "SELECT COUNT(*) FROM model_history") == rows);
  CHECK(fs::is_empty(kRoot / "home"));
}

TEST_CASE("a busy or read-only recording: the history goes to the state directory, a warning") {
  const fs::path db = recording();
  const std::string d = db.string();
  const std::vector<std::string> env{"HOME=" + (kRoot / "home").string(), "-XDG_STATE_HOME"};
  const std::string state = (kRoot / "home" / ".local" / "state" / "valvediag").string();
  CHECK(vd({"fit", "--db", d, "--loop", "runs_2", "--model", "linear"}, env).status == 0);
  {
    // Another process holds the write lock (a database browser's open transaction).
    sqlite3* h = nullptr;
    REQUIRE(sqlite3_open(db.c_str(), &h) == SQLITE_OK);
    REQUIRE(sqlite3_exec(h, "BEGIN IMMEDIATE", nullptr, nullptr, nullptr) == SQLITE_OK);
    const auto t0 = std::chrono::steady_clock::now();
    const auto r = vd({"fit", "--db", d, "--loop", "runs_2", "--model", "stiction"}, env);
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    sqlite3_exec(h, "ROLLBACK", nullptr, nullptr, nullptr);
    sqlite3_close(h);
    INFO(r.out);
    CHECK(r.status == 0);
    CHECK(r.out.find("fitness:") != std::string::npos);
    CHECK(r.out.find("warning: " + d + ": database busy") != std::string::npos);
    CHECK(r.out.find("the model history goes to the state directory instead") != std::string::npos);
    CHECK(history_of(r.out).starts_with(state + "/history/"));
    CHECK(r.out.find("(1 fit)") != std::string::npos);
    CHECK(s < 60.0);  // the fit itself; the wait for the lock is a second
  }
  CHECK(sql_count(db, "SELECT COUNT(*) FROM model_history") == 1);
  // Nothing lost: the ladder holds both, in time order.
  const auto lad = vd({"ladder", "--db", d, "--loop", "runs_2"}, env);
  INFO(lad.out);
  CHECK(lad.status == 0);
  const auto lin = lad.out.find("linear"), sti = lad.out.find("stiction");
  CHECK(lin != std::string::npos);
  CHECK(sti != std::string::npos);
  CHECK(lin < sti);
  if (geteuid() != 0) {  // root writes a write-protected file
    fs::permissions(db, fs::perms::owner_read);
    const auto r = vd({"fit", "--db", d, "--loop", "runs_2", "--model", "deadband"}, env);
    fs::permissions(db, fs::perms::owner_read | fs::perms::owner_write);
    INFO(r.out);
    CHECK(r.status == 0);
    CHECK(r.out.find("warning: " + d + ": read-only") != std::string::npos);
    CHECK(r.out.find("(2 fits)") != std::string::npos);
  }
}
