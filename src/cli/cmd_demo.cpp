// The main job end to end through the bus: a simulated PLC serves the paper's Example 1 loop
// (sticky valve) over Modbus TCP on a free loopback port, the recorder records it through the
// real Modbus driver at accelerated speed, the recording is exported and fitted, the loop is
// diagnosed (which effect is missing from `linear`) and written up as an HTML report.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <thread>

#include "commands.hpp"
#include "fit_runner.hpp"
#include "valvediag/diagnose/diagnosis.hpp"
#include "valvediag/drivers/bus_factory.hpp"
#include "valvediag/drivers/sim_plc.hpp"
#include "valvediag/io/atomic_file.hpp"
#include "valvediag/io/csv_writer.hpp"
#include "valvediag/recorder/recorder.hpp"
#include "valvediag/report/fit_report.hpp"
#include "valvediag/report/html_report.hpp"
#include "valvediag/report/model_history.hpp"
#include "valvediag/sim/scenarios.hpp"
#include "valvediag/sweep/loop_verdict.hpp"
#include "verdict_output.hpp"
#include "workbench_server.hpp"

namespace valvediag::cli {

namespace {

// The embedded site: one loop, the paper's Example 1, as FLOAT32 holding registers 0..7.
// No port: it is the simulated PLC's free one, set once the PLC listens.
SiteConfig demo_site(std::uint64_t seed, double period_s) {
  const std::string toml =
      "[[bus]]\nname = \"demo-plc\"\nprotocol = \"modbus-tcp\"\n"
      "controller = \"tcp://127.0.0.1\"\ntimeout = \"200ms\"\nretries = 1\n"
      "reconnect_max = \"200ms\"\n"
      "[[loop]]\nname = \"FIC101\"\nbus = \"demo-plc\"\nsimulate = \"paper-ex1\"\nseed = " +
      std::to_string(seed) +
      "\nsample_period = 1\n"
      "op = { register = \"holding\", address = 0, type = \"FLOAT32\" }\n"
      "pv = { register = \"holding\", address = 2, type = \"FLOAT32\" }\n"
      "sp = { register = \"holding\", address = 4, type = \"FLOAT32\" }\n"
      "mv = { register = \"holding\", address = 6, type = \"FLOAT32\" }\n";
  SiteConfig site = parse_site_config(toml, "demo site (embedded)");
  site.loops[0].sample_period_s = period_s;  // below the 1 ms a file may give at high speed
  return site;
}

void print_comparison(const FitRun& run) {
  const auto& st = run.result.best.structure;
  std::printf("%-22s %-28s %s\n", "", "structure (na, nb, nk, L)", "fitness");
  std::printf("%-22s %-28s %.2f %%\n", "paper (Example 1)", "(1, 1, 5, 16)", 94.69);
  char ours[64];
  std::snprintf(ours, sizeof ours, "(%d, %d, %d, %d)", st.na, st.nb, st.nk, st.L);
  std::printf("%-22s %-28s %.2f %%   in %.2f s\n", "valvediag", ours, run.result.fitness_percent,
              run.result.elapsed_s);
}

// The loop's verdict (loop_verdict.hpp: diagnose --auto from `linear`, as every command gives
// it), its climb (the model history gets each step and the full-grid fit: the ladder) and the
// HTML report of the full-grid Preisach model.
void diagnose_and_report(const LoopData& d, const FitRun& run, const std::string& csv,
                         const std::string& report, bool offline) {
  const double Ts = d.sample_period();
  const std::string step = offline ? "" : "4. ";
  std::cout << "\n"
            << step << "diagnosing: which effects `linear` misses (valvediag diagnose " << csv
            << " --auto) ..." << std::flush;
  const auto t0 = std::chrono::steady_clock::now();
  // The reason's times on the data's own axis, as `diagnose` of the exported file gives them.
  VerdictOptions vo;
  vo.diagnose.time_origin_s = d.t.front();
  const LoopVerdict lv = loop_verdict(d, vo);
  const Diagnosis& diag = lv.diagnosis;
  std::vector<HistoryEntry> entries;
  if (!lv.judged()) {
    std::cout << " not possible\n";
  } else {
    std::printf(" done in %.1f s\n",
                std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
    const auto& base = diag.steps.front().fit;
    if (std::isfinite(base.fitness_percent))
      std::printf(
          "  linear: %.2f %% estimation, %.2f %% validation; the trial fits, most likely "
          "missing first (the diagnosis's ranking: `diagnose` says why):\n",
          base.fitness_percent, base.validation_fitness_percent);
    else  // gains are then counted from a fitness of 0 (the mean)
      std::printf(
          "  linear: no stable model on this record; the trial fits, most likely missing "
          "first (the diagnosis's ranking: `diagnose` says why):\n");
    const auto& findings = diag.steps.front().findings;
    for (std::size_t i = 0; i < findings.size() && i < 3; ++i)
      std::printf("  %zu. + %-15s %+.2f / %+.2f points (validation / estimation), score %.2f\n",
                  i + 1, findings[i].effect.c_str(), findings[i].validation_gain_percent,
                  findings[i].estimation_gain_percent, findings[i].score);
    for (std::size_t i = 1; i < diag.steps.size(); ++i) {
      const auto& f = diag.steps[i].fit;
      std::printf("  climbed to %s: %.2f %% estimation, %.2f %% validation\n",
                  to_string(f.spec).c_str(), f.fitness_percent, f.validation_fitness_percent);
    }
    for (const auto& st : diag.steps)
      entries.push_back(history_entry(st.fit, "demo: diagnose --auto"));
  }
  std::cout << verdict_text(lv, false);
  if (lv.verdict == "error") std::cout << "note:      " << lv.error << "\n";
  const ModelFit fit = model_fit_of(run.result, d.op, d.pv, Ts);
  entries.push_back(history_entry(fit, "demo: fit (paper's full grid)"));
  const std::string history = history_path_for(csv);
  append_history(history, entries);

  const FitSeries series = fit_series(run.result, d.op, d.pv);
  const ResidualAnalysis where = analyse_fit(run.result, d.op, d.pv, series);
  ReportContent c;
  c.data = &d;
  c.data_name = csv;
  c.fit = &fit;
  c.where = &where;
  if (lv.judged()) {
    c.diagnosis = &diag;
    c.diagnosis_command = "valvediag diagnose " + csv + " --auto";
  } else if (lv.verdict == "error") {
    c.notes.push_back(lv.error);
  }
  c.verdict = lv.verdict;
  c.unusable = lv.verdict == "not-enough-data" ? lv.reason : "";
  c.ladder = load_history(history);
  c.notes.push_back(offline ? "Simulated without the bus (valvediag demo --offline)."
                            : "Recorded through the Modbus TCP driver from a simulated PLC "
                              "running the paper's Example 1 loop; t in plant seconds.");
  c.generator = "valvediag demo";
  ReportOptions ro;
  ro.require_plots = false;  // without gnuplot the page says so in place of each plot
  const ReportFile r = write_report_file(report, c, ro);
  std::cout << (offline ? "" : "5. ") << "report: " << report_file_summary(report, r);
}

}  // namespace

void add_demo(CLI::App& app, int& exit_code) {
  auto* cmd = app.add_subcommand(
      "demo",
      "The whole story: a simulated PLC with a sticky valve loop, recorded over Modbus TCP, "
      "fitted, compared with the paper, diagnosed and written up as an HTML report");
  cmd->footer(
      "Examples:\n  valvediag demo\n  valvediag demo --out-dir /tmp/vd --speed 200\n"
      "  valvediag demo --offline      (no bus: simulate and fit directly)\n"
      "  valvediag demo --serve        (then the workbench on the recording, in a browser)");
  struct Args {
    std::uint64_t seed = 1;
    std::string json;
    std::string out_dir = "valvediag-demo";
    double speed = 100.0;
    std::size_t samples = 3000;
    bool offline = false;
    bool serve = false;
    int port = 8080;
  };
  auto a = std::make_shared<Args>();
  cmd->add_option("--seed", a->seed, "random seed of the simulation")->capture_default_str();
  cmd->add_option("--json", a->json, "also write the fit result as JSON to this file");
  cmd->add_option("--out-dir", a->out_dir,
                  "where the recording, CSV, model, model history and report go")
      ->capture_default_str();
  cmd->add_option("--speed", a->speed, "simulated seconds per real second (10..500)")
      ->check(CLI::Range(10.0, 500.0))
      ->capture_default_str();
  cmd->add_option("--samples", a->samples, "samples to record (Ts 0.5 s)")
      ->check(CLI::Range(600, 20000))
      ->capture_default_str();
  cmd->add_flag("--offline", a->offline, "simulate and fit without the bus (the quick check)");
  cmd->add_flag("--serve", a->serve,
                "then open the workbench on the recording (http://127.0.0.1:PORT/, until Ctrl-C)");
  cmd->add_option("--port", a->port, "--serve: the workbench's port; 0 picks a free one")
      ->check(CLI::Range(0, 65535))
      ->capture_default_str();
  cmd->callback([a, &exit_code] {
    namespace fs = std::filesystem;
    const Scenario s = scenario_by_name("paper-ex1");
    LoopData d;
    std::string json_path = a->json;
    const std::string csv = (fs::path(a->out_dir) / "fic101.csv").string();
    const std::string report = (fs::path(a->out_dir) / "report.html").string();
    // The demo's history stays in its own folder with its other files, not in the state directory.
    const std::string history = history_path_for(csv);
    const std::string db = (fs::path(a->out_dir) / "demo.sqlite").string();
    fs::create_directories(a->out_dir);
    check_report_writable(report);
    fs::remove(history);  // a new recording starts a new ladder
    if (a->offline) {
      std::cout << "Simulating scenario 'paper-ex1': " << s.description << "\n";
      d = run_scenario(s, a->seed, a->samples);
      write_loop_csv(csv, d);
    } else {
      for (const char* suffix : {"", "-wal", "-shm"}) fs::remove(db + suffix);
      const double Ts = s.loop.Ts, period = Ts / a->speed;
      SiteConfig site = demo_site(a->seed, period);
      SimPlc plc(site, SimPlcOptions{a->speed, 0});
      plc.start();
      std::cout << "1. simulated PLC on 127.0.0.1:" << plc.port()
                << ": loop FIC101 = " << s.description << ", running " << a->speed
                << "x real time\n";
      RecorderOptions o;
      o.db_path = db;
      // Polls half a PLC cycle after its steps, so every read sees exactly one new sample; the
      // first a moment from now, once the recorder is set up.
      const auto P = std::chrono::duration<double>(period);
      const double k0 = std::ceil(
          (std::chrono::steady_clock::now() + std::chrono::milliseconds(300) - plc.started()) / P);
      o.start = plc.started() +
                std::chrono::duration_cast<std::chrono::steady_clock::duration>((k0 + 0.5) * P);
      o.duration_s = static_cast<double>(a->samples) * period;
      std::cout << "2. recording " << a->samples << " samples (" << a->samples * Ts
                << " s of plant time) through the Modbus TCP driver, every " << period * 1e3
                << " ms ..." << std::flush;
      for (auto& b : site.buses) b.port = plc.port();
      Recorder rec(site, o, make_bus);
      std::atomic<bool> stop{false};
      const RecorderStatus st = rec.run(stop);
      plc.stop();
      std::printf(" done in %.1f s\n", st.elapsed_s);
      std::cout << recorder_summary(st, db, rec.run_id());
      if (plc.write_requests() != 0)
        throw std::runtime_error("the demo sent a write request: this is a bug");
      // Ticks the recorder missed (a loaded machine) are gaps: short ones are bridged, then the
      // longest clean stretch is fitted.
      RecordedLoop r =
          read_recorded_loop(db, "FIC101", std::nullopt, std::nullopt, 0, true, kBridgedTicks);
      for (const auto& n : r.notes) std::cout << "note: " << n << "\n";
      if (r.data.size() < a->samples / 2)
        throw std::runtime_error("only " + std::to_string(r.data.size()) +
                                 " consecutive good samples were recorded (machine overloaded?); "
                                 "try a lower --speed, e.g. --speed 50");
      d = std::move(r.data);
      for (double& t : d.t) t *= a->speed;  // back to plant seconds
      d.source = db + " loop FIC101 (recorded over Modbus TCP, t in plant seconds)";
      write_loop_csv(csv, d);
      std::cout << "3. exported " << csv << "\n";
      if (json_path.empty()) json_path = (fs::path(a->out_dir) / "model.json").string();
    }
    std::cout
        << "Identifying over the paper's full grid (na <= 3, nb <= 3, nk <= 10, L <= 20) ...\n\n";
    FitOptions fo;
    FitRun run = run_fit(d, fo, "pv");
    std::cout << run.summary << "\n";
    print_comparison(run);
    if (!json_path.empty()) {
      write_file_atomically(json_path, run.json.dump(2) + "\n");
      std::cout << "wrote " << json_path << "\n";
    }
    if (run.result.status != IdentificationStatus::Ok) {
      exit_code = kNoModel;
      return;
    }
    diagnose_and_report(d, run, csv, report, a->offline);
    std::cout << "\nfiles in " << a->out_dir << ":\n";
    if (!a->offline) std::cout << "  recording       " << db << "\n";
    std::cout << "  data (CSV)      " << csv << "\n";
    if (!json_path.empty()) std::cout << "  model (JSON)    " << json_path << "\n";
    std::cout << "  model history   " << history << "   (valvediag ladder " << csv << " --history "
              << history << ")\n"
              << "  report (HTML)   " << report << "\n";
    if (a->serve) {
      // The recording in the workbench: the same loop, its models built by hand from linear.
      WorkbenchSettings w;
      w.port = a->port;
      std::vector<std::string> notes;
      std::vector<serve::ServedLoop> loops;
      loops.push_back(served_loop("FIC101", d, w, notes));
      loops.back().history = history;  // the workbench's models join the demo's ladder
      for (const auto& n : notes) std::cout << "note: " << n << "\n";
      std::cout << "\n" << (a->offline ? "" : "6. ") << "the workbench on FIC101:\n";
      run_workbench(std::move(loops), w);
    }
    exit_code = kOk;
  });
}

}  // namespace valvediag::cli
