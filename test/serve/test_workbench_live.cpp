// The workbench's API for a split moved and a recording that grows, without sockets: a job's own
// held-out share (validate) and its latest seconds (last_s), PV against OP at another split, a
// live loop read again as it grows (the jobs fit the data as it was when they started, each
// model keeps its own), and GET /api/status.
#include <doctest/doctest.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <thread>

#include "api_checks.hpp"
#include "valvediag/serve/workbench_api.hpp"
#include "valvediag/sim/scenarios.hpp"

using namespace valvediag;
using namespace valvediag::serve;
using nlohmann::json;
using valvediag::test::check_error;
using Clock = std::chrono::steady_clock;

namespace {

// The paper's Example 1 loop with He stiction: 1500 samples every 0.5 s, t 0 to 749.5 s.
const LoopData& ex1() {
  static const LoopData d = run_scenario(scenario_by_name("paper-ex1"), 1, 1500);
  return d;
}

// The first n samples of ex1: a recording so far.
LoopData first(std::size_t n) {
  LoopData d = ex1();
  for (auto* v : {&d.t, &d.op, &d.pv, &d.sp, &d.mv})
    if (v->size() > n) v->resize(n);
  return d;
}

ApiRequest request(const std::string& method, const std::string& path,
                   std::multimap<std::string, std::string> query = {},
                   const std::string& body = "") {
  ApiRequest r;
  r.method = method;
  r.path = path;
  r.query = std::move(query);
  r.body = body;
  r.content_type = "application/json";
  return r;
}

json run(const WorkbenchApi& api, const json& body, std::size_t loop = 0) {
  const auto r =
      api.handle(request("POST", "/api/loops/" + std::to_string(loop) + "/jobs", {}, body.dump()));
  REQUIRE_MESSAGE(r.status == 202, r.body.dump());
  const std::string id = r.body["job"];
  const auto end = Clock::now() + std::chrono::seconds(600);
  for (;;) {
    const auto st = api.handle(request("GET", "/api/jobs/" + id));
    REQUIRE(st.status == 200);
    const std::string s = st.body["state"];
    if (s != "queued" && s != "running") return st.body;
    REQUIRE(Clock::now() < end);
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
}

json no_verdict(const LoopData&, const OpRange&) {
  return json{{"verdict", "stiction"}};
}

}  // namespace

TEST_CASE("a job's validate and last_s: the held-out share and the latest seconds it fits") {
  const WorkbenchApi api({{"ex1", ex1()}}, no_verdict);
  // The latest 300 s (601 samples) with a quarter held out: the split at sample 451.
  const json j =
      run(api, {{"action", "fit"}, {"model", "linear"}, {"validate", 0.25}, {"last_s", 300}});
  REQUIRE_MESSAGE(j["state"] == "done", j.dump());
  CHECK(j["validate"] == 0.25);  // the request, as the job shows it
  CHECK(j["last_s"] == 300.0);
  const json& data = j["result"]["data"];
  CHECK(data["samples"] == 601);
  CHECK(data["from_s"] == 449.5);
  CHECK(data["to_s"] == 749.5);
  CHECK(data["validate"] == 0.25);
  const json lad = api.handle(request("GET", "/api/loops/0/ladder")).body;
  REQUIRE(lad["steps"].size() == 1);
  CHECK(lad["steps"][0]["estimation_end_s"] == 449.5 + 0.5 * 451);
  CHECK(lad["steps"][0]["data"] == data);
  // The model's simulation and its download are of those samples, not of the whole loop.
  const auto sim = api.handle(request("GET", "/api/loops/0/models/0/simulation"));
  REQUIRE(sim.status == 200);
  CHECK(sim.body["samples"] == 601);
  CHECK(sim.body["estimation_end_s"] == 449.5 + 0.5 * 451);
  CHECK(api.handle(request("GET", "/api/loops/0/models/0/simulation", {{"to", "400"}})).status ==
        400);  // before the part fitted: no sample
  // Without them: the server's share (0.3) of the whole loop.
  const json all = run(api, {{"action", "fit"}, {"model", "linear"}});
  CHECK(all["result"]["data"]["samples"] == 1500);
  CHECK(all["result"]["data"]["validate"] == 0.3);
  CHECK(api.handle(request("GET", "/api/loops/0/ladder")).body["steps"][1]["estimation_end_s"] ==
        0.5 * 1050);
  // A diagnosis reports the samples it diagnosed too; last_s longer than the record: all of it.
  const json dg = run(api, {{"action", "diagnose"}, {"validate", 0.5}, {"last_s", 1e6}});
  REQUIRE_MESSAGE(dg["state"] == "done", dg.dump());
  CHECK(dg["result"]["data"]["samples"] == 1500);
  CHECK(dg["result"]["data"]["validate"] == 0.5);
  CHECK(api.handle(request("GET", "/api/loops/0/diagnosis")).body["data"]["validate"] == 0.5);
}

TEST_CASE("a job's validate outside 0.05..0.6, or a bad last_s, is a 400 naming the value") {
  const WorkbenchApi api({{"ex1", ex1()}}, no_verdict);
  const auto post = [&](const std::string& body) {
    return api.handle(request("POST", "/api/loops/0/jobs", {}, body));
  };
  for (const std::string v : {"0.7", "0.04", "0", "-0.3", "1", "\"0.3\"", "null", "true"}) {
    const auto r = post(R"({"action":"fit","model":"linear","validate":)" + v + "}");
    check_error(r, 400);
    const std::string e = r.body["error"];
    CHECK_MESSAGE(e.find("got " + v) != std::string::npos, e);
    CHECK(e.find("0.05 to 0.6") != std::string::npos);
  }
  for (const std::string v : {"0", "-5", "\"60\"", "null"}) {
    const auto r = post(R"({"action":"diagnose","last_s":)" + v + "}");
    check_error(r, 400);
    CHECK(r.body["error"].get<std::string>().find("got " + v) != std::string::npos);
  }
  // The bounds themselves are taken.
  CHECK(post(R"({"action":"fit","model":"linear","validate":0.05})").status == 202);
  CHECK(post(R"({"action":"fit","model":"linear","validate":0.6})").status == 202);
  // A last part too short to fit fails the job, saying why.
  const json short_part = run(api, {{"action", "fit"}, {"model", "linear"}, {"last_s", 10}});
  CHECK(short_part["state"] == "failed");
  CHECK(short_part["error"].get<std::string>().find("200") != std::string::npos);
}

TEST_CASE("phase: validate moves the held-out flags; outside 0.05..0.6 it is a 400") {
  const WorkbenchApi api({{"ex1", ex1()}}, no_verdict);
  const auto r = api.handle(request("GET", "/api/loops/0/phase", {{"validate", "0.5"}}));
  REQUIRE(r.status == 200);
  CHECK(r.body["estimation_end_s"] == 0.5 * 750);
  for (std::size_t k = 0; k < r.body["index"].size(); ++k)
    CHECK(r.body["held_out"][k] == (r.body["index"][k].get<std::size_t>() >= 750));
  CHECK(api.handle(request("GET", "/api/loops/0/phase")).body["estimation_end_s"] == 0.5 * 1050);
  for (const std::string v : {"0.9", "0.01", "x", ""}) {
    const auto bad = api.handle(request("GET", "/api/loops/0/phase", {{"validate", v}}));
    check_error(bad, 400);
    CHECK(bad.body["error"].get<std::string>().find("'" + v + "'") != std::string::npos);
  }
  check_error(api.handle(request("GET", "/api/loops/0/series", {{"validate", "0.3"}})), 400);
}

TEST_CASE("a live loop is read again as it grows; each job fits the data of its start") {
  // The recording so far: 400 samples, then 800, then 1200 (read at most every kLiveRefreshS).
  std::atomic<std::size_t> recorded{400};
  std::atomic<int> reads{0};
  ServedLoop loop("live", LoopData{});
  loop.live = [&]() -> std::shared_ptr<const LoopSnapshot> {
    ++reads;
    return std::make_shared<const LoopSnapshot>(LoopSnapshot{first(recorded), std::nullopt});
  };
  std::atomic<int> verdicts{0};
  std::vector<ServedLoop> loops;
  loops.push_back(std::move(loop));
  const WorkbenchApi api(std::move(loops), [&](const LoopData& d, const OpRange&) {
    ++verdicts;
    return json{{"verdict", "stiction"}, {"judged", d.size()}};
  });
  const auto listed = [&] { return api.handle(request("GET", "/api/loops")).body["loops"][0]; };
  json l = listed();
  CHECK(l["live"] == true);
  CHECK(l["samples"] == 400);
  CHECK(l["end_s"] == 199.5);
  // Many requests within the refresh interval read the recording once.
  const int before = reads;
  for (int i = 0; i < 20; ++i) (void)api.handle(request("GET", "/api/loops/0/series"));
  CHECK(reads - before <= 1);
  const json fit400 = run(api, {{"action", "fit"}, {"model", "linear"}});
  CHECK(fit400["result"]["data"]["samples"] == 400);
  auto v = api.handle(request("GET", "/api/loops/0/verdict")).body;
  CHECK(v["judged"] == 400);
  CHECK(v["samples"] == 400);

  recorded = 800;
  std::this_thread::sleep_for(std::chrono::duration<double>(kLiveRefreshS * 1.2));
  l = listed();
  CHECK(l["samples"] == 800);
  const auto series = api.handle(request("GET", "/api/loops/0/series", {{"buckets", "4"}}));
  CHECK(series.body["samples"] == 800);
  CHECK(series.body["t_end"][3] == 399.5);
  // The verdict judges the grown data again; the latest 100 s of it are fitted by a job.
  v = api.handle(request("GET", "/api/loops/0/verdict")).body;
  CHECK(v["judged"] == 800);
  CHECK(v["cached"] == false);
  CHECK(verdicts == 2);
  const json last = run(api, {{"action", "fit"}, {"model", "linear"}, {"last_s", 150}});
  REQUIRE_MESSAGE(last["state"] == "done", last.dump());
  CHECK(last["result"]["data"]["samples"] == 301);
  CHECK(last["result"]["data"]["from_s"] == 249.5);
  CHECK(last["result"]["data"]["to_s"] == 399.5);

  // It grows on: the models fitted before keep their own data.
  recorded = 1200;
  std::this_thread::sleep_for(std::chrono::duration<double>(kLiveRefreshS * 1.2));
  CHECK(listed()["samples"] == 1200);
  CHECK(api.handle(request("GET", "/api/loops/0/models/0/simulation")).body["samples"] == 400);
  CHECK(api.handle(request("GET", "/api/loops/0/models/1/simulation")).body["samples"] == 301);
  const auto lad = api.handle(request("GET", "/api/loops/0/ladder")).body["steps"];
  CHECK(lad[0]["estimation_end_s"] == 0.5 * 280);
  CHECK(lad[1]["estimation_end_s"] == 249.5 + 0.5 * std::llround(301 * 0.7));
}

TEST_CASE("a live loop with nothing recorded yet: listed with 0 samples, its series a 404") {
  std::vector<ServedLoop> loops;
  loops.emplace_back("empty", LoopData{});
  loops.back().live = [] { return std::shared_ptr<const LoopSnapshot>(); };
  const WorkbenchApi api(std::move(loops), no_verdict);
  CHECK(api.handle(request("GET", "/api/loops")).body["loops"][0]["samples"] == 0);
  const auto r = api.handle(request("GET", "/api/loops/0/series"));
  check_error(r, 404);
  CHECK(r.body["error"].get<std::string>().find("recorded yet") != std::string::npos);
  // A job on it fails, saying it needs more samples; the server goes on.
  const json j = run(api, {{"action", "diagnose"}});
  CHECK(j["state"] == "failed");
  CHECK(api.handle(request("GET", "/api/loops")).status == 200);
}

TEST_CASE("GET /api/status: the recorder's counters with --config; {live: false} without") {
  const WorkbenchApi files({{"ex1", ex1()}}, no_verdict);
  const auto plain = files.handle(request("GET", "/api/status"));
  CHECK(plain.status == 200);
  CHECK(plain.body == json{{"live", false}});
  const WorkbenchApi live({{"ex1", ex1()}}, no_verdict, "", {}, {}, [] {
    return json{{"recording", true}, {"run", 3}};
  });
  const auto st = live.handle(request("GET", "/api/status"));
  CHECK(st.body == json{{"live", true}, {"recording", true}, {"run", 3}});
  check_error(live.handle(request("POST", "/api/status")), 405);
  check_error(live.handle(request("GET", "/api/status", {{"x", "1"}})), 400);
  check_error(live.handle(request("GET", "/api/status/1")), 404);
}
