#include "valvediag/serve/workbench_api.hpp"

#include <arpa/inet.h>
#include <netinet/in.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <random>
#include <stdexcept>
#include <utility>

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
    "the API has GET /api/loops, /api/loops/{id}/series?from=S&to=S&buckets=N and "
    "/api/loops/{id}/verdict";

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

int bucket_count(const std::string& text) {
  const bool digits =
      !text.empty() && text.size() <= 6 &&
      std::all_of(text.begin(), text.end(), [](char c) { return c >= '0' && c <= '9'; });
  const int n = digits ? std::stoi(text) : 0;
  if (n < 1 || n > kMaxBuckets)
    throw BadRequest("parameter 'buckets' must be a whole number from 1 to " +
                     std::to_string(kMaxBuckets) + ", got '" + text + "'");
  return n;
}

json number(double x) {
  return std::isfinite(x) ? json(x) : json();
}

}  // namespace

std::string response_text(const ApiResponse& r) {
  return r.body.dump(-1, ' ', false, json::error_handler_t::replace);
}

WorkbenchApi::WorkbenchApi(std::vector<ServedLoop> loops, VerdictFunction verdict,
                           std::string token)
    : loops_(std::move(loops)), verdict_(std::move(verdict)), token_(std::move(token)) {
  for (std::size_t i = 0; i < loops_.size(); ++i) cache_.push_back(std::make_unique<Cached>());
}

ApiResponse WorkbenchApi::handle(const ApiRequest& req) const {
  // The token first: without it nobody learns even which paths exist.
  if (!token_.empty() && !same_secret(req.authorization, "Bearer " + token_))
    return error(401,
                 "missing or wrong token: send the header 'Authorization: Bearer TOKEN' with "
                 "the token valvediag serve printed at start");
  if (token_.empty() && !req.host.empty() && !is_loopback_host(req.host))
    return error(403,
                 "this server answers requests addressed to localhost or 127.0.0.1 only, not '" +
                     req.host.substr(0, 100) + "' (serving other names needs --bind ADDR --token)");
  try {
    return route(req);
  } catch (const BadRequest& e) {
    return error(400, e.what());
  } catch (const std::exception& e) {
    return error(500, std::string("internal error: ") + e.what());
  } catch (...) {
    return error(500, "internal error");
  }
}

ApiResponse WorkbenchApi::route(const ApiRequest& req) const {
  const std::vector<std::string> s = segments(req.path);
  const bool loops_path = s.size() >= 2 && s[0] == "api" && s[1] == "loops";
  const bool known =
      loops_path && (s.size() == 2 || (s.size() == 4 && (s[3] == "series" || s[3] == "verdict")));
  if (!known) return error(404, "no such endpoint: " + req.path.substr(0, 200) + "; " + kRoutes);
  if (req.method != "GET" && req.method != "HEAD")
    return error(405,
                 "method " + req.method.substr(0, 20) + " not allowed: the API only reads (GET)");
  if (s.size() == 2) {
    only_params(req, {}, "GET /api/loops takes none");
    return {200, loops_json()};
  }
  const auto id = loop_id(s[2], loops_.size());
  if (!id)
    return error(404, "no loop '" + s[2].substr(0, 40) + "': the loops are numbered 0 to " +
                          std::to_string(static_cast<long>(loops_.size()) - 1) +
                          " (GET /api/loops lists them)");
  if (s[3] == "verdict") {
    only_params(req, {}, "GET /api/loops/{id}/verdict takes none");
    return {200, verdict_json(*id)};
  }
  only_params(req, {"from", "to", "buckets"}, "series takes from, to (s) and buckets");
  const LoopData& d = loops_[*id].data;
  if (d.t.empty()) return error(404, "loop " + s[2] + " has no samples");
  const auto from_text = param(req, "from"), to_text = param(req, "to"),
             buckets_text = param(req, "buckets");
  const double from = from_text ? finite_number("from", *from_text) : d.t.front();
  const double to = to_text ? finite_number("to", *to_text) : d.t.back();
  if ((from_text || to_text) && !(from < to))
    throw BadRequest("'from' must be below 'to' (the record spans " + std::to_string(d.t.front()) +
                     " to " + std::to_string(d.t.back()) + " s)");
  const int buckets = buckets_text ? bucket_count(*buckets_text) : kDefaultBuckets;
  json j = decimated_series(d, from, to, buckets);  // no sample in range: invalid_argument
  j["id"] = *id;
  return {200, std::move(j)};
}

json WorkbenchApi::loops_json() const {
  json list = json::array();
  for (std::size_t i = 0; i < loops_.size(); ++i) {
    const LoopData& d = loops_[i].data;
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
                    {"sample_period_s", number(d.sample_period())},
                    {"start_s", number(start)},
                    {"end_s", number(d.t.empty() ? NAN : d.t.back())},
                    {"start_clock", clock},
                    {"signals", signals},
                    {"verdict", verdict}});
  }
  return json{{"loops", list}};
}

json WorkbenchApi::verdict_json(std::size_t id) const {
  Cached& c = *cache_[id];
  std::lock_guard<std::mutex> once(c.compute);
  std::optional<json> have;
  {
    std::lock_guard<std::mutex> lock(c.value);
    have = c.verdict;
  }
  const bool cached = have.has_value();
  double seconds = 0.0;
  if (!have) {
    // Computed once, on the first request: a fit of a long record takes seconds.
    const auto t0 = std::chrono::steady_clock::now();
    have = verdict_(loops_[id].data);
    seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    std::lock_guard<std::mutex> lock(c.value);
    c.verdict = have;
  }
  json j = std::move(*have);
  j["id"] = id;
  j["name"] = loops_[id].name;
  j["cached"] = cached;
  j["seconds"] = seconds;
  return j;
}

json decimated_series(const LoopData& d, double from, double to, int buckets) {
  const auto b = std::lower_bound(d.t.begin(), d.t.end(), from);
  const auto e = std::upper_bound(d.t.begin(), d.t.end(), to);
  if (b >= e)
    throw BadRequest("no sample between from=" + std::to_string(from) +
                     " and to=" + std::to_string(to) + " s (the record spans " +
                     (d.t.empty()
                          ? std::string("nothing")
                          : std::to_string(d.t.front()) + " to " + std::to_string(d.t.back())) +
                     " s)");
  const std::size_t i0 = static_cast<std::size_t>(b - d.t.begin());
  const std::size_t m = static_cast<std::size_t>(e - b);
  const std::size_t nb = std::min<std::size_t>(static_cast<std::size_t>(std::max(buckets, 1)), m);
  struct Signal {
    const char* name;
    const std::vector<double>* x;
    json lo = json::array(), hi = json::array();
  };
  std::vector<Signal> sig;
  sig.push_back({"op", &d.op});
  if (d.has_pv()) sig.push_back({"pv", &d.pv});
  if (d.has_sp()) sig.push_back({"sp", &d.sp});
  json t = json::array(), t_end = json::array(), n = json::array();
  for (std::size_t k = 0; k < nb; ++k) {
    // Buckets of consecutive samples, sizes differing by at most one: none is empty.
    const std::size_t lo = i0 + k * m / nb, hi = i0 + (k + 1) * m / nb;
    t.push_back(d.t[lo]);
    t_end.push_back(d.t[hi - 1]);
    n.push_back(hi - lo);
    for (auto& s : sig) {
      double mn = NAN, mx = NAN;  // fmin/fmax skip a missing (NaN) sample
      for (std::size_t i = lo; i < hi && i < s.x->size(); ++i) {
        mn = std::fmin(mn, (*s.x)[i]);
        mx = std::fmax(mx, (*s.x)[i]);
      }
      s.lo.push_back(number(mn));
      s.hi.push_back(number(mx));
    }
  }
  json j{{"from", from},     {"to", to},          {"samples", m},
         {"buckets", nb},    {"t", std::move(t)}, {"t_end", std::move(t_end)},
         {"n", std::move(n)}};
  for (auto& s : sig) j[s.name] = {{"min", std::move(s.lo)}, {"max", std::move(s.hi)}};
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
