#include "valvediag/serve/workbench_api.hpp"

#include <arpa/inet.h>
#include <netinet/in.h>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <random>
#include <stdexcept>
#include <thread>
#include <utility>

#include "valvediag/core/cancel.hpp"
#include "valvediag/report/json_number.hpp"
#include "valvediag/serve/static_files.hpp"
#include "valvediag/util/utc_time.hpp"

namespace valvediag::serve {

namespace {

using nlohmann::json;

// A request the client got wrong (400); the message goes back to it.
struct BadRequest : std::invalid_argument {
  using std::invalid_argument::invalid_argument;
};

ApiResponse error(int status, const std::string& message) {
  return {status, json{{"error", message}}};
}

const char* kRoutes =
    "the workbench has GET / (the page), GET /api/loops, /api/status, "
    "/api/loops/{id}/series?from=S&to=S&"
    "buckets=N, /api/loops/{id}/verdict, /api/loops/{id}/ladder, /api/loops/{id}/diagnosis, "
    "/api/loops/{id}/phase?from=S&to=S&points=N, /api/loops/{id}/models/{n}, "
    "/api/loops/{id}/models/{n}/simulation, /api/loops/{id}/models/{n}/signature, "
    "/api/loops/{id}/report, "
    "POST /api/loops/{id}/jobs, GET and DELETE /api/jobs/{id} (docs/workbench.md)";

// The path's segments after the leading '/': "/api/loops/0" -> {api, loops, 0}. Empty segments
// are kept, so "/api//loops" matches no route.
std::vector<std::string> segments(const std::string& path) {
  std::vector<std::string> s;
  if (path.empty() || path[0] != '/') return s;
  std::size_t b = 1;
  for (;;) {
    const std::size_t e = path.find('/', b);
    s.push_back(path.substr(b, e == std::string::npos ? std::string::npos : e - b));
    if (e == std::string::npos) return s;
    b = e + 1;
  }
}

// A loop id: decimal digits only (no sign, no space, no '..'), below n.
std::optional<std::size_t> loop_id(const std::string& s, std::size_t n) {
  if (s.empty() || s.size() > 9 ||
      !std::all_of(s.begin(), s.end(), [](char c) { return c >= '0' && c <= '9'; }))
    return std::nullopt;
  const std::size_t id = std::stoul(s);
  if (id >= n) return std::nullopt;
  return id;
}

// Constant time in the token's content: the comparison says nothing about a prefix.
bool same_secret(const std::string& a, const std::string& b) {
  unsigned char diff = a.size() == b.size() ? 0 : 1;
  const std::size_t n = std::max(a.size(), b.size());
  for (std::size_t i = 0; i < n; ++i)
    diff |= static_cast<unsigned char>((i < a.size() ? a[i] : 0) ^ (i < b.size() ? b[i] : 0));
  return diff == 0;
}

// The one value of a query parameter, or nullopt; a name given twice is ambiguous.
std::optional<std::string> param(const ApiRequest& req, const std::string& name) {
  const auto [b, e] = req.query.equal_range(name);
  if (b == e) return std::nullopt;
  if (std::next(b) != e) throw BadRequest("parameter '" + name + "' given more than once");
  return b->second;
}

void only_params(const ApiRequest& req, const std::vector<std::string>& known,
                 const std::string& what) {
  for (const auto& [k, v] : req.query)
    if (std::find(known.begin(), known.end(), k) == known.end())
      throw BadRequest("unknown parameter '" + k + "': " + what);
}

double finite_number(const std::string& name, const std::string& text) {
  char* end = nullptr;
  const double x = text.empty() ? NAN : std::strtod(text.c_str(), &end);
  if (text.empty() || end != text.c_str() + text.size() || !std::isfinite(x))
    throw BadRequest("parameter '" + name + "' must be a finite number of seconds, got '" + text +
                     "'");
  return x;
}

// A count parameter (buckets, points): a whole number from lo to hi.
int whole_number(const std::string& name, const std::string& text, int lo, int hi) {
  const bool digits =
      !text.empty() && text.size() <= 6 &&
      std::all_of(text.begin(), text.end(), [](char c) { return c >= '0' && c <= '9'; });
  const int n = digits ? std::stoi(text) : 0;
  if (n < lo || n > hi)
    throw BadRequest("parameter '" + name + "' must be a whole number from " + std::to_string(lo) +
                     " to " + std::to_string(hi) + ", got '" + text.substr(0, 40) + "'");
  return n;
}

// The held-out share parameter: a job's bounds.
double share(const std::string& text) {
  char* end = nullptr;
  const double x = text.empty() ? NAN : std::strtod(text.c_str(), &end);
  if (text.empty() || end != text.c_str() + text.size() ||
      !(x >= kMinJobValidate && x <= kMaxJobValidate)) {
    char b[160];
    std::snprintf(b, sizeof b, "parameter 'validate' must be the held-out share, from %g to %g",
                  kMinJobValidate, kMaxJobValidate);
    throw BadRequest(std::string(b) + ", got '" + text.substr(0, 40) + "'");
  }
  return x;
}

}  // namespace

std::string response_text(const ApiResponse& r) {
  if (!r.content_type.empty()) return r.raw;
  return r.body.dump(-1, ' ', false, json::error_handler_t::replace);
}

std::string response_type(const ApiResponse& r) {
  return r.content_type.empty() ? "application/json" : r.content_type;
}

WorkbenchApi::WorkbenchApi(std::vector<ServedLoop> loops, VerdictFunction verdict,
                           std::string token, ModelOptions models, JobLimits limits,
                           StatusFunction status)
    : loops_(std::move(loops)),
      verdict_(std::move(verdict)),
      token_(std::move(token)),
      model_options_(models),
      status_(std::move(status)),
      jobs_(limits) {
  for (std::size_t i = 0; i < loops_.size(); ++i) {
    cache_.push_back(std::make_unique<Cached>());
    cache_.back()->snapshot = loops_[i].snapshot;
    models_.push_back(loops_[i].history_writer
                          ? std::make_unique<LoopModels>(loops_[i].history_writer)
                          : std::make_unique<LoopModels>(loops_[i].history));
  }
}

std::shared_ptr<const LoopSnapshot> WorkbenchApi::snapshot(std::size_t id) const {
  Cached& c = *cache_[id];
  const auto current = [&c] {
    std::lock_guard<std::mutex> lock(c.data);
    return c.snapshot;
  };
  if (!loops_[id].live) return current();
  const auto fresh = [&c] {
    std::lock_guard<std::mutex> lock(c.data);
    return std::chrono::steady_clock::now() - c.read_at <
           std::chrono::duration<double>(kLiveRefreshS);
  };
  if (fresh()) return current();
  std::lock_guard<std::mutex> one(c.reading);  // others asking meanwhile get its result
  if (fresh()) return current();
  std::shared_ptr<const LoopSnapshot> s = loops_[id].live();
  std::lock_guard<std::mutex> lock(c.data);
  c.read_at = std::chrono::steady_clock::now();
  if (s) c.snapshot = std::move(s);
  return c.snapshot;
}

WorkbenchApi::~WorkbenchApi() {
  jobs_.shutdown();
}

std::string token_cookie_name(const std::string& host) {
  const std::size_t colon = host.rfind(':');
  if (colon == std::string::npos || colon + 1 == host.size() || host.size() - colon > 6 ||
      host.find_first_not_of("0123456789", colon + 1) != std::string::npos)
    return kTokenCookie;
  return std::string(kTokenCookie) + "_" + host.substr(colon + 1);
}

bool WorkbenchApi::authorized(const ApiRequest& req) const {
  if (same_secret(req.authorization, "Bearer " + token_)) return true;
  // The page's own requests carry it in the cookie set when /?token=TOKEN was opened.
  const std::string name = token_cookie_name(req.host) + "=";
  for (std::size_t b = 0; b < req.cookie.size();) {
    std::size_t e = req.cookie.find(';', b);
    if (e == std::string::npos) e = req.cookie.size();
    std::string c = req.cookie.substr(b, e - b);
    c.erase(0, c.find_first_not_of(' '));
    if (c.starts_with(name) && same_secret(c.substr(name.size()), token_)) return true;
    b = e + 1;
  }
  const auto [qb, qe] = req.query.equal_range("token");
  return qb != qe && std::next(qb) == qe && same_secret(qb->second, token_);
}

ApiResponse WorkbenchApi::handle(const ApiRequest& req) const {
  // The token first: without it nobody learns even which paths exist.
  if (!token_.empty() && !authorized(req))
    return error(401,
                 "missing or wrong token: open the address valvediag serve printed (it ends in "
                 "?token=...), or send the header 'Authorization: Bearer TOKEN'");
  if (token_.empty() && !req.host.empty() && !is_loopback_host(req.host))
    return error(403,
                 "this server answers requests addressed to localhost or 127.0.0.1 only, not '" +
                     req.host.substr(0, 100) + "' (serving other names needs --bind ADDR --token)");
  try {
    if (token_.empty() || req.query.count("token") == 0) return route(req);
    ApiRequest plain = req;  // the token is no parameter of the routes
    plain.query.erase("token");
    ApiResponse r = route(plain);
    // Opening the page with ?token=: its scripts and requests then carry it in a cookie that
    // other sites' pages cannot send (SameSite=Strict) and scripts cannot read (HttpOnly).
    if (r.status == 200 && req.path == "/")
      r.set_cookie =
          token_cookie_name(req.host) + "=" + token_ + "; Path=/; HttpOnly; SameSite=Strict";
    return r;
  } catch (const BadRequest& e) {
    return error(400, e.what());
  } catch (const Cancelled&) {
    return error(503, "the server is stopping: the computation was cancelled");
  } catch (const std::exception& e) {
    return error(500, std::string("internal error: ") + e.what());
  } catch (...) {
    return error(500, "internal error");
  }
}

namespace {

// The methods a route takes; anything else is a 405 naming them.
std::optional<ApiResponse> method_check(const ApiRequest& req,
                                        const std::vector<std::string>& allowed) {
  for (const auto& m : allowed)
    if (req.method == m || (m == "GET" && req.method == "HEAD")) return std::nullopt;
  std::string list;
  for (const auto& m : allowed) list += (list.empty() ? "" : ", ") + m;
  return error(405, "method " + req.method.substr(0, 20) + " not allowed on " +
                        req.path.substr(0, 100) + ": it takes " + list);
}

// A step number of the ladder: digits only.
std::optional<std::size_t> step_number(const std::string& s, std::size_t n) {
  return loop_id(s, n);
}

// from, to and buckets of /series and /simulation (points of /phase and /signature), checked
// against the time axis t.
struct Window {
  double from, to;
  int count;  // buckets, or points
};
Window window(const ApiRequest& req, const std::vector<double>& t, const std::string& what,
              bool path = false) {
  const std::string count = path ? "points" : "buckets";
  only_params(req, {"from", "to", count}, what + " takes from, to (s) and " + count);
  if (t.empty()) throw BadRequest("the loop has no samples");
  const auto from_text = param(req, "from"), to_text = param(req, "to"),
             count_text = param(req, count);
  const double from = from_text ? finite_number("from", *from_text) : t.front();
  const double to = to_text ? finite_number("to", *to_text) : t.back();
  if ((from_text || to_text) && !(from < to))
    throw BadRequest("'from' must be below 'to' (the record spans " + std::to_string(t.front()) +
                     " to " + std::to_string(t.back()) + " s)");
  const int n = !count_text ? (path ? kDefaultPathPoints : kDefaultBuckets)
                : path      ? whole_number(count, *count_text, kMinPathPoints, kMaxPathPoints)
                            : whole_number(count, *count_text, 1, kMaxBuckets);
  return {from, to, n};
}

ApiResponse download(std::string body, const std::string& type, const std::string& file) {
  ApiResponse r;
  r.raw = std::move(body);
  r.content_type = type;
  r.attachment = file;
  return r;
}

// A name safe in a Content-Disposition header: letters, digits, '-', '_' and '.'.
std::string file_stem(const std::string& name) {
  std::string s;
  for (char c : name.substr(0, 60))
    s += std::isalnum(static_cast<unsigned char>(c)) || c == '-' || c == '_' || c == '.' ? c : '_';
  return s.empty() ? "loop" : s;
}

}  // namespace

ApiResponse WorkbenchApi::route(const ApiRequest& req) const {
  // The page and its scripts: exact paths only, from the binary.
  for (const auto& f : static_files())
    if (req.path == f.path) {
      if (auto bad = method_check(req, {"GET"})) return *bad;
      only_params(req, {}, "the page takes none");
      ApiResponse r;
      r.raw = std::string(f.body);
      r.content_type = std::string(f.content_type);
      return r;
    }
  const std::vector<std::string> s = segments(req.path);
  const auto not_found = [&] {
    return error(404, "no such endpoint: " + req.path.substr(0, 200) + "; " + kRoutes);
  };
  if (s.size() == 3 && s[0] == "api" && s[1] == "jobs") return job_route(req, s[2]);
  if (s.size() == 2 && s[0] == "api" && s[1] == "status") {
    if (auto bad = method_check(req, {"GET"})) return *bad;
    only_params(req, {}, "GET /api/status takes none");
    json j = status_ ? status_() : json::object();
    j["live"] = static_cast<bool>(status_);
    return {200, std::move(j)};
  }
  if (s.size() < 2 || s[0] != "api" || s[1] != "loops") return not_found();
  if (s.size() == 2) {
    if (auto bad = method_check(req, {"GET"})) return *bad;
    only_params(req, {}, "GET /api/loops takes none");
    return {200, loops_json()};
  }
  static const std::vector<std::string> kLoopRoutes{"series",    "phase",  "verdict", "ladder",
                                                    "diagnosis", "report", "jobs"};
  const bool loop_route_known =
      (s.size() == 4 &&
       std::find(kLoopRoutes.begin(), kLoopRoutes.end(), s[3]) != kLoopRoutes.end()) ||
      (s.size() == 5 && s[3] == "models") ||
      (s.size() == 6 && s[3] == "models" && (s[5] == "simulation" || s[5] == "signature"));
  if (!loop_route_known) return not_found();
  if (auto bad = method_check(req, {s[3] == "jobs" ? "POST" : "GET"})) return *bad;
  const auto id = loop_id(s[2], loops_.size());
  if (!id)
    return error(404, "no loop '" + s[2].substr(0, 40) + "': the loops are numbered 0 to " +
                          std::to_string(static_cast<long>(loops_.size()) - 1) +
                          " (GET /api/loops lists them)");
  return loop_route(req, s, *id);
}

ApiResponse WorkbenchApi::loop_route(const ApiRequest& req, const std::vector<std::string>& s,
                                     std::size_t id) const {
  const ServedLoop& loop = loops_[id];
  const LoopModels& models = *models_[id];
  if (s[3] == "jobs") return submit(req, id);
  const std::shared_ptr<const LoopSnapshot> snap = snapshot(id);
  if (s[3] == "verdict") {
    only_params(req, {}, "GET /api/loops/{id}/verdict takes none");
    return {200, verdict_json(id)};
  }
  if (s[3] == "ladder") {
    only_params(req, {}, "GET /api/loops/{id}/ladder takes none");
    json j = ladder_json(models);
    j["id"] = id;
    return {200, std::move(j)};
  }
  if (s[3] == "diagnosis") {
    only_params(req, {}, "GET /api/loops/{id}/diagnosis takes none");
    const auto d = models.diagnosis();
    if (!d)
      return error(404, "loop " + std::to_string(id) + " has no diagnosis yet: POST /api/loops/" +
                            std::to_string(id) + "/jobs with {\"action\":\"diagnose\"}");
    json j = d->json;
    j["id"] = id;
    return {200, std::move(j)};
  }
  if (s[3] == "report") {
    only_params(req, {}, "GET /api/loops/{id}/report takes none");
    if (!models.last())
      return error(404, "loop " + std::to_string(id) +
                            " has no model yet: fit one first (POST /api/loops/" +
                            std::to_string(id) + "/jobs with {\"action\":\"diagnose\"})");
    const std::string verdict = verdict_json(id).value("verdict", std::string());
    return download(report_html(models, loop.name, verdict), "text/html; charset=utf-8",
                    file_stem(loop.name) + "-report.html");
  }
  if (s[3] == "models") {
    const auto steps = models.steps();
    const auto n = step_number(s[4], steps.size());
    if (!n)
      return error(404, "no model '" + s[4].substr(0, 40) + "' of loop " + std::to_string(id) +
                            ": its ladder has " + std::to_string(steps.size()) +
                            " step(s), numbered from 0 (GET /api/loops/" + std::to_string(id) +
                            "/ladder)");
    const LoopData& d = *steps[*n]->data;  // the data the step was fitted to
    if (s.size() == 6 && s[5] == "signature") {
      const ModelStep& step = *steps[*n];
      if (!has_valve_effect(step.fit.spec) || step.fit.x_hat.size() != d.size())
        return error(404, "step " + std::to_string(*n) + "'s model, " + step.entry.model +
                              ", has no valve effect: its valve position is OP itself, so it has "
                              "no signature (a model with stiction, deadband, preisach, "
                              "saturation, characteristic or actuator-lag has)");
      const Window w = window(req, d.t, "signature", true);
      json j = signature_json(step, d, w.from, w.to, w.count);
      j["id"] = id;
      j["step"] = *n;
      return {200, std::move(j)};
    }
    if (s.size() == 6) {
      const Window w = window(req, d.t, "simulation");
      json j = simulation_json(*steps[*n], d, w.from, w.to, w.count);
      j["id"] = id;
      j["step"] = *n;
      return {200, std::move(j)};
    }
    only_params(req, {}, "GET /api/loops/{id}/models/{n} takes none");
    return download(model_json(*steps[*n], d).dump(2) + "\n", "application/json",
                    file_stem(loop.name) + "-model-" + std::to_string(*n) + ".json");
  }
  if (s[3] == "phase") {
    // On the part the models are fitted to, with their split: the held-out samples flagged (the
    // last `validate` share, the server's by default).
    const LoopData& d = snap->model_data();
    if (d.t.empty() || !d.has_pv())
      return error(404, "loop " + s[2] + " has no PV samples to plot against OP");
    only_params(req, {"from", "to", "points", "validate"},
                "phase takes from, to (s), points and validate (the held-out share)");
    ModelOptions mo = model_options_;
    if (const auto v = param(req, "validate")) mo.validate = share(*v);
    ApiRequest rest = req;
    rest.query.erase("validate");
    const Window w = window(rest, d.t, "phase", true);
    const std::size_t split = mo.estimation_end(d.size());
    json j = decimated_path(d.t, {{"op", &d.op}, {"pv", &d.pv}}, w.from, w.to, w.count, split);
    j["estimation_end_s"] = split < d.t.size() ? json(d.t[split]) : json();
    j["id"] = id;
    return {200, std::move(j)};
  }
  const LoopData& d = snap->data;
  if (d.t.empty())
    return error(404, "loop " + s[2] + " has no samples" +
                          (loop.live ? " recorded yet: ask again in a moment" : ""));
  const Window w = window(req, d.t, "series");
  json j = decimated_series(d, w.from, w.to, w.count);  // no sample in range: invalid_argument
  j["id"] = id;
  return {200, std::move(j)};
}

ApiResponse WorkbenchApi::submit(const ApiRequest& req, std::size_t id) const {
  only_params(req, {}, "POST /api/loops/{id}/jobs takes a JSON body, no parameters");
  // JSON only: a form another site's page posts (text/plain, no preflight) is refused.
  if (!req.content_type.starts_with("application/json"))
    return error(415, "send the job as JSON with the header 'Content-Type: application/json'");
  if (req.body.size() > kMaxBody)
    return error(413, "the body is " + std::to_string(req.body.size()) +
                          " bytes; a job takes at "
                          "most " +
                          std::to_string(kMaxBody));
  JobRequest jr;
  try {
    jr = parse_job_request(json::parse(req.body));
  } catch (const json::parse_error& e) {
    throw BadRequest(std::string("the body is not JSON (") + e.what() +
                     "): send e.g. {\"action\":\"diagnose\"}");
  } catch (const std::invalid_argument& e) {
    throw BadRequest(e.what());
  }
  json info = jr.info();
  info["loop"] = id;
  LoopModels* models = models_[id].get();
  std::mutex* busy = &cache_[id]->jobs;
  const ModelOptions opt = options_of(id);
  const auto job = jobs_.submit(info, [=, this](JobControl& c) {
    // One job per loop at a time: each starts from the model the one before left.
    std::unique_lock<std::mutex> lock(*busy, std::defer_lock);
    while (!lock.try_lock()) {
      throw_if_cancelled(c.cancel_flag());
      c.report(0.0, "waiting for the loop's other job");
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    // The data as it is when the job starts: a live loop's recording so far.
    const std::shared_ptr<const LoopSnapshot> snap = snapshot(id);
    return run_job(jr, std::shared_ptr<const LoopData>(snap, &snap->model_data()), *models, opt, c);
  });
  if (!job)
    return error(503, "the job queue is full (" + std::to_string(jobs_.max_queued()) +
                          " waiting): wait for a job to finish, or cancel one with "
                          "DELETE /api/jobs/{id}");
  json j = *jobs_.status(*job);
  j["job"] = *job;
  j["url"] = "/api/jobs/" + *job;
  return {202, std::move(j)};
}

ApiResponse WorkbenchApi::job_route(const ApiRequest& req, const std::string& id) const {
  if (auto bad = method_check(req, {"GET", "DELETE"})) return *bad;
  only_params(req, {}, "/api/jobs/{id} takes none");
  const auto st = req.method == "DELETE" ? jobs_.cancel(id) : jobs_.status(id);
  if (!st)
    return error(404, "no job '" + id.substr(0, 40) +
                          "': unknown, or finished long ago and forgotten (POST "
                          "/api/loops/{id}/jobs starts one)");
  return {200, *st};
}

json WorkbenchApi::loops_json() const {
  json list = json::array();
  for (std::size_t i = 0; i < loops_.size(); ++i) {
    const std::shared_ptr<const LoopSnapshot> snap = snapshot(i);
    const LoopData& d = snap->data;
    const LoopData& m = snap->model_data();
    json signals = json::array({"op"});
    if (d.has_pv()) signals.push_back("pv");
    if (d.has_sp()) signals.push_back("sp");
    const double start = d.t.empty() ? NAN : d.t.front();
    json clock;  // the stamps' own clock, zone unknown (a historian's local time)
    if (std::isfinite(d.clock_at_zero_s) && std::isfinite(start))
      clock = utc_text(static_cast<std::time_t>(std::floor(d.clock_at_zero_s + start)),
                       "%Y-%m-%d %H:%M:%S");
    json verdict;
    {
      std::lock_guard<std::mutex> lock(cache_[i]->value);
      if (cache_[i]->verdict) verdict = (*cache_[i]->verdict)["verdict"];
    }
    list.push_back({{"id", i},
                    {"name", loops_[i].name},
                    {"source", d.source},
                    {"samples", d.size()},
                    {"sample_period_s", json_number(d.sample_period())},
                    {"start_s", json_number(start)},
                    {"end_s", json_number(d.t.empty() ? NAN : d.t.back())},
                    {"start_clock", clock},
                    {"signals", signals},
                    {"verdict", verdict},
                    {"analysed_start_s", json_number(m.t.empty() ? NAN : m.t.front())},
                    {"validate", model_options_.validate},
                    {"live", static_cast<bool>(loops_[i].live)}});
  }
  return json{{"loops", list}};
}

ModelOptions WorkbenchApi::options_of(std::size_t id) const {
  ModelOptions o = model_options_;
  if (loops_[id].op_range) o.range = *loops_[id].op_range;
  return o;
}

json WorkbenchApi::verdict_json(std::size_t id) const {
  Cached& c = *cache_[id];
  std::lock_guard<std::mutex> once(c.compute);
  const std::shared_ptr<const LoopSnapshot> snap = snapshot(id);
  std::optional<json> have;
  {
    std::lock_guard<std::mutex> lock(c.value);
    if (c.verdict_of == snap) have = c.verdict;  // a live loop's grown data is judged again
  }
  const bool cached = have.has_value();
  double seconds = 0.0;
  if (!have) {
    // Computed once per version of the data, on the first request: a fit takes seconds.
    const auto t0 = std::chrono::steady_clock::now();
    have = verdict_(snap->data, options_of(id).range);
    seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    std::lock_guard<std::mutex> lock(c.value);
    c.verdict = have;
    c.verdict_of = snap;
  }
  json j = std::move(*have);
  j["id"] = id;
  j["name"] = loops_[id].name;
  j["cached"] = cached;
  j["seconds"] = seconds;
  j["samples"] = snap->data.size();  // the data judged (a live loop's grows)
  return j;
}

json decimated_series(const LoopData& d, double from, double to, int buckets) {
  std::vector<Column> cols{{"op", &d.op}};
  if (d.has_pv()) cols.push_back({"pv", &d.pv});
  if (d.has_sp()) cols.push_back({"sp", &d.sp});
  return decimated_columns(d.t, cols, from, to, buckets);
}

namespace {

// The samples [first, first + count) of time axis tt within [from, to] s; none: a bad request
// naming what the axis (`what`) spans.
std::pair<std::size_t, std::size_t> window_of(const std::vector<double>& tt, double from, double to,
                                              const char* what) {
  const auto b = std::lower_bound(tt.begin(), tt.end(), from);
  const auto e = std::upper_bound(tt.begin(), tt.end(), to);
  if (b >= e)
    throw BadRequest("no sample between from=" + std::to_string(from) +
                     " and to=" + std::to_string(to) + " s (" + what + " spans " +
                     (tt.empty()
                          ? std::string("nothing")
                          : std::to_string(tt.front()) + " to " + std::to_string(tt.back())) +
                     " s)");
  return {static_cast<std::size_t>(b - tt.begin()), static_cast<std::size_t>(e - b)};
}

}  // namespace

json decimated_columns(const std::vector<double>& tt, const std::vector<Column>& columns,
                       double from, double to, int buckets) {
  const auto [i0, m] = window_of(tt, from, to, "the record");
  const std::size_t nb = std::min<std::size_t>(static_cast<std::size_t>(std::max(buckets, 1)), m);
  struct Signal {
    Column c;
    json lo = json::array(), hi = json::array();
  };
  std::vector<Signal> sig;
  for (const auto& c : columns) sig.push_back({c});
  json t = json::array(), t_end = json::array(), n = json::array();
  for (std::size_t k = 0; k < nb; ++k) {
    // Buckets of consecutive samples, sizes differing by at most one: none is empty.
    const std::size_t lo = i0 + k * m / nb, hi = i0 + (k + 1) * m / nb;
    t.push_back(tt[lo]);
    t_end.push_back(tt[hi - 1]);
    n.push_back(hi - lo);
    for (auto& s : sig) {
      double mn = NAN, mx = NAN;  // fmin/fmax skip a missing (NaN) sample
      for (std::size_t i = lo; i < hi && i < s.c.x->size(); ++i) {
        mn = std::fmin(mn, (*s.c.x)[i]);
        mx = std::fmax(mx, (*s.c.x)[i]);
      }
      s.lo.push_back(json_number(mn));
      s.hi.push_back(json_number(mx));
    }
  }
  json j{{"from", from},     {"to", to},          {"samples", m},
         {"buckets", nb},    {"t", std::move(t)}, {"t_end", std::move(t_end)},
         {"n", std::move(n)}};
  for (auto& s : sig) j[s.c.name] = {{"min", std::move(s.lo)}, {"max", std::move(s.hi)}};
  return j;
}

json decimated_path(const std::vector<double>& tt, const std::vector<Column>& columns, double from,
                    double to, int points, std::size_t held_out_from) {
  const auto [i0, m] = window_of(tt, from, to, "the part plotted");
  const std::size_t budget = static_cast<std::size_t>(std::max(points, 1));
  const auto value = [](const Column& c, std::size_t i) {
    return i < c.x->size() ? (*c.x)[i] : NAN;
  };
  std::vector<std::size_t> keep;
  if (m <= budget) {
    for (std::size_t i = i0; i < i0 + m; ++i) keep.push_back(i);
  } else {
    // Each run keeps at most two samples per column, so the answer stays within the budget.
    const std::size_t per_run = 2 * std::max<std::size_t>(columns.size(), 1);
    const std::size_t runs = std::max<std::size_t>(budget / per_run, 1);
    std::vector<std::size_t> run;
    for (std::size_t k = 0; k < runs; ++k) {
      const std::size_t lo = i0 + k * m / runs, hi = i0 + (k + 1) * m / runs;
      run.clear();
      for (const auto& c : columns) {
        std::size_t at_min = hi, at_max = hi;  // hi: no finite sample in the run
        for (std::size_t i = lo; i < hi; ++i) {
          const double x = value(c, i);
          if (!std::isfinite(x)) continue;
          if (at_min == hi || x < value(c, at_min)) at_min = i;
          if (at_max == hi || x > value(c, at_max)) at_max = i;
        }
        if (at_min < hi) run.push_back(at_min);
        if (at_max < hi) run.push_back(at_max);
      }
      std::sort(run.begin(), run.end());
      run.erase(std::unique(run.begin(), run.end()), run.end());
      keep.insert(keep.end(), run.begin(), run.end());
    }
  }
  json t = json::array(), index = json::array(), held = json::array();
  std::vector<json> cols(columns.size(), json::array());
  for (const std::size_t i : keep) {
    t.push_back(tt[i]);
    index.push_back(i);
    held.push_back(i >= held_out_from);
    for (std::size_t c = 0; c < columns.size(); ++c)
      cols[c].push_back(json_number(value(columns[c], i)));
  }
  json j{{"from", from},          {"to", to},          {"samples", m},
         {"points", keep.size()}, {"t", std::move(t)}, {"index", std::move(index)}};
  for (std::size_t c = 0; c < columns.size(); ++c) j[columns[c].name] = std::move(cols[c]);
  j["held_out"] = std::move(held);
  return j;
}

std::string random_token() {
  std::random_device rd;  // /dev/urandom (getrandom) with libstdc++ on Linux
  std::string s;
  char buf[9];
  for (int i = 0; i < 4; ++i) {
    std::snprintf(buf, sizeof buf, "%08x", static_cast<unsigned>(rd()));
    s += buf;
  }
  return s;
}

bool is_loopback(const std::string& a) {
  if (a == "localhost") return true;
  // Parsed, not matched by prefix: "127.0.0.1.example.com" is a name anyone can point anywhere.
  in_addr v4{};
  if (inet_pton(AF_INET, a.c_str(), &v4) == 1)
    return (ntohl(v4.s_addr) >> 24) == 127;  // 127.0.0.0/8
  in6_addr v6{};
  return inet_pton(AF_INET6, a.c_str(), &v6) == 1 && IN6_IS_ADDR_LOOPBACK(&v6);
}

bool is_loopback_host(const std::string& host) {
  std::string h = host;
  if (h.starts_with('[')) {  // [::1]:8080
    const auto close = h.find(']');
    if (close == std::string::npos) return false;
    const std::string rest = h.substr(close + 1);
    if (!rest.empty() && !rest.starts_with(':')) return false;
    h = h.substr(1, close - 1);
  } else if (const auto colon = h.find(':'); colon != std::string::npos && h.rfind(':') == colon) {
    h = h.substr(0, colon);  // name:port (a bare IPv6 address has several colons)
  }
  return is_loopback(h);
}

}  // namespace valvediag::serve
