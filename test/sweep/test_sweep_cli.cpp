// The sweep, sweep-merge and trend commands in their own processes: a site recorded from the
// simulated PLC (reads only), data files with a bad one among them, shards merged back, a loop
// stopped at its time limit, and user errors.
#include <doctest/doctest.h>

#include <algorithm>
#include <cctype>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <nlohmann/json.hpp>

#include "../common/plant_csv.hpp"
#include "../common/run_cli.hpp"
#include "../common/sanitized.hpp"
#include "valvediag/drivers/sim_plc.hpp"
#include "valvediag/drivers/site_config.hpp"

using namespace valvediag;
namespace fs = std::filesystem;

namespace {
const fs::path kTmp = VALVEDIAG_TMP;
const std::string kSimSite = std::string(VALVEDIAG_CONFIG_DIR) + "/sim-site.toml";

test::CliResult run(const std::vector<std::string>& args, double limit_s = 240.0) {
  return test::run_cli(VALVEDIAG_BIN, args, kTmp, limit_s);
}

std::string fresh(const std::string& name) {
  const fs::path p = kTmp / name;
  for (const char* suffix : {"", "-wal", "-shm"}) fs::remove(p.string() + suffix);
  return p.string();
}

nlohmann::json read_json(const std::string& path) {
  std::ifstream f(path);
  return nlohmann::json::parse(f);
}

// A file written by the command under test (a report page), whole; it must exist.
std::string read_text(const std::string& path) {
  std::ifstream f(path);
  REQUIRE(f);
  return std::string((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
}

const nlohmann::json* loop_in(const nlohmann::json& j, const std::string& name) {
  for (const auto& l : j["loops"])
    if (l["loop"] == name) return &l;
  return nullptr;
}
}  // namespace

#ifdef VALVEDIAG_SANITIZED
// A diagnosis runs about ten times slower under the sanitizers, and once FIC101 is found sticky
// the climb tries every effect on top of stiction (30 s on 3600 samples in Release): half the
// recording keeps both sweeps of the case below within their time limits. The verdict is only
// warned about there.
const char* const kRecordFor = "18s";
#else
const char* const kRecordFor = "36s";
#endif

TEST_CASE("sweep --record: a site from the simulated PLC, ranked, stored, trend; nothing written") {
  SimPlc plc(load_site_config(kSimSite), SimPlcOptions{50.0, 0});
  plc.start();
  // FIC101 (paper Example 1, sticky) at 50x: 10 ms ticks, about 3500 in 36 s (fewer samples
  // leave the diagnosis too little to tell stiction from a slow load); DEAD201: nobody serves it.
  const std::string site = (kTmp / "sweep-site.toml").string();
  {
    std::ofstream f(site);
    f << "[[bus]]\nname = \"plc\"\nprotocol = \"modbus-tcp\"\ncontroller = \"tcp://127.0.0.1:"
      << plc.port() << "\"\ntimeout = \"100ms\"\nretries = 0\nreconnect_max = \"500ms\"\n"
      << "[[bus]]\nname = \"gone\"\nprotocol = \"modbus-tcp\"\ncontroller = "
         "\"tcp://127.0.0.1:1\"\ntimeout = \"50ms\"\nretries = 0\nreconnect_max = \"500ms\"\n"
      << "[[loop]]\nname = \"FIC101\"\nbus = \"plc\"\nsample_period = 0.01\n"
      << "op = { register = \"holding\", address = 0, type = \"FLOAT32\" }\n"
      << "pv = { register = \"holding\", address = 2, type = \"FLOAT32\" }\n"
      << "sp = { register = \"holding\", address = 4, type = \"FLOAT32\" }\n"
      << "mv = { register = \"holding\", address = 6, type = \"FLOAT32\" }\n"
      << "[[loop]]\nname = \"DEAD201\"\nbus = \"gone\"\nsample_period = 0.1\n"
      << "op = { register = \"holding\", address = 0, type = \"FLOAT32\" }\n"
      << "pv = { register = \"holding\", address = 2, type = \"FLOAT32\" }\n";
  }
  const std::string db = fresh("sweep.sqlite");
  const std::string json = (kTmp / "sweep.json").string(), csv = (kTmp / "sweep.csv").string(),
                    html = (kTmp / "sweep.html").string();
  auto r = run({"sweep", "--config", site, "--db", db, "--record", kRecordFor, "--window", "1h",
                "--json", json, "--csv", csv, "--html", html});
  INFO(r.out);
  CHECK(r.status == 0);  // findings and a dead loop are results
  CHECK(plc.write_requests() == 0);
  const auto j = read_json(json);
  CHECK(j["format"] == "valvediag-sweep-1");
  REQUIRE(j["loops"].size() == 2);
  const nlohmann::json& fic = *loop_in(j, "FIC101");
  CHECK(fic["ladder"].size() >= 2);  // analysed: diagnose --auto climbed from linear
  CHECK(j["loops"][1]["loop"] == "DEAD201");
  CHECK(j["loops"][1]["verdict"] == "not-enough-data");
  // The recorded samples depend on when each poll meets the simulated PLC's step (machine
  // timing), and on one recording a slow load rivalled stiction in the closed-loop models (under
  // the sanitizers with a full 3600-sample window). test_sweep.cpp and the file sweep below
  // assert the models' verdict on fixed data; here the loop must be analysed.
  const std::string v = fic["verdict"];
  CHECK(
      (v == "stiction" || v == "deadband" || v == "other-nonlinearity" || v == "no-valve-problem"));
  const int samples = fic["health"]["samples"].get<int>();
  const std::string why =
      "recorded FIC101 (" + std::to_string(samples) + " clean samples) came out " + v;
  // The valve position is recorded too: the valve-travel test reads He's friction from OP -> MV,
  // whatever the closed-loop models made of the recording.
  INFO(why);
  INFO(fic["valve_travel"]["summary"].get<std::string>());
  CHECK(fic["valve_travel"]["decided"] == true);
  CHECK(v == "stiction");
  CHECK(fic["stiction_percent"].get<double>() == doctest::Approx(8.4).epsilon(0.2));
  CHECK(j["loops"][0]["loop"] == "FIC101");  // the sticky valve ranks first
  std::ifstream c(csv);
  std::string header;
  std::getline(c, header);
  CHECK(header.rfind("rank,loop,verdict,severity,stiction_percent", 0) == 0);
  CHECK(header.find(",valve_travel") != std::string::npos);
  CHECK(fs::file_size(html) > 500);

  // A second sweep over the same recording (no --record), with the split check: the trend shows
  // both, the second with its agreement.
  // (Under the sanitizers without it: two more climbs; sweep_split runs the check sanitized.)
#ifdef VALVEDIAG_SANITIZED
  constexpr bool split = false;
#else
  constexpr bool split = true;
#endif
  std::vector<std::string> again{"sweep",   "--config", site,       "--db", db,
                                 "--loops", "FIC101",   "--window", "1h",   "--quiet"};
  if (split) again.push_back("--split-check");
  r = run(again);
  CHECK(r.status == 0);
  r = run({"trend", "--db", db, "--loop", "FIC101"});
  CHECK(r.status == 0);
  CHECK(r.out.find("FIC101:") == 0);
  if (split) {
    CHECK(r.out.find(" splits ") != std::string::npos);
    CHECK(r.out.find("/3 ") != std::string::npos);
  }
  // Two sweeps listed, each with FIC101's verdict.
  std::size_t rows = 0;
  for (std::size_t p = r.out.find(" " + v + " "); p != std::string::npos;
       p = r.out.find(" " + v + " ", p + 1))
    ++rows;
  CHECK(rows >= 2);
  CHECK(run({"sweep", "--config", site, "--db", db, "--loops", "NOPE"}).status == 2);
}

TEST_CASE("sweep over files: a bad file is reported and the sweep goes on; shards merge back") {
  const std::string sticky = (kTmp / "sticky.csv").string(), clean = (kTmp / "clean.csv").string(),
                    bad = (kTmp / "bad.csv").string(), tiny = (kTmp / "tiny.csv").string();
  if (!test::kSanitizedBuild) {  // sanitized, no climb runs here (see below)
    REQUIRE(run({"simulate", "--scenario", "paper-ex1", "--seed", "2", "--samples", "3000", "--out",
                 sticky})
                .status == 0);
    REQUIRE(run({"simulate", "--scenario", "linear-clean", "--seed", "2", "--samples", "3000",
                 "--out", clean})
                .status == 0);
  }
  REQUIRE(run({"simulate", "--scenario", "linear-clean", "--seed", "3", "--samples", "120", "--out",
               tiny})
              .status == 0);
  {
    std::ofstream f(bad);
    f << "t,op,pv\n0,1,2\n1,x,3\n";
  }
  const std::string all = (kTmp / "files.json").string();
  // Each sweep runs two 3000-sample diagnoses side by side: minutes under the sanitizers on a
  // loaded machine, so each run gets the time of the test's own limit.
  constexpr double kLimit = 600.0;
  // Sanitized, the files no climb is run on: the sweep's reading, isolation and output paths (a
  // climb runs in sweep_site there; the verdicts and sweep-merge are Release's).
  const std::vector<std::string> files = test::kSanitizedBuild
                                             ? std::vector<std::string>{bad, tiny}
                                             : std::vector<std::string>{sticky, clean, bad, tiny};
  std::vector<std::string> args{"sweep", "--jobs", "2", "--json", all};
  args.insert(args.end(), files.begin(), files.end());
  auto r = run(args, kLimit);
  INFO(r.out);
  CHECK(r.status == 0);
  const auto j = read_json(all);
  REQUIRE(j["loops"].size() == files.size());
  CHECK((*loop_in(j, "bad"))["verdict"] == "error");
  CHECK((*loop_in(j, "bad"))["error"].get<std::string>().find("bad.csv:3") != std::string::npos);
  CHECK((*loop_in(j, "tiny"))["verdict"] == "not-enough-data");
  if (test::kSanitizedBuild) return;
  CHECK((*loop_in(j, "sticky"))["verdict"] == "stiction");
  CHECK((*loop_in(j, "clean"))["verdict"] == "no-valve-problem");

  // Two shards cover the list once; sweep-merge gives the same verdicts.
  const std::string p0 = (kTmp / "part-0.json").string(), p1 = (kTmp / "part-1.json").string();
  CHECK(run({"sweep", sticky, clean, bad, tiny, "--shard", "0/2", "--json", p0, "--quiet"}, kLimit)
            .status == 0);
  CHECK(run({"sweep", sticky, clean, bad, tiny, "--shard", "1/2", "--json", p1, "--quiet"}, kLimit)
            .status == 0);
  CHECK(read_json(p0)["loops"].size() + read_json(p1)["loops"].size() == 4);
  const std::string merged = (kTmp / "merged.json").string();
  r = run({"sweep-merge", p0, p1, "--json", merged});
  CHECK(r.status == 0);
  const auto m = read_json(merged);
  REQUIRE(m["loops"].size() == 4);
  for (const auto& l : j["loops"]) CHECK((*loop_in(m, l["loop"]))["verdict"] == l["verdict"]);
  CHECK(m["loops"][0]["loop"] == "sticky");
  CHECK(m["validate"] == 0.3);
  r = run({"sweep-merge", p0, p0});
  CHECK(r.status == 2);
  CHECK(r.out.find("also in an earlier file") != std::string::npos);
  // Parts scored on different held-out shares are not one sweep.
  {
    auto other = read_json(p1);
    CHECK(other["validate"] == 0.3);
    other["validate"] = 0.4;
    std::ofstream((kTmp / "part-1b.json").string()) << other.dump();
  }
  r = run({"sweep-merge", p0, (kTmp / "part-1b.json").string()});
  CHECK(r.status == 2);
  CHECK(r.out.find("held out 0.4 of each record (--validate)") != std::string::npos);
  CHECK(run({"sweep-merge", bad}).status == 2);
}

// Issue 5: the reactor cooling-water loop of the Tennessee Eastman benchmark, normal operation and
// the valve-sticking fault IDV(14), by matrix columns (OP = XMV(10), PV = XMEAS(21)).
TEST_CASE("sweep over the Tennessee Eastman runs: the sticking fault is stiction, normal is not" *
          valvediag::test::release_only()) {
  const std::string te = std::string(VALVEDIAG_DATA_DIR) + "/tennessee-eastman/";
  const std::string out = (kTmp / "te.json").string();
  const std::vector<std::string> files{te + "m1d00.mat", te + "m1d14.mat"};
  std::vector<std::string> args{"sweep"};
  args.insert(args.end(), files.begin(), files.end());
  for (const char* a : {"--op", "51", "--pv", "21", "--sample-period", "36", "--json"})
    args.emplace_back(a);
  args.push_back(out);
  const test::CliResult r = run(args, 600.0);
  INFO(r.out);
  REQUIRE(r.status == 0);
  const nlohmann::json j = read_json(out);
  const nlohmann::json* faulty = loop_in(j, "m1d14");
  REQUIRE(faulty != nullptr);
  CHECK((*faulty)["verdict"] == "stiction");
  CHECK((*faulty)["limit_cycle"]["stick_slip"] == true);
  // The apparent band (% of travel): TE's valve jumps once OP is 2 % away from it.
  CHECK((*faulty)["stiction_percent"].get<double>() > 1.5);
  CHECK((*faulty)["stiction_percent"].get<double>() < 4.0);
  CHECK((*faulty)["health"]["oscillating"] == true);
  const nlohmann::json* normal = loop_in(j, "m1d00");
  REQUIRE(normal != nullptr);
  CHECK((*normal)["verdict"] == "no-valve-problem");
  CHECK((*normal)["limit_cycle"]["stick_slip"] == false);
}

// Issue 5: the real plant loops labelled by their provider (shared/data/plant-loops), swept as
// historian exports; the confusion table of verdict against label as the README shows it. The
// file names' `Stick1=` figure is the provider's and is never read.
TEST_CASE("sweep over the plant loops: verdict against the provider's labels" *
          valvediag::test::accuracy()) {
  const fs::path root = fs::path(VALVEDIAG_DATA_DIR) / "plant-loops";
  std::vector<std::string> args{"sweep"};
  std::size_t n = 0;
  for (const char* label : {"stiction", "no-stiction"}) {
    std::vector<std::string> files;
    for (const auto& e : fs::directory_iterator(root / label)) files.push_back(e.path().string());
    std::sort(files.begin(), files.end());
    for (std::size_t i = 0; i < files.size(); ++i, ++n) args.push_back(files[i]);
  }
  const std::string out = (kTmp / "plant.json").string();
  args = test::with_plant_layout(args);
  for (const std::string a : {"--jobs", "2", "--json"}) args.push_back(a);
  args.push_back(out);
  const test::CliResult r = run(args, 1200.0);
  INFO(r.out);
  REQUIRE(r.status == 0);
  const nlohmann::json j = read_json(out);
  REQUIRE(j["loops"].size() == n);
  const char* verdicts[] = {"stiction",         "deadband",        "other-nonlinearity",
                            "no-valve-problem", "not-enough-data", "error"};
  std::map<std::string, std::map<std::string, int>> table;
  for (const auto& l : j["loops"]) {
    const std::string src = l["source"];
    const std::string label =
        src.find("/no-stiction/") != std::string::npos ? "no-stiction" : "stiction";
    CHECK(!l["verdict"].get<std::string>().empty());
    table[label][l["verdict"].get<std::string>()]++;
  }
  std::printf("\n| label \\ verdict |");
  for (const char* v : verdicts) std::printf(" %s |", v);
  std::printf("\n|---|---|---|---|---|---|---|\n");
  for (const char* label : {"stiction", "no-stiction"}) {
    int total = 0;
    for (const char* v : verdicts) total += table[label][v];
    std::printf("| %s (%d) |", label, total);
    for (const char* v : verdicts) std::printf(" %d |", table[label][v]);
    std::printf("\n");
  }
  const double found = table["stiction"]["stiction"] / 18.0;
  const double clean = 1.0 - table["no-stiction"]["stiction"] / 23.0;
  std::printf("balanced accuracy %.1f %% (sticky found %.1f %%, clean kept %.1f %%)\n",
              50 * (found + clean), 100 * found, 100 * clean);
  // Beside it, over the records that can be judged (neither not-enough-data nor refused): the
  // goal counts the others as misses, so this is not the figure it is measured by.
  auto judged = [&](const char* label) {
    return table[label]["stiction"] + table[label]["deadband"] +
           table[label]["other-nonlinearity"] + table[label]["no-valve-problem"];
  };
  const double found_j = table["stiction"]["stiction"] / static_cast<double>(judged("stiction"));
  const double clean_j =
      1.0 - table["no-stiction"]["stiction"] / static_cast<double>(judged("no-stiction"));
  std::printf("judged records only (%d of 41): balanced accuracy %.1f %% (sticky found %.1f %%)\n",
              judged("stiction") + judged("no-stiction"), 50 * (found_j + clean_j), 100 * found_j);
  // As measured (README); the issue aims at 85 % with at most 10 % false sticky.
  CHECK(table["stiction"]["stiction"] >= 14);
  CHECK(table["no-stiction"]["stiction"] == 0);
  // The export with duplicate time stamps is refused, naming its line; the sweep goes on.
  CHECK(table["stiction"]["error"] == 1);
}

// A level loop (LIC30501, 12 Dec) on which least squares gives `linear` no stable part: every A
// of the range lies past the unit circle. The output-error fit from the reflected poles beats the
// record's mean, so fit reports it and says how it was found; but it is a level, and the sweep's
// climb goes on from `integrator`, as an engineer would, when that fits better on both parts. Its
// page shows that model and the whole-record test against it. Its OP rests for 48 minutes first:
// the whole record is what this case is about (--keep-lead-in).
TEST_CASE("sweep --reports: a level whose `linear` is stable only by force climbs from integrator" *
          valvediag::test::release_only()) {
  const fs::path file = fs::path(VALVEDIAG_DATA_DIR) / "plant-loops" / "stiction" /
                        "stic_2411LIC30501_1212_0008_Stick1=0.95907.txt";
  const test::CliResult fit =
      run(test::with_plant_layout({"fit", file.string(), "--model", "linear", "--no-history"}));
  INFO(fit.out);
  CHECK(fit.status == 0);
  CHECK(fit.out.find("least squares gave no stable A, so the output-error fit started from its "
                     "poles reflected inside the unit circle") != std::string::npos);
  CHECK(fit.out.find("residual RMS") != std::string::npos);
  const test::CliResult diag =
      run(test::with_plant_layout({"diagnose", file.string(), "--no-history", "--keep-lead-in"}));
  INFO(diag.out);
  CHECK(diag.status == 0);
  CHECK(diag.out.find("residual:  RMS") != std::string::npos);

  const fs::path pages = kTmp / "pages-nostable";
  fs::remove_all(pages);
  const std::string out = (kTmp / "nostable.json").string();
  const test::CliResult r = run(test::with_plant_layout(
      {"sweep", file.string(), "--json", out, "--reports", pages.string(), "--keep-lead-in"}));
  INFO(r.out);
  REQUIRE(r.status == 0);
  const nlohmann::json l = read_json(out)["loops"][0];
  CHECK(l["error"] == "");
  REQUIRE(l["ladder"].size() >= 2);
  CHECK(l["ladder"][0]["fitness_percent"].get<double>() > 0.0);  // linear, stable by force
  CHECK(l["ladder"][1]["model"] == "integrator");
  CHECK(l["ladder"][1]["fitness_percent"].get<double>() >
        l["ladder"][0]["fitness_percent"].get<double>());
  CHECK(l["ladder"][1]["fitness_percent"].get<double>() > 0.0);
  CHECK(l["first_missing"] == "integrator");
  // The label says sticky. From `integrator`, judged k steps ahead, the deadband that ranks
  // first gains too little (+1.8 points on the estimation part); the climb adds the supported
  // friction ranked below it, He's stiction, and the level's model rises to about 73 %.
  const std::string last_model = l["ladder"].back()["model"];
  CHECK(last_model == "stiction+integrator");
  CHECK(l["verdict"] == "stiction");
  CHECK(l["stiction_percent"].get<double>() > 0.5);
  CHECK(l["stiction_percent"].get<double>() < 5.0);
  const std::string reason = l["reason"];
  CHECK(reason.find("`linear` is stable on this record only by force (least squares put its "
                    "poles past the unit circle) and `integrator` fits better, so the climb went "
                    "on from `integrator`") != std::string::npos);
  CHECK(reason.find("white-noise level") != std::string::npos);  // the last model's residual
  const std::string page = read_text(l["report"].get<std::string>());
  CHECK(page.find("<tr><th>model</th><td><code>" + last_model) != std::string::npos);
  // The level's rate gain is small (4e-4 PV/s per OP unit): significant digits, not "0.000".
  CHECK(page.find("integrator: rate_gain 0.000 ") == std::string::npos);
  const std::size_t rate = page.find("integrator: rate_gain 0.000");
  REQUIRE(rate != std::string::npos);
  CHECK(std::isdigit(static_cast<unsigned char>(page[rate + 27])));
  CHECK(page[rate + 27] != '0');
  fs::remove_all(pages);
}

// FIC20102 of 26 Dec 2024 (labelled sticky) rests for 95 minutes; then the set point steps down
// twice, OP winds 2 % while PV stays put, and PV drops at once: a stuck valve that slips. On the
// whole record the noise of the rest outweighs it; from a little before OP moves, the climb finds
// He's stiction with a band of about the 2 % OP wound.
TEST_CASE("sweep --reports: a record at rest until its last half hour is judged after its rest" *
          valvediag::test::release_only()) {
  const fs::path file = fs::path(VALVEDIAG_DATA_DIR) / "plant-loops" / "stiction" /
                        "stic_2411FIC20102_20241226_0953_Stick1=0.681163.txt";
  const std::string dj = (kTmp / "rest.json").string();
  const std::vector<std::string> dargs{"diagnose",      file.string(), "--auto", "--no-history",
                                       "--split-check", "--json",      dj};
  const test::CliResult diag = run(test::with_plant_layout(dargs), 600.0);
  INFO(diag.out);
  REQUIRE(diag.status == 0);
  CHECK(diag.out.find("note: the analysis starts at t = 5290 s (sample 530 of 751): before t = "
                      "5730 s OP holds within a quarter of its span") != std::string::npos);
  CHECK(diag.out.find("verdict:   stiction") != std::string::npos);
  const nlohmann::json d = read_json(dj);
  // The slip explains the part after the rest whichever share of it is held out.
  CHECK(diag.out.find("splits:    stiction with 0.25 held out; stiction with 0.35 held out; 3 "
                      "of 3 shares give stiction") != std::string::npos);
  REQUIRE(d["split_check"].size() == 2);
  CHECK(d["split_check"][1]["validate"].get<double>() == doctest::Approx(0.35));
  CHECK(d["split_check"][1]["verdict"] == "stiction");
  CHECK(d["analysed_from_s"].get<double>() == 5290.0);
  CHECK(d["unusable_reason"] == "");  // a sweep judges it too
  CHECK(d["stiction_percent"].get<double>() > 1.0);
  CHECK(d["stiction_percent"].get<double>() < 3.0);
  // The whole record.
  {
    const test::CliResult whole = run(test::with_plant_layout({"diagnose", file.string(), "--auto",
                                                               "--no-history", "--keep-lead-in"}),
                                      600.0);
    INFO(whole.out);
    CHECK(whole.out.find("the analysis starts") == std::string::npos);
    CHECK(whole.out.find("verdict:   no-valve-problem") != std::string::npos);
  }

  // `report` analyses the same part as the diagnose command its page quotes, in both modes.
  for (const bool keep : {false, true}) {
    CAPTURE(keep);
    const std::string page = (kTmp / "rest-report.html").string();
    std::vector<std::string> args{"report",       file.string(), "--model", "linear",
                                  "--no-history", "--no-plots",  "--out",   page};
    if (keep) args.push_back("--keep-lead-in");
    const test::CliResult rep = run(test::with_plant_layout(args), 600.0);
    INFO(rep.out);
    REQUIRE(rep.status == 0);
    CHECK((rep.out.find("note: the analysis starts at t = 5290 s") != std::string::npos) == !keep);
    CHECK(rep.out.find(keep ? "verdict:   no-valve-problem" : "verdict:   stiction") !=
          std::string::npos);
    const std::string html = read_text(page);
    CHECK((html.find("the analysis starts at t = 5290 s") != std::string::npos) == !keep);
    // The diagnose command it quotes: of `linear`, or (with the whole record, where the
    // verdict's climb ends at `linear`) that climb, --auto, shown rather than run again.
    CHECK((html.find(keep ? "--auto --keep-lead-in</code>" : "--model linear</code>") !=
           std::string::npos));
  }

  const fs::path pages = kTmp / "pages-rest";
  fs::remove_all(pages);
  const std::string out = (kTmp / "rest-sweep.json").string();
  const test::CliResult r = run(
      test::with_plant_layout({"sweep", file.string(), "--json", out, "--reports", pages.string()}),
      600.0);
  INFO(r.out);
  REQUIRE(r.status == 0);
  const nlohmann::json l = read_json(out)["loops"][0];
  CHECK(l["verdict"] == "stiction");
  CHECK(l["analysed_from_s"].get<double>() == 5290.0);
  CHECK(l["health"]["samples"] == 751);  // the loop's figures cover the whole window
  CHECK(l["reason"].get<std::string>().find("The analysis starts at t = 5290 s") == 0);
  const std::string page = read_text(l["report"].get<std::string>());
  CHECK(page.find("the analysis starts at t = 5290 s") != std::string::npos);
  fs::remove_all(pages);
}

// AIC90201 of 2 Oct (labelled sticky): OP stays within 0.08 % of its range, so a sweep does not
// fit it (not-enough-data). diagnose --auto --json, the one-loop check the issue asks for, and
// report give the same verdict and reason, while they still show their fits.
TEST_CASE("diagnose and report: a record a sweep refuses is not-enough-data there too") {
  const fs::path file = fs::path(VALVEDIAG_DATA_DIR) / "plant-loops" / "stiction" /
                        "stic_2411AIC90201_1002_0004_Stick1=0.59209.txt";
  const std::string sj = (kTmp / "idle-sweep.json").string();
  const test::CliResult sw = run(test::with_plant_layout({"sweep", file.string(), "--json", sj}));
  INFO(sw.out);
  REQUIRE(sw.status == 0);
  const nlohmann::json l = read_json(sj)["loops"][0];
  REQUIRE(l["verdict"] == "not-enough-data");
  const std::string reason = l["reason"];
  CHECK(reason.find("OP does not move beyond its noise") == 0);

  const std::string dj = (kTmp / "idle-diagnose.json").string();
  const test::CliResult dg = run(
      test::with_plant_layout({"diagnose", file.string(), "--auto", "--no-history", "--json", dj}),
      600.0);
  INFO(dg.out);
  REQUIRE(dg.status == 0);
  CHECK(dg.out.find("note: a sweep would not judge this record: " + reason) != std::string::npos);
  CHECK(dg.out.find("verdict:   not-enough-data: " + reason) != std::string::npos);
  CHECK(dg.out.find("ladder") != std::string::npos);  // the fits are still shown
  CHECK(dg.out.find("stiction:  ") == std::string::npos);
  const nlohmann::json d = read_json(dj);
  CHECK(d["verdict"] == "not-enough-data");
  CHECK(d["unusable_reason"] == reason);
  CHECK(d["stiction_percent"].is_null());

  const std::string page = (kTmp / "idle-report.html").string();
  const test::CliResult rep =
      run(test::with_plant_layout({"report", file.string(), "--model", "linear", "--no-history",
                                   "--no-plots", "--out", page}),
          600.0);
  INFO(rep.out);
  REQUIRE(rep.status == 0);
  CHECK(rep.out.find("verdict:   not-enough-data: " + reason) != std::string::npos);
  const std::string html = read_text(page);
  CHECK(html.find("<span class=\"verdict\">not-enough-data</span>") != std::string::npos);
  CHECK(html.find("<span class=\"verdict\">no-valve-problem</span>") == std::string::npos);
}

TEST_CASE("sweep: a loop over its time limit is stopped and reported; user errors exit 2") {
  const std::string longf = (kTmp / "long.csv").string();
  REQUIRE(
      run({"simulate", "--scenario", "paper-ex1", "--samples", "6000", "--out", longf}).status ==
      0);
  const auto r =
      run({"sweep", longf, "--loop-timeout", "0.3s", "--json", (kTmp / "t.json").string()}, 60);
  INFO(r.out);
  CHECK(r.status == 0);
  CHECK(r.out.find("stopped at the time limit of 0.3 s (--loop-timeout)") != std::string::npos);
  CHECK(read_json((kTmp / "t.json").string())["loops"][0]["verdict"] == "error");

  CHECK(run({"sweep"}).status == 2);
  CHECK(run({"sweep", longf, "--config", kSimSite}).status == 2);
  CHECK(run({"sweep", longf, "--shard", "2/2"}).status == 2);
  CHECK(run({"sweep", "--config", kSimSite, "--db", (kTmp / "x.sqlite").string(), "--op-range",
             "0:200"})
            .status == 2);  // a site gives each loop's range
  CHECK(run({"sweep", longf, "--op-range", "100:0"}).status == 2);
  CHECK(run({"sweep", longf, "--window", "soon"}).status == 2);
  CHECK(run({"sweep", longf, "--validate", "0.95"}).status == 2);
  const test::CliResult split = run({"sweep", longf, "--split-check", "--validate", "0.08"});
  CHECK(split.status == 2);
  CHECK(split.out.find("--validate must lie in (0.1, 0.85)") != std::string::npos);
  CHECK(run({"diagnose", longf, "--split-check", "--validate", "0.88"}).status == 2);
  CHECK(run({"trend", "--db", (kTmp / "none.sqlite").string()}).status == 2);
  const test::CliResult not_db = run({"trend", "--db", longf});  // a CSV file, not a database
  CHECK(not_db.status == 2);
  CHECK(not_db.out.find("(is this a valvediag site database?)") != std::string::npos);
}
