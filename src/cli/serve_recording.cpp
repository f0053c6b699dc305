// The workbench's loops from a recording: `serve --db` (each loop's latest window, as a sweep
// reads it) and `serve --config --db` (the recorder runs in the server and the loops grow as it
// records). The recorder only reads from the PLC (bus.hpp has no write).
#include <cmath>
#include <cstdio>
#include <iostream>

#include "commands.hpp"
#include "valvediag/drivers/bus_factory.hpp"
#include "valvediag/io/data_error.hpp"
#include "valvediag/sweep/sweep_store.hpp"
#include "workbench_server.hpp"

namespace valvediag::cli {

namespace {

using nlohmann::json;

// A job's "history" from what adding to a recording's table (or its fallback file) did.
json history_result(const HistoryAppended& r) {
  if (!r.error.empty()) return {{"error", r.error + "; the models stand without it"}};
  json j{{"entries", r.total}, {"where", r.where}};
  if (!r.warnings.empty()) j["warnings"] = r.warnings;
  return j;
}

std::string seconds_text(double s) {
  char b[40];
  std::snprintf(b, sizeof b, "%.15g", s);
  return b;
}

}  // namespace

std::vector<serve::ServedLoop> recorded_loops_to_serve(const RecordingSource& src,
                                                       const WorkbenchSettings& w,
                                                       const HistoryOptions& hist) {
  std::vector<std::string> names;
  try {
    names = recorded_loops(src.db);  // no such file, not a recording: said with the file's name
  } catch (const std::runtime_error& e) {
    throw UsageError(e.what());
  }
  if (names.empty())
    throw UsageError(src.db + ": holds no recorded loop; record some first (valvediag record " +
                     "--config site.toml --db " + src.db + ")");
  check_selection(src.wanted, names, src.db);
  std::vector<serve::ServedLoop> loops;
  for (const auto& name : names) {
    if (!selected(src.wanted, name)) continue;
    std::optional<RecordedLoop> r;
    try {
      r = read_latest_window(src.db, name, src.window_s, src.max_rows);
    } catch (const DataError&) {
      throw;                                 // names the run, loop and tick, and --max-rows
    } catch (const std::runtime_error& e) {  // nothing clean in the window
      throw UsageError(std::string(e.what()) + "; give a longer --window, or leave loop " + name +
                       " out with --loops");
    }
    if (!r || r->data.size() < 2)
      throw UsageError(src.db + ": loop " + name +
                       " has no samples to serve; record it first (valvediag record), or leave "
                       "it out with --loops");
    std::vector<std::string> notes = r->notes;
    // Short gaps bridged: the history's key and the commands that read these samples back say
    // so (--bridge-gaps).
    const bool bridged = r->bridged_gaps > 0;
    LoopData d = std::move(r->data);
    // The history `fit --db site.sqlite --loop NAME --from A --to B` keeps for these samples:
    // the recording's table model_history (the state directory when the file cannot take it).
    DataOptions in;
    in.db = src.db;
    in.loop = name;
    in.run_read = r->run;
    if (bridged) in.bridge_gaps = kBridgedTicks;
    if (d.t.front() > 0) {
      in.from = seconds_text(d.t.front());
      in.to = seconds_text(d.t.back());
    }
    std::string where;
    serve::HistoryWriter writer;
    if (!hist.off) {
      const HistoryPlace place = history_place(hist, in, d);
      where = place.where();
      writer = [place](const std::vector<HistoryEntry>& e) {
        return history_result(append_history_at(place, e));
      };
    }
    const std::string range = (in.from.empty() ? "" : " --from " + in.from + " --to " + in.to) +
                              (bridged ? " --bridge-gaps " + std::to_string(kBridgedTicks) : "");
    loops.push_back(served_loop(name, std::move(d), w, notes));
    loops.back().history_writer = writer;
    for (const auto& n : notes)
      std::cout << "note: " << src.db << ", loop " << name << ": " << n << "\n";
    std::cout << "loop " << name << ": run " << r->run << ", t "
              << loops.back().snapshot->data.t.front() << " to "
              << loops.back().snapshot->data.t.back() << " s";
    if (!where.empty())
      std::cout << "; model history: " << where << " (valvediag ladder --db " << src.db
                << " --loop " << name << range << ")";
    std::cout << "\n";
  }
  return loops;
}

LiveRecording::LiveRecording(SiteConfig site, const RecordingSource& src,
                             const WorkbenchSettings& w, const HistoryOptions& hist)
    : db_(src.db) {
  std::vector<std::string> names;
  for (const auto& l : site.loops) names.push_back(l.name);
  check_selection(src.wanted, names, site.file);
  RecorderOptions o;
  o.db_path = src.db;
  for (const auto& n : names)
    if (selected(src.wanted, n)) o.loops.push_back(n);
  o.status_interval_s = 0.25;  // the page's status and the run id soon after the start
  std::vector<LoopConfigEntry> configs;
  for (const auto& n : o.loops) configs.push_back(*site.find_loop(n));
  try {
    recorder_ = std::make_unique<Recorder>(std::move(site), o, make_bus);
  } catch (const std::runtime_error& e) {
    throw UsageError(e.what());  // no SocketCAN, database not writable or being recorded
  }
  for (const auto& cfg : configs) {
    LoopData empty;
    empty.source = src.db + " loop " + cfg.name + " (recording)";
    serve::ServedLoop l(cfg.name, std::move(empty));
    // The site's OP span of the loop: its verdict, its jobs and its quiet lead-in, as sweep
    // --config judges it.
    const OpRange span{cfg.op_min, cfg.op_max};
    l.op_range = span;
    WorkbenchSettings wl = w;
    wl.range = span;
    const std::string db = src.db, name = cfg.name;
    const double window_s = src.window_s;
    const std::size_t max_rows = src.max_rows;
    // The current run's latest window, once the recorder has stored some of it; read errors
    // (nothing clean yet) keep the data shown as it was.
    l.live = [this, db, name, window_s, max_rows,
              wl]() -> std::shared_ptr<const serve::LoopSnapshot> {
      const std::int64_t run = run_.load();
      if (run == 0) return nullptr;
      try {
        auto r = read_latest_window(db, name, window_s, max_rows, run);
        if (!r || r->data.size() < 2) return nullptr;
        std::vector<std::string> notes;
        return std::make_shared<const serve::LoopSnapshot>(
            served_snapshot(std::move(r->data), wl, notes));
      } catch (const std::exception&) {
        return nullptr;
      }
    };
    if (!hist.off)
      // The run's history in the recording, where `ladder --db DB --loop NAME` finds it.
      l.history_writer = [this, db, name](const std::vector<HistoryEntry>& e) {
        HistoryPlace p;
        p.db = db;
        p.key = {run_.load(), name, ""};
        return history_result(append_history_at(p, e));
      };
    loops_.push_back(std::move(l));
  }
}

LiveRecording::~LiveRecording() {
  stop();
}

void LiveRecording::start() {
  running_ = true;
  thread_ = std::thread([this] {
    try {
      const RecorderStatus s = recorder_->run(stop_, [this](const RecorderStatus& st) {
        run_ = st.run;
        std::lock_guard<std::mutex> lock(m_);
        status_ = st;
      });
      std::lock_guard<std::mutex> lock(m_);
      status_ = s;
    } catch (const std::exception& e) {
      std::lock_guard<std::mutex> lock(m_);
      error_ = e.what();
    }
    running_ = false;
  });
}

void LiveRecording::stop() {
  stop_ = true;
  if (thread_.joinable()) thread_.join();
}

std::string LiveRecording::summary() const {
  std::lock_guard<std::mutex> lock(m_);
  return recorder_summary(status_, db_, recorder_->run_id()) +
         (error_.empty() ? "" : "  the recorder stopped: " + error_ + "\n");
}

std::string LiveRecording::error() const {
  std::lock_guard<std::mutex> lock(m_);
  return error_;
}

json LiveRecording::status_json() const {
  std::lock_guard<std::mutex> lock(m_);
  const RecorderStatus& s = status_;
  json loops = json::array(), buses = json::array();
  for (const auto& l : s.loops)
    loops.push_back({{"name", l.name},
                     {"rows", l.rows},
                     {"good", l.good},
                     {"comm_error", l.comm_error},
                     {"stale", l.stale},
                     {"missed", l.missed},
                     {"invalid", l.invalid},
                     {"gaps", l.gaps}});
  for (const auto& [name, b] : s.buses)
    buses.push_back({{"name", name},
                     {"connected", b.connected},
                     {"requests", b.requests},
                     {"errors", b.errors},
                     {"timeouts", b.timeouts},
                     {"exceptions", b.exceptions},
                     {"garbled", b.garbled},
                     {"disconnects", b.disconnects},
                     {"reconnects", b.reconnects},
                     {"connect_attempts", b.connect_attempts},
                     {"last_error", b.last_error}});
  return {{"recording", running_.load()},
          {"db", db_},
          {"run", s.run},
          {"elapsed_s", s.elapsed_s},
          {"rows", s.rows},
          {"stored", s.committed},
          {"bad_rows", s.bad_rows},
          {"missed", s.missed},
          {"lateness_p50_s", s.lateness_p50_s},
          {"lateness_p99_s", s.lateness_p99_s},
          {"lateness_max_s", s.lateness_max_s},
          {"database_busy_s", s.busy_s},
          {"last_error", s.last_error},
          {"error", error_.empty() ? json() : json(error_)},
          {"loops", loops},
          {"buses", buses}};
}

}  // namespace valvediag::cli
