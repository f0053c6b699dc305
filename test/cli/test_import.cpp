// valvediag import and FILE.mat --loop in the analysis commands, as a user runs them: the
// stiction database benchmark, the Tennessee Eastman matrix and .mat files written here.
#include <doctest/doctest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "../common/run_cli.hpp"
#include "../common/sanitized.hpp"
#include "../common/sqlite_exec.hpp"
#include "../common/text.hpp"
#include "../io/mat_fixtures.hpp"

namespace fs = std::filesystem;
using valvediag::test::CliResult;

namespace {

const std::string kData = VALVEDIAG_DATA_DIR;
const std::string kBenchmark = kData + "/benchmark.mat";
const std::string kTe14 = kData + "/tennessee-eastman/m1d14.mat";

fs::path tmp_dir() {
  const fs::path p = fs::path(VALVEDIAG_TMP) / "import";
  fs::create_directories(p);
  return p;
}

std::string import_tmp(const std::string& name) {
  return (tmp_dir() / name).string();
}

CliResult run_import(const std::vector<std::string>& args) {
  return valvediag::test::run_cli(VALVEDIAG_BIN, args, tmp_dir(), 300.0);
}

using valvediag::test::has;

std::string read_file(const fs::path& p) {
  std::ifstream f(p, std::ios::binary);
  std::ostringstream s;
  s << f.rdbuf();
  return s.str();
}

// The line of `text` that holds `part`.
std::string line_with(const std::string& text, const std::string& part) {
  std::istringstream s(text);
  std::string line;
  while (std::getline(s, line))
    if (has(line, part)) return line;
  return "";
}

using valvediag::test::with;

const std::vector<std::string> kImportGrid{"--na-max", "1", "--nb-max",    "1", "--nk-max", "2",
                                           "--L-max",  "8", "--no-history"};

}  // namespace

TEST_CASE("import lists the loops of the stiction database benchmark") {
  const CliResult r = run_import({"import", kBenchmark});
  INFO(r.out);
  CHECK(r.status == 0);
  CHECK(has(r.out, "93 loop(s)"));
  CHECK(has(r.out,
            "groups: benchmark.buildings 8, benchmark.chemicals 63, benchmark.pulpPapers 13, "
            "benchmark.power 5, benchmark.mining 1, benchmark.metals 3"));
  const std::string l23 = line_with(r.out, "benchmark.chemicals.loop23 ");
  CHECK(has(l23, " 1500 "));
  CHECK(has(l23, " 10 "));
  CHECK(has(l23, "OP  (no PV)"));
  CHECK(has(l23, "oscillation 1"));  // the database's label, listed as it is
  CHECK(has(line_with(r.out, "benchmark.chemicals.loop16 "), "Type 1"));
  CHECK(has(r.out, "no loop has PV"));

  SUBCASE("a loop without PV: a clear message, exit status 2") {
    const CliResult f = run_import({"fit", kBenchmark, "--loop", "chemicals.loop23"});
    CHECK(f.status == 2);
    CHECK(has(f.out,
              "loop 'benchmark.chemicals.loop23': no PV field (fields present: "
              "oscillation, Ts, OP)"));
    const CliResult d = run_import(
        {"import", kBenchmark, "--loop", "chemicals.loop23", "--db", import_tmp("nopv.sqlite")});
    CHECK(d.status == 2);
    CHECK(has(d.out, "no PV field"));
  }
  SUBCASE("several loops and no --loop: the message lists them") {
    const CliResult f = run_import({"fit", kBenchmark});
    CHECK(f.status == 2);
    CHECK(has(f.out, "93 loops in the file; choose one with --loop PATH"));
    CHECK(has(f.out, "benchmark.buildings.loop1"));
  }
  SUBCASE("an OP-only loop imports as t, op") {
    const CliResult i = run_import(
        {"import", kBenchmark, "--loop", "chemicals.loop23", "--out", import_tmp("l23.csv")});
    CHECK(i.status == 0);
    CHECK(has(i.out, "1500 samples"));
    std::ifstream f(import_tmp("l23.csv"));
    std::string header;
    std::getline(f, header);
    CHECK(header == "t,op");
  }
}

TEST_CASE("import a loop of a .mat file to CSV, to a recording, or fit the .mat directly") {
  const std::string mat = import_tmp("runs.mat");
  valvediag::test::write_runs_file(mat, MAT_FT_MAT5, MAT_COMPRESSION_ZLIB);

  const CliResult list = run_import({"import", mat});
  INFO(list.out);
  CHECK(list.status == 0);
  CHECK(has(list.out, "2 loop(s)"));
  CHECK(has(line_with(list.out, "runs(2)"), "OP PV SP"));

  const CliResult to_csv =
      run_import({"import", mat, "--loop", "runs(2)", "--out", import_tmp("r2.csv")});
  CHECK(to_csv.status == 0);
  CHECK(has(to_csv.out,
            "wrote " + import_tmp("r2.csv") + ": 400 samples of loop runs(2) (Ts 0.5 s)"));

  const CliResult from_csv = run_import(with({"fit", import_tmp("r2.csv")}, kImportGrid));
  const CliResult direct = run_import(with({"fit", mat, "--loop", "runs(2)"}, kImportGrid));
  INFO(from_csv.out);
  INFO(direct.out);
  CHECK(from_csv.status == 0);
  CHECK(direct.status == 0);
  CHECK(has(direct.out, mat + ":runs(2) (400 samples, Ts 0.500 s"));
  const std::string fitness = line_with(from_csv.out, "fitness:");
  CHECK_FALSE(fitness.empty());
  CHECK(line_with(direct.out, "fitness:") == fitness);  // the same data, bit for bit

  SUBCASE("into a recording: fit --db --loop reads it") {
    const std::string db = import_tmp("imported.sqlite");
    fs::remove(db);
    const CliResult i = run_import({"import", mat, "--loop", "runs(2)", "--db", db});
    INFO(i.out);
    CHECK(i.status == 0);
    CHECK(has(i.out, "stored loop runs_2 in " + db));
    const CliResult f = run_import(with({"fit", "--db", db, "--loop", "runs_2"}, kImportGrid));
    INFO(f.out);
    CHECK(f.status == 0);
    CHECK(line_with(f.out, "fitness:") == fitness);
  }
  SUBCASE("every loop into a folder") {
    const std::string dir = import_tmp("all");
    fs::remove_all(dir);
    const CliResult i = run_import({"import", mat, "--out-dir", dir});
    CHECK(i.status == 0);
    CHECK(has(i.out, "2 loop(s) written"));
    CHECK(fs::exists(fs::path(dir) / "runs_1.csv"));
    CHECK(fs::exists(fs::path(dir) / "runs_2.csv"));
  }
  SUBCASE("wrong uses: exit status 2 with a message") {
    CHECK(run_import({"import", import_tmp("r2.csv")}).status == 2);
    const CliResult nowhere = run_import({"import", mat, "--loop", "runs(2)"});
    CHECK(nowhere.status == 2);
    CHECK(has(nowhere.out, "--out"));
    CHECK(run_import({"import", mat, "--loop", "runs(9)", "--out", import_tmp("x.csv")}).status ==
          2);
    const CliResult csv_loop = run_import({"fit", import_tmp("r2.csv"), "--loop", "runs(2)"});
    CHECK(csv_loop.status == 2);
    CHECK(has(csv_loop.out, "--loop goes with --db or a .mat file"));
    const CliResult csv_opt = run_import({"fit", mat, "--loop", "runs(2)", "--delimiter", "tab"});
    CHECK(csv_opt.status == 2);
    CHECK(has(csv_opt.out, "for CSV files, not .mat"));
    std::ofstream(import_tmp("garbage.mat")) << std::string(300, 'x');
    const CliResult garbage = run_import({"fit", import_tmp("garbage.mat")});
    CHECK(garbage.status == 2);
    CHECK(has(garbage.out, "not a MATLAB v5/v7/v7.3 MAT-file"));
  }
}

TEST_CASE("sweep over .mat files: every loop of each, chosen by pattern; OP-only loops" *
          valvediag::test::release_only()) {
  const std::string mat = import_tmp("sweep-runs.mat");
  valvediag::test::write_runs_file(mat, MAT_FT_MAT5, MAT_COMPRESSION_NONE, 1500);
  const std::string out = import_tmp("sweep-mat.json");
  fs::remove(out);
  const fs::path pages = import_tmp("sweep-mat-pages");
  fs::remove_all(pages);
  const CliResult r = run_import({"sweep", mat, kBenchmark, "--loops", "runs(*),benchmark.power.*",
                                  "--jobs", "2", "--json", out, "--reports", pages.string(),
                                  "--html", (pages / "index.html").string()});
  INFO(r.out);
  REQUIRE(r.status == 0);
  CHECK(has(r.out, "sweep: 7 loop(s)"));
  std::ifstream f(out);
  const auto j = nlohmann::json::parse(f);
  std::vector<std::string> names;
  for (const auto& l : j["loops"]) {
    const std::string name = l["loop"];
    names.push_back(name);
    CAPTURE(name);
    CHECK(l["verdict"] != "error");
    if (name.starts_with("runs(")) {
      // OP and PV: diagnosed like any loop (the valve sticks 2 %).
      CHECK(l["verdict"] != "not-enough-data");
      CHECK(l["health"]["signal"] == "sp-pv");
      CHECK(l["source"] == mat + ":" + name);
    } else {
      // OP only: no model, but OP's figures; the reason says what is missing.
      CHECK(l["verdict"] == "not-enough-data");
      CHECK(has(l["reason"].get<std::string>(), "no PV in the record"));
      CHECK(l["health"]["signal"] == "op");
      CHECK(l["health"]["op_travel_percent_per_hour"].get<double>() > 100);
      if (name == "benchmark.power.loop1") {  // labelled oscillating in the database
        CHECK(l["health"]["oscillating"] == true);
        CHECK(l["health"]["period_s"].get<double>() == doctest::Approx(113).epsilon(0.05));
      }
    }
  }
  // Every loop has its page: the model's, or (OP only) why there is none and OP's figures.
  const std::string index = read_file(pages / "index.html");
  for (const auto& name : names) {
    CAPTURE(name);
    CHECK(has(index, "href=\"" + name + ".html\""));
    const std::string page = read_file(pages / (name + ".html"));
    CHECK(has(page, "id=\"plot-trends\""));
    if (name.starts_with("runs(")) {
      CHECK(has(page, "id=\"plots-valve\""));
    } else {
      CHECK(has(page, "<tr><th>why</th><td>no PV in the record"));
      CHECK(has(page, "id=\"health\""));
      CHECK_FALSE(has(page, "id=\"plots-valve\""));
    }
  }
  CHECK(has(read_file(pages / "benchmark.power.loop1.html"), "yes, in OP: period 11"));
  fs::remove_all(pages);
  std::sort(names.begin(), names.end());
  CHECK(names == std::vector<std::string>{"benchmark.power.loop1", "benchmark.power.loop2",
                                          "benchmark.power.loop3", "benchmark.power.loop4",
                                          "benchmark.power.loop5", "runs(1)", "runs(2)"});

  // A name or pattern that selects nothing is a typo: said before any loop runs.
  const CliResult typo = run_import({"sweep", mat, "--loops", "runs(*),benchmark.metal.*"});
  CHECK(typo.status == 2);
  CHECK(has(typo.out,
            "--loops: no loop 'benchmark.metal.*' in the data files; its loops: "
            "runs(1), runs(2)"));
}

TEST_CASE("Tennessee Eastman m1d14: the cooling-water loop named by matrix columns" *
          valvediag::test::release_only()) {
  const std::vector<std::string> loop{"--op", "51", "--pv", "21", "--sample-period", "36"};
  const CliResult list = run_import({"import", kTe14});
  CHECK(list.status == 0);
  CHECK(has(line_with(list.out, "  m1d14 "), "matrix, 81 columns"));

  const CliResult i =
      run_import(with({"import", kTe14, "--loop", "m1d14", "--out", import_tmp("te.csv")}, loop));
  INFO(i.out);
  CHECK(i.status == 0);
  CHECK(has(i.out, "op column 51, pv column 21, Ts 36 s"));
  CHECK(has(i.out, "7201 samples of loop m1d14 (Ts 36 s)"));
  std::ifstream f(import_tmp("te.csv"));
  std::string line, last;
  std::size_t rows = 0;
  std::getline(f, line);
  CHECK(line == "t,op,pv");
  while (std::getline(f, line)) {
    ++rows;
    last = line;
  }
  CHECK(rows == 7201);
  CHECK(last.rfind("259200,", 0) == 0);  // 72 h

  const CliResult fit = run_import(with(with({"fit", kTe14}, loop), kImportGrid));
  INFO(fit.out);
  CHECK(fit.status == 0);
  CHECK(has(fit.out, "m1d14.mat:m1d14 (7201 samples, Ts 36.000 s"));
  const CliResult no_period = run_import({"fit", kTe14, "--op", "51", "--pv", "21"});
  CHECK(no_period.status == 2);
  CHECK(has(no_period.out, "--sample-period"));
}

TEST_CASE("a damaged .mat file is a clear error, never a crash of the command") {
  // Files that crash libmatio (v5, v7.3) in test/io/damaged-mat/; the hanging ones are tested
  // with a short time limit in test_io.
  const std::string dir = std::string(VALVEDIAG_TEST_DIR) + "/io/damaged-mat/";
  for (const char* name : {"v5-segfault.mat", "v73-segfault.mat"}) {
    const std::string mat = dir + name;
    INFO(name);
    for (const auto& args : std::vector<std::vector<std::string>>{
             {"import", mat},
             {"import", mat, "--loop", "runs(1)", "--out", import_tmp("damaged.csv")},
             {"diagnose", mat, "--loop", "runs(1)", "--no-history"}}) {
      const CliResult r = run_import(args);
      INFO(r.out);
      CHECK(r.status == 2);
      CHECK(has(r.out, mat + ": "));
      CHECK(has(r.out, "the file is damaged"));
    }
  }
}

TEST_CASE("a .mat loop and a recording obey --max-rows and the 1e12 bound as a CSV file does") {
  const std::string mat = import_tmp("capped.mat");
  valvediag::test::write_runs_file(mat);
  const CliResult m =
      run_import({"fit", mat, "--loop", "runs(2)", "--max-rows", "100", "--no-history"});
  INFO(m.out);
  CHECK(m.status == 2);
  CHECK(has(m.out,
            "loop 'runs(2)': field op has 400 samples, more than 100, the --max-rows limit "
            "that keeps memory bounded"));
  const std::string db = import_tmp("capped.sqlite");
  for (const char* suffix : {"", "-wal", "-shm"}) fs::remove(db + suffix);
  REQUIRE(run_import({"import", mat, "--loop", "runs(2)", "--db", db}).status == 0);
  const CliResult d = run_import({"fit", "--db", db, "--loop", "runs_2", "--max-rows", "100"});
  INFO(d.out);
  CHECK(d.status == 2);
  CHECK(has(d.out, db + ": run 1, loop runs_2: more than 100 rows in the range, the --max-rows "
                        "limit that keeps memory bounded"));
  CHECK(has(d.out, "or a shorter range (--from/--to)"));
  // Within the cap: read as before.
  CHECK(run_import(with({"fit", "--db", db, "--loop", "runs_2", "--max-rows", "400"}, kImportGrid))
            .status == 0);

  // A stored value no instrument gives (a corrupt row): refused naming run, loop and tick, by
  // the analysis commands and in a sweep.
  valvediag::test::exec_sql(db, "UPDATE samples SET op = 5e13 WHERE tick = 10");
  const std::string where =
      db + ": column 'op': run 1, loop runs_2, tick 10 (t = 5 s): 5e+13 is no measurement";
  const CliResult f = run_import(with({"fit", "--db", db, "--loop", "runs_2"}, kImportGrid));
  INFO(f.out);
  CHECK(f.status == 2);
  CHECK(has(f.out, where));
  const std::string site = import_tmp("capped.toml");
  std::ofstream(site) << "[[bus]]\nname = \"plc\"\nprotocol = \"modbus-tcp\"\n"
                         "controller = \"tcp://127.0.0.1:1\"\n"
                         "[[loop]]\nname = \"runs_2\"\nbus = \"plc\"\nsample_period = 0.5\n"
                         "op = { register = \"holding\", address = 0, type = \"FLOAT32\" }\n"
                         "pv = { register = \"holding\", address = 2, type = \"FLOAT32\" }\n";
  const CliResult s = run_import({"sweep", "--config", site, "--db", db, "--window", "1h"});
  INFO(s.out);
  CHECK(s.status == 0);
  CHECK(has(line_with(s.out, "runs_2 "), "error"));
  CHECK(has(s.out, where));
}

TEST_CASE("an OP spike below 1e12 in a CSV file: the verdict names the sample") {
  const std::string csv = import_tmp("spike.csv"), spiked = import_tmp("spiked.csv");
  REQUIRE(
      run_import({"simulate", "--scenario", "paper-ex1-linear", "--samples", "600", "--out", csv})
          .status == 0);
  std::ifstream in(csv);
  std::ofstream out(spiked);
  std::string line;
  for (int n = 1; std::getline(in, line); ++n) {
    if (n == 301)
      line = line.substr(0, line.find(',')) + ",9e11" +
             line.substr(line.find(',', line.find(',') + 1));
    out << line << "\n";
  }
  out.close();
  const CliResult r = run_import({"diagnose", spiked, "--no-history"});
  INFO(r.out);
  CHECK(r.status == 0);
  CHECK(has(line_with(r.out, "verdict:"),
            "not-enough-data: OP sample 300 (t = 149.5 s) is 9e+11, a million times its usual "
            "size"));
}
