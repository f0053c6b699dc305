// Diagnostic sweeps over many loops: each loop's latest recorded window (or a data file) is
// checked, diagnosed (diagnose --auto) and ranked; results go to the site database, a results
// file (what a shard writes and sweep-merge reads), CSV and HTML. Loops run in child processes
// with a time limit, so one bad loop never stops the sweep.
#include <fnmatch.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <set>
#include <thread>

#include "commands.hpp"
#include "data_options.hpp"
#include "fit_runner.hpp"
#include "isolated_jobs.hpp"
#include "isolated_mat_reader.hpp"
#include "stop_signal.hpp"
#include "valvediag/drivers/bus_factory.hpp"
#include "valvediag/drivers/site_config.hpp"
#include "valvediag/io/atomic_file.hpp"
#include "valvediag/io/data_error.hpp"
#include "valvediag/recorder/recorder.hpp"
#include "valvediag/report/html_report.hpp"
#include "valvediag/report/model_history.hpp"
#include "valvediag/report/sweep_report.hpp"
#include "valvediag/sweep/loop_assessment.hpp"
#include "valvediag/sweep/sweep_store.hpp"
#include "valvediag/util/text_stats.hpp"

namespace valvediag::cli {

namespace {

namespace fs = std::filesystem;

// "I/N" with 0 <= I < N.
std::pair<int, int> parse_shard(const std::string& s) {
  const auto slash = s.find('/');
  try {
    if (slash != std::string::npos) {
      std::size_t p1 = 0, p2 = 0;
      const int i = std::stoi(s.substr(0, slash), &p1);
      const int n = std::stoi(s.substr(slash + 1), &p2);
      if (p1 == slash && p2 == s.size() - slash - 1 && n >= 1 && i >= 0 && i < n) return {i, n};
    }
  } catch (const std::exception&) {
  }
  throw UsageError("--shard '" + s +
                   "': give I/N with 0 <= I < N, e.g. --shard 0/4 (Slurm: "
                   "$SLURM_ARRAY_TASK_ID/$SLURM_ARRAY_TASK_COUNT)");
}

// One loop to assess: from the site's database or from a data file.
struct LoopJob {
  std::string name;
  std::string file;  // data file (file mode)
  OpRange range;
  std::string mat_loop;  // the loop's path inside a .mat file holding several
};

struct SweepArgs {
  std::string config, db, loops, window = "4h", record, shard, json, csv, html, loop_timeout = "5m";
  std::string reports;   // a folder for each loop's HTML report
  std::string op_range;  // data files: every file's OP span (a site gives each loop's)
  std::vector<std::string> files;
  DataOptions layout;  // CSV layout for data files
  int jobs = 0;
  double validate = 0.3;     // fraction of each record held out for scoring, as diagnose
  bool split_check = false;  // also score at the shares split_check_shares() gives
  bool quiet = false;
  bool keep_lead_in = false;
};

LoopAssessment failed(const LoopJob& job, const std::string& source, const std::string& why) {
  LoopAssessment a;
  a.loop = job.name;
  a.source = source;
  a.verdict = "error";
  a.error = why;
  a.severity = severity(a);
  return a;
}

// Runs in the child: read the loop's data and assess it; the result as JSON text.
std::string assess_job(const LoopJob& job, const SweepArgs& a, double window_s, int threads) {
  AssessOptions opt;
  opt.range = job.range;
  opt.diagnose.fit.threads = threads;
  opt.keep_lead_in = a.keep_lead_in;
  opt.diagnose.validation_fraction = a.validate;
  opt.check_splits = split_check_shares(a.validate, a.split_check);
  LoopData d;
  std::vector<std::string> notes;  // column choices: the per-loop report shows them, not the sweep
  try {
    if (!job.file.empty()) {
      DataOptions in = a.layout;
      in.data = job.file;
      in.loop = job.mat_loop;
      in.require_pv = false;  // an OP-only loop still gives its OP figures
      d = load_data(in, notes);
    } else {
      std::optional<RecordedLoop> r =
          read_latest_window(a.db, job.name, window_s, a.layout.csv.max_rows);
      if (!r) {
        LoopAssessment x;
        x.loop = job.name;
        x.source = a.db;
        x.verdict = "not-enough-data";
        x.reason = "nothing recorded for this loop in " + a.db +
                   ": record first (valvediag record, or sweep --record 10m)";
        return assessment_json(x).dump();
      }
      d = std::move(r->data);
      d.source = a.db + " (run " + std::to_string(r->run) + ")";
    }
  } catch (const DataError& e) {
    LoopAssessment x = failed(job, job.file.empty() ? a.db : job.file, e.what());
    return assessment_json(x).dump();
  } catch (const UsageError& e) {  // a file the layout options cannot read
    LoopAssessment x = failed(job, job.file, e.what());
    return assessment_json(x).dump();
  } catch (const std::runtime_error& e) {  // nothing clean recorded in the window
    LoopAssessment x;
    x.loop = job.name;
    x.source = a.db;
    x.verdict = "not-enough-data";
    x.reason = e.what();
    x.severity = severity(x);
    return assessment_json(x).dump();
  }
  Diagnosis dg;
  LoopAssessment r = assess_loop(d, job.name, opt, &dg);
  // The diagnosis covers the record after a quiet lead-in: its page shows that part.
  const QuietLeadIn& lead = r.lead_in;
  const LoopData shown_data = lead.cut() && !dg.steps.empty() ? drop_lead_in(d, lead.begin) : d;
  if (lead.cut() && !dg.steps.empty())
    notes.push_back(describe_lead_in(lead, d.t));  // on the page's time axis
  if (!a.reports.empty() && (!dg.steps.empty() || d.size() >= 2)) {
    // The loop's page: the climbed ladder's top model, where it fails, the findings; without a
    // model (not-enough-data, or no stable model on the ladder), why, the loop-health figures and
    // the trend.
    const fs::path path = fs::path(a.reports) / (job.name + ".html");
    const std::string shown = job.file.empty() ? a.db + ", loop " + job.name : job.file;
    ReportOptions ro;
    ro.require_plots = false;  // without gnuplot the page says so in place of each plot
    try {
      if (!dg.steps.empty() && dg.last().fit.status != ModelFitStatus::NoStableModel) {
        std::vector<HistoryEntry> ladder;
        for (const auto& s : dg.steps) ladder.push_back(history_entry(s.fit, "sweep"));
        ReportContent c;
        c.data = &shown_data;
        c.data_name = shown;
        c.fit = &dg.last().fit;
        c.where = &dg.last().residual;
        c.diagnosis = &dg;
        c.diagnosis_command = "valvediag sweep (diagnose --auto from linear)";
        c.verdict = r.verdict;  // the loop's verdict, of which dg is the analysis
        c.ladder = ladder;
        c.notes = notes;
        c.generator = "valvediag sweep";
        write_report_file(path.string(), c, ro);
      } else {
        DataPageContent c;
        c.data = &d;
        c.data_name = shown;
        c.verdict = r.verdict;
        c.reason = r.error.empty() ? r.reason : r.error;
        c.health = &r.health;
        if (r.limit_cycle.oscillating)
          c.findings.emplace_back("limit cycle", r.limit_cycle.summary);
        if (r.whole_record.tested) c.findings.emplace_back("whole record", r.whole_record.summary);
        c.notes = notes;
        c.generator = "valvediag sweep";
        write_page_file(path.string(), html_data_page(c, ro));
      }
      r.report = path.string();
    } catch (const std::exception& e) {
      r.error = std::string("report not written: ") + e.what();
    }
  }
  return assessment_json(r).dump();
}

void write_file(const std::string& path, const std::string& text) {
  // A results file is either whole or absent.
  try {
    write_file_atomically(path, text);
  } catch (const std::runtime_error& e) {
    throw UsageError(e.what());
  }
}

void write_outputs(const SweepArgs& a, const SweepInfo& info,
                   const std::vector<LoopAssessment>& loops) {
  if (!a.json.empty()) {
    write_file(a.json, sweep_json(info, loops).dump(1) + "\n");
    std::cout << "wrote " << a.json << "\n";
  }
  if (!a.csv.empty()) {
    write_file(a.csv, sweep_csv(loops));
    std::cout << "wrote " << a.csv << "\n";
  }
  if (!a.html.empty()) {
    // Links relative to the summary's folder, so the folder can be copied or served as a whole.
    std::vector<std::string> links;
    const fs::path base = fs::absolute(a.html).parent_path();
    for (const auto& l : loops)
      links.push_back(l.report.empty() ? ""
                                       : fs::absolute(l.report).lexically_relative(base).string());
    write_file(a.html, sweep_html(info, loops, links));
    std::cout << "wrote " << a.html << "\n";
  }
}

// The loops of the data files: one per CSV file; one per loop of a .mat file that holds
// several (an International Stiction Database file holds a hundred). A .mat file that cannot
// be listed stays one job, whose reading then reports why.
std::vector<LoopJob> file_jobs(const std::vector<std::string>& files, const OpRange& range) {
  std::vector<LoopJob> jobs;
  for (const auto& f : files) {
    const std::string stem = fs::path(f).stem().string();
    if (is_mat_file(f)) {
      try {
        const MatFileInfo info = list_mat_loops_isolated(f);
        if (info.loops.size() > 1) {
          for (const auto& l : info.loops) jobs.push_back({l.path, f, range, l.path});
          continue;
        }
      } catch (const DataError&) {
      } catch (const std::runtime_error&) {
      }
    }
    jobs.push_back({stem, f, range, ""});
  }
  std::set<std::string> seen;
  for (auto& j : jobs) {
    const std::string base = j.name;
    for (int k = 2; seen.count(j.name); ++k) j.name = base + "#" + std::to_string(k);
    seen.insert(j.name);
  }
  return jobs;
}

// Records the selected loops for `duration_s` before the sweep (--record).
void record_first(const SweepArgs& a, const std::vector<std::string>& loops, double duration_s,
                  const std::atomic<bool>& stop) {
  RecorderOptions o;
  o.db_path = a.db;
  o.loops = loops;
  o.duration_s = duration_s;
  std::unique_ptr<Recorder> rec;
  try {
    rec = std::make_unique<Recorder>(load_site_config(a.config), o, make_bus);
  } catch (const std::runtime_error& e) {
    throw UsageError(e.what());
  }
  std::cout << "recording " << loops.size() << " loop(s) for " << duration_s << " s into " << a.db
            << " before the sweep\n";
  const RecorderStatus s = rec->run(stop);
  if (!a.quiet) std::cout << recorder_summary(s, a.db, rec->run_id());
}

}  // namespace

double duration_option(const std::string& opt, const std::string& v) {
  const auto d = parse_duration(v);
  if (!d || !(*d > 0)) throw UsageError(opt + " '" + v + "': give e.g. 90s, 10m or 4h");
  return *d;
}

// --loops: names, or shell patterns (benchmark.chemicals.*) when they hold * ? or [.
bool selected(const std::vector<std::string>& wanted, const std::string& name) {
  if (wanted.empty()) return true;
  for (const auto& w : wanted)
    if (w == name || fnmatch(w.c_str(), name.c_str(), 0) == 0) return true;
  return false;
}

// A name or pattern of --loops that selects none of `names`: a typo, said before any work.
void check_selection(const std::vector<std::string>& wanted, const std::vector<std::string>& names,
                     const std::string& where) {
  for (const auto& w : wanted)
    if (std::none_of(names.begin(), names.end(),
                     [&](const std::string& n) { return selected({w}, n); })) {
      std::string list;
      for (std::size_t i = 0; i < names.size() && i < 20; ++i) list += (i ? ", " : "") + names[i];
      if (names.size() > 20) list += ", ... (" + std::to_string(names.size() - 20) + " more)";
      throw UsageError("--loops: no loop '" + w + "' in " + where + "; its loops: " + list);
    }
}

void add_sweep(CLI::App& app, int& exit_code) {
  auto* cmd = app.add_subcommand(
      "sweep", "Diagnose many loops unattended and rank the valves that need maintenance");
  cmd->footer(
      "Examples:\n"
      "  valvediag sweep --config site.toml --db site.sqlite                (latest 4 h of each "
      "loop)\n"
      "  valvediag sweep --config site.toml --db site.sqlite --record 10m --loops FIC101,LIC201\n"
      "  valvediag sweep --config site.toml --db site.sqlite --shard 3/16 --json part-3.json\n"
      "  valvediag sweep-merge part-*.json --csv plant.csv --html plant.html\n"
      "  valvediag sweep loops/*.txt   (data files; --format auto finds their layout)\n"
      "  valvediag sweep isdb.mat --loops 'isdb.chemicals.*'     (the loops of a .mat file)\n"
      "Each loop runs in its own process with a time limit: a bad loop is reported and the sweep "
      "goes on.\n"
      "Exit status 0 when the sweep ran (findings are results); 2 for bad options or config; 1 "
      "when it could not run.");
  auto a = std::make_shared<SweepArgs>();
  cmd->add_option("files", a->files,
                  "data files to sweep instead of a site: one loop per CSV file, every loop of a "
                  ".mat file");
  cmd->add_option("--config", a->config, "site TOML: the loops and their OP ranges");
  cmd->add_option("--db", a->db,
                  "site database: recordings are read from it and results stored in it");
  cmd->add_option("--loops", a->loops,
                  "comma-separated loop names or patterns (benchmark.chemicals.*); default: all "
                  "of the site, or of the files (every loop of a .mat file)");
  cmd->add_option("--window", a->window, "latest recorded window per loop: 30m, 4h, 1d")
      ->capture_default_str();
  cmd->add_option("--record", a->record, "record this long first (reads only), e.g. 10m");
  cmd->add_option("--jobs", a->jobs, "loops analysed at once (0: one per core)")
      ->capture_default_str();
  cmd->add_option("--shard", a->shard,
                  "run slice I of N of the loop list (0 <= I < N), for cluster job arrays");
  cmd->add_option("--loop-timeout", a->loop_timeout, "time limit per loop, e.g. 90s, 5m")
      ->capture_default_str();
  cmd->add_option("--json", a->json, "write the results file (sweep-merge reads it)");
  cmd->add_option("--csv", a->csv, "write the ranked summary as CSV");
  cmd->add_option("--html", a->html, "write the ranked summary as HTML");
  cmd->add_option("--reports", a->reports,
                  "write each loop's HTML report into this folder (linked from --html)");
  cmd->add_option("--validate", a->validate,
                  "fraction of each record held out for scoring, as in diagnose")
      ->capture_default_str();
  cmd->add_flag(
      "--split-check", a->split_check,
      "climb again with 0.05 less and 0.05 more held out and report whether the verdict "
      "holds (about 3x the time per judged loop; --loop-timeout covers all three climbs)");
  cmd->add_flag("--quiet", a->quiet, "no line per finished loop");
  cmd->add_flag("--keep-lead-in", a->keep_lead_in,
                "diagnose the whole window even when OP holds still for most of it before the "
                "loop moves (by default that lead-in is left out)");
  add_layout_options(cmd, a->layout);
  add_op_range_option(cmd, a->op_range);
  cmd->callback([a, &exit_code] {
    const bool site_mode = !a->config.empty();
    if (site_mode == !a->files.empty())
      throw UsageError("give --config site.toml --db site.sqlite, or data files (one of them)");
    if (site_mode && a->db.empty()) throw UsageError("--config needs --db site.sqlite");
    if (!site_mode && !a->record.empty()) throw UsageError("--record goes with --config");
    if (site_mode && !a->op_range.empty())
      throw UsageError(
          "--op-range goes with data files; a site gives each loop's OP range as "
          "op_range = [min, max] in " +
          a->config);
    const OpRange file_range = parse_op_range(a->op_range);
    const double window_s = duration_option("--window", a->window);
    const double timeout_s = duration_option("--loop-timeout", a->loop_timeout);
    if (a->jobs < 0) throw UsageError("--jobs must be 0 (one per core) or more");
    (void)split_check_shares(a->validate, a->split_check);  // user errors before any work
    if (!a->reports.empty()) {
      std::error_code ec;
      fs::create_directories(a->reports, ec);
      if (ec || !fs::is_directory(a->reports))
        throw UsageError("--reports " + a->reports + ": cannot create the folder" +
                         (ec ? ": " + ec.message() : ""));
    }
    std::pair<int, int> shard{0, 1};
    if (!a->shard.empty()) shard = parse_shard(a->shard);

    std::vector<LoopJob> jobs;
    const auto wanted = split_names(a->loops);
    if (site_mode) {
      const SiteConfig site = load_site_config(a->config);  // config errors before anything
      std::vector<std::string> names;
      for (const auto& l : site.loops) names.push_back(l.name);
      check_selection(wanted, names, a->config);
      for (const auto& l : site.loops)
        if (selected(wanted, l.name)) jobs.push_back({l.name, "", OpRange{l.op_min, l.op_max}, ""});
    } else {
      std::vector<std::string> names;
      for (auto& j : file_jobs(a->files, file_range)) {
        names.push_back(j.name);
        if (selected(wanted, j.name)) jobs.push_back(std::move(j));
      }
      check_selection(wanted, names, "the data files");
    }
    std::sort(jobs.begin(), jobs.end(),
              [](const auto& x, const auto& y) { return x.name < y.name; });
    if (shard.second > 1) {
      std::vector<LoopJob> mine;
      for (std::size_t i = 0; i < jobs.size(); ++i)
        if (static_cast<int>(i % static_cast<std::size_t>(shard.second)) == shard.first)
          mine.push_back(jobs[i]);
      jobs = std::move(mine);
    }

    auto& stop = install_stop_signals();
    if (!a->record.empty()) {
      std::vector<std::string> names;
      for (const auto& j : jobs) names.push_back(j.name);
      record_first(*a, names, duration_option("--record", a->record), stop);
    }

    SweepInfo info;
    info.started_utc = utc_timestamp();
    info.source = site_mode ? a->config + " / " + a->db : std::to_string(jobs.size()) + " files";
    info.shard = a->shard;
    info.window_s = site_mode ? window_s : 0.0;
    info.validation_fraction = a->validate;
    std::unique_ptr<SweepStore> store;
    std::int64_t sweep_id = 0;
    if (!a->db.empty()) {
      store = std::make_unique<SweepStore>(a->db);
      sweep_id = store->begin_sweep(info);
    }
    const unsigned cores = std::max(1u, std::thread::hardware_concurrency());
    const int parallel = a->jobs > 0 ? a->jobs : static_cast<int>(cores);
    const int threads = std::max(1, static_cast<int>(cores) / parallel);
    const auto t0 = std::chrono::steady_clock::now();
    std::vector<LoopAssessment> results;
    std::cout << "sweep: " << jobs.size() << " loop(s)"
              << (a->shard.empty() ? "" : ", shard " + a->shard) << ", " << parallel
              << " at once, at most " << timeout_s << " s each\n";
    run_isolated(
        jobs.size(), parallel, timeout_s,
        [&](std::size_t i) { return assess_job(jobs[i], *a, window_s, threads); },
        [&](std::size_t i, const JobOutcome& o) {
          const std::string source = jobs[i].file.empty() ? a->db : jobs[i].file;
          LoopAssessment r;
          using S = JobOutcome::Status;
          if (o.status == S::Ok) {
            try {
              r = assessment_from_json(nlohmann::json::parse(o.output));
            } catch (const std::exception& e) {
              r = failed(jobs[i], source, std::string("unreadable result: ") + e.what());
            }
          } else if (o.status == S::TimedOut) {
            char b[96];
            std::snprintf(b, sizeof b, "stopped at the time limit of %g s (--loop-timeout)",
                          timeout_s);
            r = failed(jobs[i], source, b);
          } else {
            r = failed(jobs[i], source, o.message);
          }
          r.elapsed_s = o.elapsed_s;
          if (store) store->add_result(sweep_id, r);
          if (!a->quiet) {
            char b[64];
            std::snprintf(b, sizeof b, " (%.1f s)", o.elapsed_s);
            std::cout << "[" << results.size() + 1 << "/" << jobs.size() << "] " << r.loop << ": "
                      << r.verdict << b << (r.error.empty() ? "" : ": " + r.error) << "\n"
                      << std::flush;
          }
          results.push_back(std::move(r));
        },
        &stop);
    info.finished_utc = utc_timestamp();
    info.elapsed_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    const bool complete = results.size() == jobs.size();
    if (store) store->end_sweep(sweep_id, info, complete ? "done" : "stopped");
    rank(results);
    std::cout << "\n" << format_sweep_table(results);
    char b[96];
    std::snprintf(b, sizeof b, "%.1f s", info.elapsed_s);
    std::cout << "swept " << results.size() << " of " << jobs.size() << " loop(s) in " << b
              << (complete ? "" : " (stopped early)") << "\n";
    if (store)
      std::cout << "results stored in " << a->db << " (sweep " << sweep_id
                << "; valvediag trend --db " << a->db << ")\n";
    write_outputs(*a, info, results);
    exit_code = complete ? kOk : kFailure;
  });
}

void add_sweep_merge(CLI::App& app, int& exit_code) {
  auto* cmd = app.add_subcommand(
      "sweep-merge", "Merge the results files of a sharded sweep into one ranked summary");
  cmd->footer(
      "Example:\n  valvediag sweep-merge part-*.json --json plant.json --csv plant.csv --html "
      "plant.html --db site.sqlite");
  auto a = std::make_shared<SweepArgs>();
  cmd->add_option("results", a->files, "results files written by sweep --json")->required();
  cmd->add_option("--json", a->json, "write the merged results file");
  cmd->add_option("--csv", a->csv, "write the ranked summary as CSV");
  cmd->add_option("--html", a->html, "write the ranked summary as HTML");
  cmd->add_option("--db", a->db, "also store the merged sweep in this database (for trends)");
  cmd->callback([a, &exit_code] {
    std::vector<LoopAssessment> all;
    std::set<std::string> names;
    SweepInfo info;
    for (const auto& f : a->files) {
      std::ifstream in(f);
      if (!in) throw UsageError(f + ": cannot open the results file");
      nlohmann::json j;
      try {
        j = nlohmann::json::parse(in);
      } catch (const std::exception& e) {
        throw UsageError(f + ": not JSON: " + e.what());
      }
      std::vector<LoopAssessment> part;
      try {
        part = sweep_loops_from_json(j);
      } catch (const std::exception& e) {
        throw UsageError(f + ": " + e.what());
      }
      const std::string started = j.value("started_utc", "");
      if (info.started_utc.empty() || started < info.started_utc) info.started_utc = started;
      info.finished_utc = std::max(info.finished_utc, j.value("finished_utc", std::string()));
      info.window_s = j.value("window_s", 0.0);
      // Fitness and verdicts depend on the held-out share: parts scored on different shares are
      // not one sweep. (Files written before the key existed held out 0.3.)
      const double held = j.value("validate", 0.3);
      if (&f != &a->files.front() && held != info.validation_fraction)
        throw UsageError(f + ": held out " + strprintf("%g", held) +
                         " of each record (--validate), " + a->files.front() + " held out " +
                         strprintf("%g", info.validation_fraction) +
                         ": merge the parts of one sweep, run with the same --validate");
      info.validation_fraction = held;
      for (auto& l : part) {
        if (!names.insert(l.loop).second)
          throw UsageError(f + ": loop '" + l.loop +
                           "' is also in an earlier file: were two shards given the same I/N?");
        all.push_back(std::move(l));
      }
    }
    info.source = "merged from " + std::to_string(a->files.size()) + " results file(s)";
    rank(all);
    if (!a->db.empty()) {
      SweepStore store(a->db);
      const auto id = store.begin_sweep(info);
      for (const auto& l : all) store.add_result(id, l);
      store.end_sweep(id, info, "merged");
      std::cout << "stored in " << a->db << " (sweep " << id << ")\n";
    }
    std::cout << format_sweep_table(all);
    write_outputs(*a, info, all);
    exit_code = kOk;
  });
}

void add_trend(CLI::App& app, int& exit_code) {
  auto* cmd =
      app.add_subcommand("trend", "Each loop's figures over past sweeps, from the database");
  cmd->footer(
      "Examples:\n  valvediag trend --db site.sqlite\n  valvediag trend --db site.sqlite --loop "
      "FIC101 --last 30");
  struct Args {
    std::string db, loop;
    int last = 10;
  };
  auto a = std::make_shared<Args>();
  cmd->add_option("--db", a->db, "site database the sweeps stored their results in")->required();
  cmd->add_option("--loop", a->loop, "one loop (default: every loop a sweep assessed)");
  cmd->add_option("--last", a->last, "how many past sweeps")->capture_default_str();
  cmd->callback([a, &exit_code] {
    if (!fs::exists(a->db)) throw UsageError(a->db + ": no such database");
    // trend only reads: a read-only copy of the database will do. A file it cannot read as one
    // (not SQLite, tables of another release) is bad input, as in export.
    const auto store = [&] {
      try {
        return std::make_unique<SweepStore>(a->db, SweepStore::Access::ReadOnly);
      } catch (const std::runtime_error& e) {
        throw UsageError(e.what());
      }
    }();
    const auto loops =
        a->loop.empty() ? store->assessed_loops() : std::vector<std::string>{a->loop};
    if (loops.empty())
      throw UsageError(a->db + ": no sweep results yet: run valvediag sweep first");
    for (const auto& name : loops) {
      const auto points = store->trend(name, a->last);
      if (points.empty()) throw UsageError(a->db + ": no sweep assessed loop '" + name + "'");
      std::cout << name << ":\n";
      char line[256];
      // "held": the share held out for scoring; validation fitness compares at equal shares.
      // "splits": shares giving the verdict when the sweep ran with --split-check.
      std::snprintf(line, sizeof line, "  %-6s %-20s %-19s %8s %8s %5s %6s %9s %8s %8s\n", "sweep",
                    "started", "verdict", "stiction", "val fit", "held", "splits", "period s",
                    "rev/h", "travel/h");
      std::cout << line;
      for (const auto& p : points) {
        const auto& r = p.result;
        auto f = [](double v, int prec) {
          if (!std::isfinite(v)) return std::string("-");
          char b[32];
          std::snprintf(b, sizeof b, "%.*f", prec, v);
          return std::string(b);
        };
        std::snprintf(line, sizeof line, "  %-6lld %-20s %-19s %8s %8s %5s %6s %9s %8s %8s\n",
                      static_cast<long long>(p.sweep), p.started_utc.c_str(), r.verdict.c_str(),
                      f(r.stiction_percent, 2).c_str(), f(r.validation_fitness_percent, 1).c_str(),
                      f(p.validation_fraction, 2).c_str(), split_agreement_text(r).c_str(),
                      r.health.oscillating ? f(r.health.period_s, 0).c_str() : "-",
                      f(r.health.op_reversals_per_hour, 0).c_str(),
                      f(r.health.op_travel_percent_per_hour, 0).c_str());
        std::cout << line;
      }
    }
    exit_code = kOk;
  });
}

}  // namespace valvediag::cli
