// The workbench's JSON API without sockets: routes, the series' numbers, bounds, the token, the
// verdict's cache, and paths that try to leave the served data.
#include <doctest/doctest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <thread>
#include <tuple>

#include "api_checks.hpp"
#include "valvediag/serve/workbench_api.hpp"

using namespace valvediag;
using namespace valvediag::serve;
using nlohmann::json;
using valvediag::test::check_error;

namespace {

// 25,000 samples (the long loop) with one spike in PV that decimation must keep.
LoopData long_loop() {
  LoopData d;
  d.source = "synthetic";
  for (int i = 0; i < 25000; ++i) {
    d.t.push_back(100.0 + 0.5 * i);
    d.op.push_back(50.0 + 20.0 * std::sin(0.001 * i));
    d.pv.push_back(40.0 + 10.0 * std::sin(0.0013 * i + 1.0) + (i == 12345 ? 500.0 : 0.0));
    d.sp.push_back(i < 10000 ? 40.0 : 45.0);
  }
  return d;
}

LoopData short_loop() {
  LoopData d;
  for (int i = 0; i < 10; ++i) {
    d.t.push_back(i);
    d.op.push_back(i);
    d.pv.push_back(-i);
  }
  d.tag = "FIC101";
  return d;
}

struct Fixture {
  std::atomic<int> calls{0};
  WorkbenchApi api;
  explicit Fixture(std::string token = "")
      : api(
            {{"long", long_loop()}, {"FIC101", short_loop()}},
            [this](const LoopData& d, const OpRange&) {
              ++calls;
              return json{{"verdict", d.size() > 100 ? "stiction" : "not-enough-data"}};
            },
            std::move(token)) {}
  ApiResponse get(const std::string& path, std::multimap<std::string, std::string> q = {},
                  const std::string& auth = "") {
    ApiRequest r;
    r.path = path;
    r.query = std::move(q);
    r.authorization = auth;
    return api.handle(r);
  }
};

}  // namespace

TEST_CASE("GET /api/loops lists the loops it was given") {
  Fixture f;
  const auto r = f.get("/api/loops");
  REQUIRE(r.status == 200);
  const auto& l = r.body["loops"];
  REQUIRE(l.size() == 2);
  CHECK(l[0]["id"] == 0);
  CHECK(l[0]["name"] == "long");
  CHECK(l[0]["samples"] == 25000);
  CHECK(l[0]["sample_period_s"].get<double>() == doctest::Approx(0.5));
  CHECK(l[0]["start_s"].get<double>() == doctest::Approx(100.0));
  CHECK(l[0]["signals"] == json::array({"op", "pv", "sp"}));
  CHECK(l[0]["verdict"].is_null());  // not computed yet
  CHECK(l[1]["name"] == "FIC101");
  CHECK(l[1]["signals"] == json::array({"op", "pv"}));
}

TEST_CASE("series: min and max per bucket are the raw data's over the bucket") {
  Fixture f;
  const LoopData d = long_loop();
  const auto r = f.get("/api/loops/0/series");
  REQUIRE(r.status == 200);
  const json& j = r.body;
  CHECK(j["buckets"] == kDefaultBuckets);
  CHECK(j["samples"] == 25000);
  REQUIRE(j["t"].size() == static_cast<std::size_t>(kDefaultBuckets));
  std::size_t covered = 0;
  for (std::size_t k = 0; k < j["t"].size(); ++k) {
    const double t0 = j["t"][k], t1 = j["t_end"][k];
    const auto b = std::lower_bound(d.t.begin(), d.t.end(), t0) - d.t.begin();
    const auto e = std::upper_bound(d.t.begin(), d.t.end(), t1) - d.t.begin();
    REQUIRE(e - b == j["n"][k].get<long>());
    covered += static_cast<std::size_t>(e - b);
    for (const auto& [name, x] : {std::pair{"op", &d.op}, {"pv", &d.pv}, {"sp", &d.sp}}) {
      const auto [lo, hi] = std::minmax_element(x->begin() + b, x->begin() + e);
      CHECK(j[name]["min"][k].get<double>() == *lo);
      CHECK(j[name]["max"][k].get<double>() == *hi);
      CHECK(j[name]["min"][k].get<double>() <= j[name]["max"][k].get<double>());
    }
  }
  CHECK(covered == 25000);  // every sample in exactly one bucket
  // The one-sample spike survives decimation.
  double top = 0;
  for (const auto& v : j["pv"]["max"]) top = std::max(top, v.get<double>());
  CHECK(top > 500.0);
}

TEST_CASE("series: from, to and buckets") {
  Fixture f;
  auto r = f.get("/api/loops/0/series", {{"from", "200"}, {"to", "300"}, {"buckets", "7"}});
  REQUIRE(r.status == 200);
  CHECK(r.body["samples"] == 201);  // t = 200, 200.5, ..., 300
  CHECK(r.body["buckets"] == 7);
  CHECK(r.body["t"][0].get<double>() == 200.0);
  CHECK(r.body["t_end"][6].get<double>() == 300.0);
  // More buckets than samples: one sample each.
  r = f.get("/api/loops/1/series", {{"buckets", "10000"}});
  REQUIRE(r.status == 200);
  CHECK(r.body["buckets"] == 10);
  CHECK(r.body["pv"]["min"][3].get<double>() == -3.0);
  CHECK(!r.body.contains("sp"));
}

TEST_CASE("series: bad queries are 400 with a message") {
  Fixture f;
  using Q = std::multimap<std::string, std::string>;
  for (const Q& q :
       {Q{{"buckets", "0"}}, Q{{"buckets", "10001"}}, Q{{"buckets", "abc"}}, Q{{"buckets", "-5"}},
        Q{{"buckets", "1.5"}}, Q{{"buckets", ""}}, Q{{"buckets", "99999999999999999999"}},
        Q{{"from", "nan"}}, Q{{"from", "inf"}}, Q{{"to", "1e999"}}, Q{{"from", "12abc"}},
        Q{{"from", ""}}, Q{{"from", "300"}, {"to", "200"}}, Q{{"from", "300"}, {"to", "300"}},
        Q{{"from", "1e9"}}, Q{{"to", "5"}}, Q{{"from", "1"}, {"from", "2"}}, Q{{"path", "/etc"}}}) {
    CAPTURE(q.begin()->first);
    CAPTURE(q.begin()->second);
    check_error(f.get("/api/loops/0/series", q), 400);
  }
  check_error(f.get("/api/loops", {{"x", "1"}}), 400);
}

TEST_CASE(
    "phase: PV against OP as a path in data order, each run's extremes kept, held out flagged") {
  Fixture f;
  const LoopData d = long_loop();
  const auto r = f.get("/api/loops/0/phase");
  REQUIRE(r.status == 200);
  const json& j = r.body;
  CHECK(j["samples"] == 25000);
  const std::size_t n = j["t"].size();
  CHECK(j["points"] == n);
  // Within the budget, and close to it: 2000 / (2 columns x 2 extremes) = 500 runs of 50.
  CHECK(n <= static_cast<std::size_t>(kDefaultPathPoints));
  CHECK(n >= 1000);
  REQUIRE(j["op"].size() == n);
  REQUIRE(j["pv"].size() == n);
  REQUIRE(j["index"].size() == n);
  REQUIRE(j["held_out"].size() == n);
  // The default held-out share, 30 %, by fit_model's rule: sample 17500 on.
  CHECK(j["estimation_end_s"].get<double>() == d.t[17500]);
  std::size_t held = 0;
  for (std::size_t k = 0; k < n; ++k) {
    const std::size_t i = j["index"][k];
    if (k > 0) CHECK(i > j["index"][k - 1].get<std::size_t>());  // data order, no repeats
    CHECK(j["t"][k].get<double>() == d.t[i]);
    CHECK(j["op"][k].get<double>() == d.op[i]);
    CHECK(j["pv"][k].get<double>() == d.pv[i]);
    CHECK(j["held_out"][k] == (i >= 17500));
    held += j["held_out"][k].get<bool>();
  }
  CHECK(held > 0);
  CHECK(held < n);
  // Each of the 500 runs of 50 samples keeps the samples of its OP and PV extremes.
  std::size_t k = 0;
  for (std::size_t run = 0; run < 500; ++run) {
    const std::size_t lo = run * 50, hi = lo + 50;
    const auto [op_lo, op_hi] = std::minmax_element(d.op.begin() + lo, d.op.begin() + hi);
    const auto [pv_lo, pv_hi] = std::minmax_element(d.pv.begin() + lo, d.pv.begin() + hi);
    std::vector<double> op, pv;
    for (; k < n && j["index"][k].get<std::size_t>() < hi; ++k) {
      op.push_back(j["op"][k]);
      pv.push_back(j["pv"][k]);
    }
    REQUIRE(!op.empty());
    REQUIRE(op.size() <= 4);
    CHECK(*std::min_element(op.begin(), op.end()) == *op_lo);
    CHECK(*std::max_element(op.begin(), op.end()) == *op_hi);
    CHECK(*std::min_element(pv.begin(), pv.end()) == *pv_lo);
    CHECK(*std::max_element(pv.begin(), pv.end()) == *pv_hi);
  }
  CHECK(k == n);
  // The one-sample spike stays.
  double top = 0;
  for (const auto& v : j["pv"]) top = std::max(top, v.get<double>());
  CHECK(top > 500.0);
}

TEST_CASE("phase: a window, a smaller budget, and fewer samples than points") {
  Fixture f;
  auto r = f.get("/api/loops/0/phase", {{"from", "200"}, {"to", "300"}});
  REQUIRE(r.status == 200);
  CHECK(r.body["samples"] == 201);  // t = 200, 200.5, ..., 300: all of them, in order
  CHECK(r.body["points"] == 201);
  CHECK(r.body["t"][0].get<double>() == 200.0);
  CHECK(r.body["t"][200].get<double>() == 300.0);
  for (std::size_t k = 0; k < 201; ++k) CHECK(r.body["held_out"][k] == false);
  for (const char* p : {"10", "37", "999"}) {
    CAPTURE(p);
    r = f.get("/api/loops/0/phase", {{"points", p}});
    REQUIRE(r.status == 200);
    CHECK(r.body["points"].get<int>() <= std::stoi(p));
    CHECK(r.body["points"].get<int>() >= 2 * (std::stoi(p) / 4));  // each run's OP min and max
    CHECK(r.body["t"].size() == r.body["points"].get<std::size_t>());
  }
  // Ten samples: every one; the last three (30 %) held out.
  r = f.get("/api/loops/1/phase");
  REQUIRE(r.status == 200);
  CHECK(r.body["points"] == 10);
  CHECK(r.body["pv"][3].get<double>() == -3.0);
  CHECK(r.body["held_out"][6] == false);
  CHECK(r.body["held_out"][7] == true);
  CHECK(r.body["estimation_end_s"].get<double>() == 7.0);
}

TEST_CASE("phase: bad queries are 400 with a message") {
  Fixture f;
  using Q = std::multimap<std::string, std::string>;
  for (const Q& q :
       {Q{{"points", "0"}}, Q{{"points", "9"}}, Q{{"points", "10001"}}, Q{{"points", "abc"}},
        Q{{"points", "-5"}}, Q{{"points", "1.5"}}, Q{{"points", ""}}, Q{{"buckets", "100"}},
        Q{{"from", "nan"}}, Q{{"from", "300"}, {"to", "200"}}, Q{{"from", "1e9"}},
        Q{{"points", "100"}, {"points", "200"}}, Q{{"step", "1"}}}) {
    CAPTURE(q.begin()->first);
    CAPTURE(q.begin()->second);
    check_error(f.get("/api/loops/0/phase", q), 400);
  }
  check_error(f.get("/api/loops/2/phase"), 404);
  check_error(f.get("/api/loops/0/phase/x"), 404);
  check_error(f.get("/api/loops/0/models/0/signature"), 404);  // no model yet
}

TEST_CASE("decimated_path: the budget, each run's extremes in data order, missing samples") {
  std::vector<double> t, a, b;
  for (int i = 0; i < 100; ++i) {
    t.push_back(i);
    a.push_back(i % 10 == 3 ? 5.0 : i % 10 == 7 ? -5.0 : 0.1 * (i % 10));
    b.push_back(i == 55 ? NAN : -0.01 * i);
  }
  // 20 points, 2 columns: 5 runs of 20 samples, each keeping a's and b's extremes.
  const json j = decimated_path(t, {{"a", &a}, {"b", &b}}, 0, 99, 20, 60);
  CHECK(j["samples"] == 100);
  REQUIRE(j["points"].get<int>() <= 20);
  std::vector<int> want;
  for (int run = 0; run < 5; ++run) {
    const int lo = run * 20;
    // a: maximum 5 at lo+3 (first of two), minimum -5 at lo+7; b falls: max at lo, min at lo+19
    for (int i : {lo, lo + 3, lo + 7, lo + 19}) want.push_back(i);
  }
  std::vector<int> got;
  for (const auto& i : j["index"]) got.push_back(i);
  CHECK(got == want);
  for (std::size_t k = 0; k < got.size(); ++k) {
    CHECK(j["t"][k].get<double>() == got[k]);
    CHECK(j["held_out"][k] == (got[k] >= 60));
  }
  // A missing sample is never an extreme; where every sample is missing, null.
  std::vector<double> gap(100, NAN);
  const json g = decimated_path(t, {{"a", &a}, {"gap", &gap}}, 50, 60, 100, 1000);
  CHECK(g["points"] == 11);
  CHECK(g["gap"][0].is_null());
  const json h = decimated_path(t, {{"b", &b}, {"gap", &gap}}, 0, 99, 10, 1000);
  for (const auto& i : h["index"]) CHECK(i != 55);
  CHECK_THROWS_AS(decimated_path(t, {{"a", &a}}, 200, 300, 10, 0), std::invalid_argument);
}

TEST_CASE("unknown paths, bad ids and traversal are 404; other methods 405") {
  Fixture f;
  for (const char* p : {"",
                        "/api",
                        "/api/",
                        "/api/loops/",
                        "/api//loops",
                        "/api/loops/2/series",
                        "/api/loops/-1/series",
                        "/api/loops/01x/verdict",
                        "/api/loops/ 0/series",
                        "/api/loops/99999999999999999999/series",
                        "/api/loops/0/series/",
                        "/api/loops/0/plot",
                        "/api/loops/../../etc/passwd",
                        "/api/loops/0/../../../etc/passwd",
                        "/api/loops/../series",
                        "/../../etc/passwd",
                        "/etc/passwd",
                        "/api/loops/..%2f..%2fetc",
                        "/api/loops/0/series\n",
                        "api/loops"}) {
    CAPTURE(p);
    const auto r = f.get(p);
    check_error(r, 404);
    CHECK(r.body.dump().find("root:") == std::string::npos);
  }
  ApiRequest post;
  post.method = "POST";
  post.path = "/api/loops";
  check_error(f.api.handle(post), 405);
  // A path that is not UTF-8 is echoed without throwing.
  CHECK_NOTHROW((void)response_text(f.get("/api/\xff\xfe")));
}

TEST_CASE("the verdict is computed once and cached, also under concurrent requests") {
  Fixture f;
  std::vector<std::thread> th;
  std::atomic<int> ok{0};
  for (int i = 0; i < 4; ++i)
    th.emplace_back([&] {
      if (f.get("/api/loops/0/verdict").body["verdict"] == "stiction") ++ok;
    });
  for (auto& t : th) t.join();
  CHECK(ok == 4);
  CHECK(f.calls == 1);
  const auto r = f.get("/api/loops/0/verdict");
  CHECK(r.body["cached"] == true);
  CHECK(r.body["name"] == "long");
  CHECK(f.calls == 1);
  CHECK(f.get("/api/loops").body["loops"][0]["verdict"] == "stiction");
  CHECK(f.get("/api/loops/1/verdict").body["verdict"] == "not-enough-data");
  CHECK(f.calls == 2);
}

TEST_CASE("listing the loops does not wait for a verdict being computed") {
  std::atomic<bool> release{false}, started{false};
  WorkbenchApi api({{"x", short_loop()}}, [&](const LoopData&, const OpRange&) {
    started = true;
    for (int i = 0; i < 1000 && !release; ++i)  // bounded: at most 10 s
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    return json{{"verdict", "deadband"}};
  });
  ApiRequest v, l;
  v.path = "/api/loops/0/verdict";
  l.path = "/api/loops";
  std::thread th([&] { CHECK(api.handle(v).body["verdict"] == "deadband"); });
  for (int i = 0; i < 10000 && !started; ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  REQUIRE(started);
  const auto t0 = std::chrono::steady_clock::now();
  const auto r = api.handle(l);
  CHECK(std::chrono::steady_clock::now() - t0 < std::chrono::seconds(2));
  CHECK(r.body["loops"][0]["verdict"].is_null());
  release = true;
  th.join();
  CHECK(api.handle(l).body["loops"][0]["verdict"] == "deadband");
}

// serve --config: each loop is judged on its site's OP span (ServedLoop::op_range), as sweep
// --config judges it; a loop without one on the server's (--op-range).
TEST_CASE("each loop's verdict is given its own OP span, else the server's") {
  std::vector<ServedLoop> loops;
  loops.emplace_back("site-loop", short_loop());
  loops.back().op_range = OpRange{4.0, 20.0};
  loops.emplace_back("file-loop", short_loop());
  ModelOptions mo;
  mo.range = OpRange{-10.0, 110.0};
  WorkbenchApi api(
      std::move(loops),
      [](const LoopData&, const OpRange& r) {
        return json{{"verdict", "no-valve-problem"}, {"lo", r.lo}, {"hi", r.hi}};
      },
      "", mo);
  for (const auto& [id, lo, hi] : {std::tuple{0, 4.0, 20.0}, std::tuple{1, -10.0, 110.0}}) {
    CAPTURE(id);
    ApiRequest r;
    r.path = "/api/loops/" + std::to_string(id) + "/verdict";
    const ApiResponse v = api.handle(r);
    REQUIRE(v.status == 200);
    CHECK(v.body["lo"] == lo);
    CHECK(v.body["hi"] == hi);
  }
}

TEST_CASE("a verdict that fails is a 500 JSON error, and tried again next time") {
  int calls = 0;
  WorkbenchApi api({{"x", short_loop()}}, [&](const LoopData&, const OpRange&) -> json {
    if (++calls == 1) throw std::runtime_error("boom");
    return json{{"verdict", "no-valve-problem"}};
  });
  ApiRequest r;
  r.path = "/api/loops/0/verdict";
  const auto first = api.handle(r);
  check_error(first, 500);
  CHECK(first.body["error"].get<std::string>().find("boom") != std::string::npos);
  CHECK(api.handle(r).body["verdict"] == "no-valve-problem");
}

TEST_CASE("the token: 401 without or with a wrong one, on every path") {
  Fixture f("s3cret");
  check_error(f.get("/api/loops"), 401);
  check_error(f.get("/api/loops", {}, "Bearer wrong"), 401);
  check_error(f.get("/api/loops", {}, "Bearer s3cre"), 401);
  check_error(f.get("/api/loops", {}, "s3cret"), 401);
  check_error(f.get("/no/such/path"), 401);  // paths are not revealed without it
  CHECK(f.get("/api/loops", {}, "Bearer s3cret").status == 200);
  check_error(f.get("/no/such/path", {}, "Bearer s3cret"), 404);
}

TEST_CASE("without a token, only requests addressed to this machine are served") {
  Fixture f;
  ApiRequest r;
  r.path = "/api/loops";
  for (const char* h : {"", "localhost", "localhost:8080", "127.0.0.1:5", "[::1]:8080", "::1"}) {
    r.host = h;
    CAPTURE(r.host);
    CHECK(f.api.handle(r).status == 200);
  }
  // A page whose name was rebound to 127.0.0.1 still sends its own name.
  for (const char* h : {"evil.example:8080", "127.0.0.1.evil.example", "[::1]x", "10.0.0.1"}) {
    r.host = h;
    CAPTURE(r.host);
    check_error(f.api.handle(r), 403);
  }
  // With a token any name may be used: the token is the guard.
  Fixture t("s3cret");
  r.host = "plant-laptop:8080";
  r.authorization = "Bearer s3cret";
  CHECK(t.api.handle(r).status == 200);
}

TEST_CASE("random tokens and loopback addresses") {
  const std::string a = random_token(), b = random_token();
  CHECK(a.size() == 32);
  CHECK(a.find_first_not_of("0123456789abcdef") == std::string::npos);
  CHECK(a != b);
  CHECK(is_loopback("127.0.0.1"));
  CHECK(is_loopback("::1"));
  CHECK(is_loopback("localhost"));
  CHECK(!is_loopback("0.0.0.0"));
  CHECK(!is_loopback("192.168.1.5"));
  CHECK(!is_loopback("::"));
  CHECK(is_loopback("127.1.2.3"));
  CHECK(!is_loopback("127.0.0.1.evil.example"));
  CHECK(!is_loopback("127.0.0.256"));
  CHECK(is_loopback_host("localhost:1"));
  CHECK(!is_loopback_host("[::1"));
}
