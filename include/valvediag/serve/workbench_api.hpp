// The workbench (issue 36, `valvediag serve`): its page, and the JSON API behind it: the loops the
// server was started with, their trends decimated per bucket, their verdicts, and the model jobs
// that build each loop's ladder (loop_models.hpp, jobs.hpp). Plain requests in, status and body
// out: no sockets here (the CLI puts cpp-httplib in front), so the routing, the bounds and the
// token are tested without a network.
//
// Safety: the API serves only the loops it was given. No endpoint takes a file name, paths are
// matched segment by segment against the few routes below (anything else, `..` included, is a
// 404), and the only files written are the loops' model histories (ServedLoop::history).
#pragma once

#include <chrono>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "valvediag/core/op_range.hpp"
#include "valvediag/io/loop_data.hpp"
#include "valvediag/report/model_history.hpp"
#include "valvediag/serve/jobs.hpp"
#include "valvediag/serve/loop_models.hpp"

namespace valvediag::serve {

// One version of a loop's data: as read, and the part the models are fitted to (diagnose's: the
// CLI leaves a quiet lead-in out, as diagnose does; nullopt: all of `data`).
struct LoopSnapshot {
  LoopData data;
  std::optional<LoopData> analysed;
  const LoopData& model_data() const { return analysed ? *analysed : data; }
};
// Reads a live loop again (a recording as it grows): its latest data, or nullptr while there is
// none. May throw: the request that asked gets an error, the data served stays as it was.
using LoopReader = std::function<std::shared_ptr<const LoopSnapshot>()>;
// Adds a job's new models to the loop's model history; the job's "history" (e.g. {"entries": N}
// or {"error": why}).
using HistoryWriter = std::function<nlohmann::json(const std::vector<HistoryEntry>&)>;

struct ServedLoop {
  ServedLoop(std::string n, LoopData d, std::optional<LoopData> a = std::nullopt,
             std::string h = "")
      : name(std::move(n)),
        snapshot(std::make_shared<const LoopSnapshot>(LoopSnapshot{std::move(d), std::move(a)})),
        history(std::move(h)) {}
  std::string name;                              // the loop's tag, else the file's stem
  std::shared_ptr<const LoopSnapshot> snapshot;  // the data served (a live loop's first)
  // The loop's model history file, where the jobs' models are appended (the CLI: the state
  // directory's file for the data and its reading options, the one `ladder` reads); "": none.
  std::string history;
  // Set: the models go there instead of `history` (the CLI: a recording's table model_history).
  HistoryWriter history_writer;
  // Set: the loop is live; its data is read again at most every kLiveRefreshS when asked for.
  LoopReader live;
  // The loop's OP span when its site gives one (serve --config: the loop's op_range), for its
  // verdict and its jobs; nullopt: the server's (--op-range, ModelOptions::range).
  std::optional<OpRange> op_range;
};

// A live loop is read again at most this often (s): a page polling every second reads the
// recording once, however many of its charts ask.
inline constexpr double kLiveRefreshS = 0.5;

// GET /api/status's body beyond "live" (the CLI: the recorder's counters and its buses').
using StatusFunction = std::function<nlohmann::json()>;

// One request as the HTTP layer parsed it: the path already URL-decoded, the query's parameters
// (a name given twice is kept twice, and refused), the Authorization, Cookie, Host and
// Content-Type headers ("" when absent), and the body.
struct ApiRequest {
  std::string method = "GET";
  std::string path;
  std::multimap<std::string, std::string> query;
  std::string authorization;
  std::string cookie;
  std::string host;
  std::string content_type;
  std::string body;
};

struct ApiResponse {
  ApiResponse() = default;
  ApiResponse(int s, nlohmann::json b) : status(s), body(std::move(b)) {}
  int status = 200;
  nlohmann::json body;
  // A page, a script or a download instead of JSON: its bytes and type ("" : the JSON body).
  std::string raw;
  std::string content_type;
  std::string attachment;  // a download's file name (Content-Disposition), "" otherwise
  std::string set_cookie;  // a Set-Cookie value, "" for none
};
// The body as sent. Text that is not UTF-8 (a decoded path echoed in a 404) is replaced, not
// thrown on.
std::string response_text(const ApiResponse& r);
// Its Content-Type: `content_type`, else application/json.
std::string response_type(const ApiResponse& r);

// The cookie the page's requests carry the token in, set when `/?token=TOKEN` is opened.
inline constexpr const char* kTokenCookie = "valvediag_token";
// Its name for a request addressed to `host`: with the Host header's port appended
// ("valvediag_token_8080"), since browsers keep cookies per host name, not per port, and two
// servers on one machine would otherwise overwrite each other's token.
std::string token_cookie_name(const std::string& host);

// POST bodies beyond this many bytes are refused (413). The jobs' bounds are JobLimits' (a full
// queue is a 503).
inline constexpr std::size_t kMaxBody = 64 * 1024;

// The JSON of a loop's verdict: the CLI passes the very call `diagnose` makes (loop_verdict()
// with its options, written by add_verdict_json()), so both give the same verdict. The range is
// the loop's OP span (ServedLoop::op_range, else the server's).
using VerdictFunction = std::function<nlohmann::json(const LoopData&, const OpRange&)>;

// Bounds of GET /api/loops/{id}/series.
inline constexpr int kDefaultBuckets = 1000;
inline constexpr int kMaxBuckets = 10000;
// Bounds of the phase plots (GET /api/loops/{id}/phase, .../models/{n}/signature): points per
// answer. The least is enough for one bucket's extremes of every column.
inline constexpr int kDefaultPathPoints = 2000;
inline constexpr int kMinPathPoints = 10;
inline constexpr int kMaxPathPoints = 10000;

class WorkbenchApi {
 public:
  // token: "" serves requests addressed to this machine by name (Host: localhost, 127.x, [::1]:
  // a web page that rebinds its own name to 127.0.0.1 gets a 403, not the plant's data); the CLI
  // then binds loopback only. Else every request needs `Authorization: Bearer TOKEN`.
  // status: GET /api/status's counters (the recorder's, with --config); none: {"live": false}.
  WorkbenchApi(std::vector<ServedLoop> loops, VerdictFunction verdict, std::string token = "",
               ModelOptions models = {}, JobLimits limits = {}, StatusFunction status = {});
  // Cancels the jobs and waits for them.
  ~WorkbenchApi();
  // Thread-safe; never throws: a bad request is a 4xx {"error": ...}, a failure inside a 500.
  ApiResponse handle(const ApiRequest& req) const;
  std::size_t size() const { return loops_.size(); }

 private:
  struct Cached {
    std::mutex compute;  // one computation per loop; other requests for it wait for its result
    std::mutex value;    // guards `verdict` only: listing the loops never waits for a fit
    std::optional<nlohmann::json> verdict;
    std::shared_ptr<const LoopSnapshot> verdict_of;  // the data the verdict judged
    std::mutex jobs;     // held by the loop's running job: one at a time per loop
    std::mutex reading;  // one read of a live loop at a time
    std::mutex data;     // guards `snapshot` and `read_at`
    std::shared_ptr<const LoopSnapshot> snapshot;
    std::chrono::steady_clock::time_point read_at{};
  };
  // The loop's data now: a live loop's read again when older than kLiveRefreshS.
  std::shared_ptr<const LoopSnapshot> snapshot(std::size_t id) const;
  ApiResponse route(const ApiRequest& req) const;
  ApiResponse loop_route(const ApiRequest& req, const std::vector<std::string>& s,
                         std::size_t id) const;
  ApiResponse job_route(const ApiRequest& req, const std::string& id) const;
  ApiResponse submit(const ApiRequest& req, std::size_t id) const;
  nlohmann::json loops_json() const;
  nlohmann::json verdict_json(std::size_t id) const;
  // The session's options for loop id: its own OP span when it has one (ServedLoop::op_range).
  ModelOptions options_of(std::size_t id) const;
  bool authorized(const ApiRequest& req) const;

  std::vector<ServedLoop> loops_;
  VerdictFunction verdict_;
  std::string token_;
  ModelOptions model_options_;
  StatusFunction status_;
  std::vector<std::unique_ptr<Cached>> cache_;
  std::vector<std::unique_ptr<LoopModels>> models_;
  // Last: destroyed first, so no job outlives the loops and models it works on.
  mutable JobQueue jobs_;
};

// OP, PV and SP (those present) of the samples with from <= t <= to, in at most `buckets`
// buckets of consecutive samples (fewer when fewer samples): per bucket its first and last time
// stamp and each signal's min and max over it, so a chart drawn from them shows every spike.
// Columns: {"from","to","samples","buckets","t":[...],"t_end":[...],"n":[...],
// "op":{"min":[...],"max":[...]}, "pv":..., "sp":...}. Throws std::invalid_argument when no
// sample lies in [from, to].
nlohmann::json decimated_series(const LoopData& d, double from, double to, int buckets);
// The same for any columns on the time axis t: {"pv": &pv, "pv_sim": &sim}.
struct Column {
  const char* name;
  const std::vector<double>* x;
};
nlohmann::json decimated_columns(const std::vector<double>& t, const std::vector<Column>& columns,
                                 double from, double to, int buckets);
// The samples with from <= t <= to as a path for an XY (phase) chart, in data order, at most
// `points` of them: all when they are that few; else the samples are cut into runs of
// consecutive samples (points / (2 * columns) runs) and each run keeps, in data order, the
// samples where a column reaches its minimum or its maximum over the run, so the path keeps its
// corners (a stiction cycle's jumps) and its extent. Columns: {"from","to","samples","points",
// "t":[...], "index":[...] (sample numbers), one array per column, "held_out":[...] (sample
// number >= held_out_from)}. Throws std::invalid_argument when no sample lies in [from, to].
nlohmann::json decimated_path(const std::vector<double>& t, const std::vector<Column>& columns,
                              double from, double to, int points, std::size_t held_out_from);

// 32 hex digits from std::random_device (the kernel's random source on Linux).
std::string random_token();

// 127.0.0.0/8, ::1 and localhost: addresses only this machine can reach.
bool is_loopback(const std::string& address);
// A Host header naming a loopback address, with or without a port ("localhost:8080",
// "[::1]:8080", "127.0.0.1").
bool is_loopback_host(const std::string& host);

}  // namespace valvediag::serve
