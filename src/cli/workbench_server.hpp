// The workbench's HTTP server (cmd_serve.cpp), for `serve` and `demo --serve`.
#pragma once

#include <atomic>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "history_options.hpp"
#include "valvediag/core/op_range.hpp"
#include "valvediag/drivers/site_config.hpp"
#include "valvediag/recorder/recorder.hpp"
#include "valvediag/serve/workbench_api.hpp"

namespace valvediag::cli {

struct WorkbenchSettings {
  int port = 8080;
  std::string bind = "127.0.0.1";
  bool token = false;         // a random token required on every request
  unsigned jobs = 0;          // model jobs at once; 0: one per core
  double validate = 0.3;      // the verdict's and the models' held-out share
  double min_gain = 2.0;      // the verdict's --min-gain
  bool keep_lead_in = false;  // analyse the whole record
  OpRange range;
};

// A UsageError when `bind` lets other machines in without a token.
void check_workbench_bind(const WorkbenchSettings& w);
// A loop's data to serve: `d` as read, the models fitted to the part diagnose analyses (notes say
// where it starts).
serve::LoopSnapshot served_snapshot(LoopData d, const WorkbenchSettings& w,
                                    std::vector<std::string>& notes);
serve::ServedLoop served_loop(std::string name, LoopData d, const WorkbenchSettings& w,
                              std::vector<std::string>& notes);
// What a live workbench (serve --config) adds: GET /api/status's counters, and `listening`,
// called once the port is bound, before the address is printed (the recorder starts there).
struct WorkbenchExtras {
  serve::StatusFunction status;
  std::function<void()> listening;
};
// A recording served: --db, --loops (names or patterns), --window, the readers' --max-rows.
struct RecordingSource {
  std::string db;
  std::vector<std::string> wanted;
  double window_s = 4 * 3600.0;
  std::size_t max_rows = kDefaultMaxRows;
};
// serve --db: each selected loop's latest window (as sweep reads it), its models' history in the
// recording's table model_history (--no-history: none). UsageErrors name the file and the loop:
// no such file, not a recording, no loop selected, a loop without samples.
std::vector<serve::ServedLoop> recorded_loops_to_serve(const RecordingSource& src,
                                                       const WorkbenchSettings& w,
                                                       const HistoryOptions& hist);

// serve --config --db: the site's selected loops recorded into the database while the workbench
// serves them, each loop its current run's latest window as it grows. The recorder only reads
// from the PLCs.
class LiveRecording {
 public:
  // Checks the selection and sets up the recorder (the buses, the database's lock); no request
  // is sent before start(). UsageErrors as `valvediag record` gives them.
  LiveRecording(SiteConfig site, const RecordingSource& src, const WorkbenchSettings& w,
                const HistoryOptions& hist);
  ~LiveRecording();  // stops and waits for the recorder
  LiveRecording(const LiveRecording&) = delete;
  LiveRecording& operator=(const LiveRecording&) = delete;
  // The loops to serve (taken once; they read the recording through this object).
  std::vector<serve::ServedLoop> take_loops() { return std::move(loops_); }
  void start();
  // Stops the recorder: it stores every sample taken and ends its run.
  void stop();
  // GET /api/status: the recorder's counters and its buses' (requests, errors, reconnects),
  // the reads' lateness.
  nlohmann::json status_json() const;
  std::string summary() const;  // record's end-of-run summary
  std::string error() const;    // why the recorder stopped early, "" when it did not

 private:
  std::string db_;
  std::unique_ptr<Recorder> recorder_;
  std::vector<serve::ServedLoop> loops_;
  std::atomic<bool> stop_{false}, running_{false};
  std::atomic<std::int64_t> run_{0};
  mutable std::mutex m_;
  RecorderStatus status_;
  std::string error_;
  std::thread thread_;
};

// Serves the loops until Ctrl-C or SIGTERM, printing the address; throws when it cannot listen.
void run_workbench(std::vector<serve::ServedLoop> loops, const WorkbenchSettings& w,
                   const WorkbenchExtras& extras = {});

}  // namespace valvediag::cli
