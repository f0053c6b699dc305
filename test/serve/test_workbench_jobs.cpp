// The workbench's model jobs and page without sockets: the job queue's bounds and cancellation,
// the fits' cancel hook, the jobs API on a simulated sticky loop (diagnose finds the hidden
// stiction, adding it raises the validation fitness), the ladder, model and simulation
// downloads, the report, bad bodies, and the embedded page with its content types and token.
#include <doctest/doctest.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <thread>

#include "../common/sanitized.hpp"
#include "api_checks.hpp"
#include "valvediag/core/identification.hpp"
#include "valvediag/model/model_fit.hpp"
#include "valvediag/report/model_history.hpp"
#include "valvediag/serve/workbench_api.hpp"
#include "valvediag/sim/scenarios.hpp"

using namespace valvediag;
using namespace valvediag::serve;
using nlohmann::json;
using valvediag::test::check_error;
using Clock = std::chrono::steady_clock;
using valvediag::test::kSanitizedBuild;

namespace {

// Waits (bounded) until the job leaves `queued`/`running`, or until `until` holds.
json wait_job(JobQueue& q, const std::string& id, double limit_s = 600.0) {
  const auto end = Clock::now() + std::chrono::duration<double>(limit_s);
  for (;;) {
    const auto st = q.status(id);
    REQUIRE(st);
    const std::string s = (*st)["state"];
    if ((s != "queued" && s != "running") || Clock::now() > end) return *st;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
}

// A job that runs until cancelled (at most 20 s).
JobWork until_cancelled(std::atomic<bool>* started = nullptr) {
  return [started](JobControl& c) -> json {
    if (started) *started = true;
    for (int i = 0; i < 2000; ++i) {
      throw_if_cancelled(c.cancel_flag());
      c.report(i / 2000.0, "waiting");
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    return json{{"finished", true}};
  };
}

const LoopData& sticky_loop() {
  // The paper's Example 1: He stiction fs 8.4, fd 3.52 hidden in a PI loop.
  static const LoopData d = run_scenario(scenario_by_name("paper-ex1"), 1, 1500);
  return d;
}

struct Api {
  WorkbenchApi api;
  explicit Api(std::string token = "", JobLimits limits = {}, std::size_t loops = 1)
      : api(
            make_loops(loops),
            [](const LoopData&, const OpRange&) {
              return json{{"verdict", "stiction"}};
            },
            std::move(token), ModelOptions{}, limits) {}
  static std::vector<ServedLoop> make_loops(std::size_t n) {
    std::vector<ServedLoop> v;
    for (std::size_t i = 0; i < n; ++i) v.emplace_back("ex1-" + std::to_string(i), sticky_loop());
    return v;
  }
  ApiResponse req(const std::string& method, const std::string& path, const std::string& body = "",
                  const std::string& type = "application/json") const {
    ApiRequest r;
    r.method = method;
    r.path = path.substr(0, path.find('?'));
    // The query as the HTTP layer hands it over: name=value pairs.
    for (std::size_t b = path.find('?'); b != std::string::npos;) {
      const std::size_t e = path.find('&', b + 1);
      const std::string kv = path.substr(b + 1, e == std::string::npos ? e : e - b - 1);
      r.query.emplace(kv.substr(0, kv.find('=')),
                      kv.find('=') == std::string::npos ? "" : kv.substr(kv.find('=') + 1));
      b = e;
    }
    r.body = body;
    r.content_type = type;
    return api.handle(r);
  }
  ApiResponse get(const std::string& path) const { return req("GET", path); }
  // Posts a job and returns its id (the request must be accepted).
  std::string post(const json& body, std::size_t loop = 0) const {
    const auto r = req("POST", "/api/loops/" + std::to_string(loop) + "/jobs", body.dump());
    REQUIRE_MESSAGE(r.status == 202, r.body.dump());
    return r.body["job"];
  }
  // The phases a running job reported, as the polls below saw them.
  mutable std::vector<std::string> phases;
  json wait(const std::string& id, double limit_s = 900.0) const {
    const auto end = Clock::now() + std::chrono::duration<double>(limit_s);
    phases.clear();
    for (;;) {
      const auto r = get("/api/jobs/" + id);
      REQUIRE(r.status == 200);
      const std::string s = r.body["state"];
      if (s == "running" && r.body.contains("phase") && r.body["phase"].is_string())
        phases.push_back(r.body["phase"]);
      if (s != "queued" && s != "running") return r.body;
      REQUIRE_MESSAGE(Clock::now() < end, "job " << id << " still " << s);
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
  }
};

}  // namespace

TEST_CASE("job queue: results, failures, unknown ids, and finished jobs forgotten in order") {
  JobQueue q({2, 8, 3});
  CHECK(q.workers() == 2);
  const auto ok = q.submit({{"action", "x"}}, [](JobControl& c) {
    c.report(0.5, "half");
    return json{{"answer", 42}};
  });
  const auto bad = q.submit({}, [](JobControl&) -> json { throw std::invalid_argument("no way"); });
  REQUIRE(ok);
  REQUIRE(bad);
  const json a = wait_job(q, *ok), b = wait_job(q, *bad);
  CHECK(a["state"] == "done");
  CHECK(a["action"] == "x");
  CHECK(a["progress"] == 1.0);
  CHECK(a["result"]["answer"] == 42);
  CHECK(b["state"] == "failed");
  CHECK(b["error"] == "no way");
  CHECK(!q.status("999"));
  CHECK(!q.cancel("999"));
  CHECK(!q.status("../1"));
  // Only the last 3 finished jobs are kept: memory stays bounded however long it serves.
  for (int i = 0; i < 4; ++i) {
    const auto id = q.submit({}, [](JobControl&) { return json(); });
    REQUIRE(id);
    wait_job(q, *id);
  }
  CHECK(!q.status(*ok));
}

TEST_CASE("job queue: bounded, and a queued or running job is cancelled") {
  JobQueue q({1, 2, 100});
  std::atomic<bool> started{false};
  const auto running = q.submit({}, until_cancelled(&started));
  REQUIRE(running);
  for (int i = 0; i < 5000 && !started; ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  REQUIRE(started);
  const auto q1 = q.submit({}, until_cancelled()), q2 = q.submit({}, until_cancelled());
  REQUIRE(q1);
  REQUIRE(q2);
  CHECK(!q.submit({}, until_cancelled()));  // one running, two waiting: full
  CHECK((*q.status(*q1))["state"] == "queued");
  // A queued job is cancelled at once, which frees its place.
  CHECK((*q.cancel(*q1))["state"] == "cancelled");
  CHECK(q.submit({}, until_cancelled()));
  // A running one stops at its next check.
  const auto t0 = Clock::now();
  CHECK((*q.status(*running))["state"] == "running");
  q.cancel(*running);
  const json r = wait_job(q, *running, 30.0);
  CHECK(r["state"] == "cancelled");
  CHECK(Clock::now() - t0 < std::chrono::seconds(5));
  // A finished job stays as it ended.
  CHECK((*q.cancel(*running))["state"] == "cancelled");
  q.shutdown();  // cancels the rest and joins
  CHECK((*q.status(*q2))["state"] == "cancelled");
}

TEST_CASE("the fits' cancel hook: a set flag stops fit_model and identify") {
  const LoopData& d = sticky_loop();
  std::atomic<bool> cancel{true};
  ModelFitOptions mo;
  mo.cancel = &cancel;
  CHECK_THROWS_AS(fit_model(d.op, d.pv, d.sample_period(), parse_model_spec("stiction"), mo),
                  Cancelled);
  FitOptions fo;
  fo.L_max = 4;
  fo.cancel = &cancel;
  CHECK_THROWS_AS(identify(d.op, d.pv, fo), Cancelled);
  // Set while the search runs: the fit ends at its next evaluation.
  cancel = false;
  std::thread later([&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    cancel = true;
  });
  const auto t0 = Clock::now();
  CHECK_THROWS_AS(fit_model(d.op, d.pv, d.sample_period(),
                            parse_model_spec("stiction+deadband+saturation"), mo),
                  Cancelled);
  later.join();
  CHECK(Clock::now() - t0 < std::chrono::seconds(kSanitizedBuild ? 60 : 5));
}

TEST_CASE("jobs: diagnose finds the hidden stiction, adding it raises the validation fitness") {
  Api a;
  check_error(a.get("/api/loops/0/diagnosis"), 404);
  check_error(a.get("/api/loops/0/report"), 404);
  CHECK(a.get("/api/loops/0/ladder").body["steps"].empty());

  const json d = a.wait(a.post({{"action", "diagnose"}}));
  REQUIRE_MESSAGE(d["state"] == "done", d.dump());
  CHECK(d["result"]["model"] == "linear");
  CHECK(d["result"]["findings"][0]["effect"] == "stiction");
  CHECK(d["result"]["steps_added"] == 1);
  const json dg = a.get("/api/loops/0/diagnosis").body;
  CHECK(dg["findings"][0]["effect"] == "stiction");
  CHECK(dg["findings"][0]["supported"] == true);
  CHECK(!dg.contains("verdict"));  // the loop's verdict is /verdict's alone

  const json add = a.wait(a.post({{"action", "add"}, {"effect", "stiction"}}));
  REQUIRE_MESSAGE(add["state"] == "done", add.dump());
  CHECK(add["result"]["model"] == "stiction");
  CHECK(add["result"]["step"] == 1);
  // The fit reported its valve search while it ran, not only its start and end.
  CHECK(std::any_of(a.phases.begin(), a.phases.end(), [](const std::string& p) {
    return p.find("fitting stiction: valve parameters") != std::string::npos;
  }));

  const json lad = a.get("/api/loops/0/ladder").body;
  REQUIRE(lad["steps"].size() == 2);
  const json& s0 = lad["steps"][0];
  const json& s1 = lad["steps"][1];
  CHECK(s0["model"] == "linear");
  CHECK(s1["model"] == "stiction");
  CHECK(s1["action"] == "add stiction");
  // The hidden effect explains what the linear model left: tens of points on held-out data.
  CHECK(s1["validation_fitness_percent"].get<double>() >
        s0["validation_fitness_percent"].get<double>() + 20.0);
  CHECK(s1["validation_fitness_percent"].get<double>() > 90.0);
  CHECK(s1["validation_fitness_change"].get<double>() ==
        doctest::Approx(s1["validation_fitness_percent"].get<double>() -
                        s0["validation_fitness_percent"].get<double>()));
  CHECK(s1["parameters"]["stiction.fs"].get<double>() == doctest::Approx(8.4).epsilon(0.1));

  // The model as fit --json writes it, as a download.
  const auto m = a.get("/api/loops/0/models/1");
  REQUIRE(m.status == 200);
  CHECK(m.content_type == "application/json");
  CHECK(m.attachment == "ex1-0-model-1.json");
  const json mj = json::parse(m.raw);
  CHECK(mj["model"] == "stiction");
  CHECK(mj["validation_fitness_percent"].get<double>() ==
        doctest::Approx(s1["validation_fitness_percent"].get<double>()));
  CHECK(mj.contains("where"));
  check_error(a.get("/api/loops/0/models/2"), 404);
  check_error(a.get("/api/loops/0/models/x"), 404);

  // Simulated PV and residual, decimated like the series; the residual is PV minus the model's.
  const json sim = a.get("/api/loops/0/models/1/simulation?buckets=20&from=100&to=600").body;
  REQUIRE(sim["buckets"] == 20);
  CHECK(sim["model"] == "stiction");
  CHECK(sim["t"][0].get<double>() >= 100.0);
  CHECK(sim["estimation_end_s"].get<double>() == doctest::Approx(525.0).epsilon(0.01));
  for (std::size_t k = 0; k < 20; ++k) {
    CHECK(sim["residual"]["max"][k].get<double>() < 2.0);  // a good model: small residual
    CHECK(sim["pv"]["min"][k].get<double>() <= sim["pv"]["max"][k].get<double>());
  }
  check_error(a.get("/api/loops/0/models/1/simulation?buckets=0"), 400);
  check_error(a.get("/api/loops/0/models/1/simulation?from=9000&to=9100"), 400);
  check_error(a.get("/api/loops/0/models/1/simulation?step=1"), 400);

  // The valve signature: the stiction model's valve position against OP, at samples of the data.
  CHECK(lad["steps"][0]["valve_effect"] == false);
  CHECK(lad["steps"][1]["valve_effect"] == true);
  check_error(a.get("/api/loops/0/models/0/signature"), 404);  // linear: x is OP
  const LoopData& data = sticky_loop();
  const json sig = a.get("/api/loops/0/models/1/signature?points=400").body;
  CHECK(sig["model"] == "stiction");
  CHECK(sig["step"] == 1);
  CHECK(sig["samples"] == data.size());
  CHECK(sig["x_in_op_units"] == true);
  const std::size_t np = sig["t"].size();
  CHECK(np == sig["points"].get<std::size_t>());
  CHECK(np <= 400);
  CHECK(np >= 200);  // 100 runs, each with at least OP's minimum and maximum
  CHECK(sig["estimation_end_s"].get<double>() == s1["estimation_end_s"].get<double>());
  const double split = sig["estimation_end_s"];
  double x_lo = 1e9, x_hi = -1e9, op_lo = 1e9, op_hi = -1e9;
  for (std::size_t k = 0; k < np; ++k) {
    const std::size_t i = sig["index"][k];
    CHECK(sig["t"][k].get<double>() == data.t[i]);
    CHECK(sig["op"][k].get<double>() == data.op[i]);
    CHECK(sig["held_out"][k] == (data.t[i] >= split));
    x_lo = std::min(x_lo, sig["x"][k].get<double>());
    x_hi = std::max(x_hi, sig["x"][k].get<double>());
    op_lo = std::min(op_lo, sig["op"][k].get<double>());
    op_hi = std::max(op_hi, sig["op"][k].get<double>());
  }
  // A sticking valve travels less than OP does, by about the band (fs 8.4) at each reversal.
  CHECK(x_hi - x_lo < op_hi - op_lo);
  CHECK(x_hi - x_lo > 0.5 * (op_hi - op_lo));
  check_error(a.get("/api/loops/0/models/1/signature?points=5"), 400);
  check_error(a.get("/api/loops/0/models/1/signature?buckets=5"), 400);
  check_error(a.get("/api/loops/0/models/1/signature?from=9000&to=9100"), 400);
  check_error(a.get("/api/loops/0/models/2/signature"), 404);
  // PV against OP: the split is the models' own.
  const json ph = a.get("/api/loops/0/phase?from=100&to=200").body;
  CHECK(ph["estimation_end_s"].get<double>() == s1["estimation_end_s"].get<double>());
  CHECK(ph["points"] == 201);
  CHECK(ph["pv"][0].get<double>() == data.pv[200]);

  // The report of the current model, as valvediag report writes it, as a download.
  const auto rep = a.get("/api/loops/0/report");
  REQUIRE(rep.status == 200);
  CHECK(rep.content_type == "text/html; charset=utf-8");
  CHECK(rep.attachment == "ex1-0-report.html");
  CHECK(rep.raw.find("<html") != std::string::npos);
  CHECK(rep.raw.find("stiction") != std::string::npos);

  // Remove goes back down the ladder, as a new step.
  const json rm = a.wait(a.post({{"action", "remove"}, {"effect", "stiction"}}));
  REQUIRE(rm["state"] == "done");
  CHECK(rm["result"]["model"] == "linear");
  CHECK(a.get("/api/loops/0/ladder").body["steps"].size() == 3);
  // Fitting an effect that is not there to remove fails with the reason.
  const json rm2 = a.wait(a.post({{"action", "remove"}, {"effect", "deadband"}}));
  CHECK(rm2["state"] == "failed");
  CHECK(!rm2["error"].get<std::string>().empty());
}

TEST_CASE(
    "signature: the model's valve position at the chosen samples, the held-out part flagged") {
  // A made-up fit: the valve position is OP delayed by a band, known sample by sample.
  LoopData d;
  ModelStep s;
  s.fit.spec = parse_model_spec("deadband");
  s.entry.model = "deadband";
  for (int i = 0; i < 5000; ++i) {
    d.t.push_back(10.0 + 2.0 * i);
    d.op.push_back(50.0 + 10.0 * std::sin(0.01 * i));
    d.pv.push_back(0.0);
    s.fit.x_hat.push_back(i == 0 ? d.op[0]
                                 : std::clamp(s.fit.x_hat.back(), d.op[i] - 2, d.op[i] + 2));
  }
  s.fit.estimation_end = 3500;
  CHECK(has_valve_effect(s.fit.spec));
  CHECK(!has_valve_effect(parse_model_spec("linear")));
  CHECK(!has_valve_effect(parse_model_spec("delay+integrator")));
  CHECK(has_valve_effect(parse_model_spec("actuator-lag")));
  const json j = signature_json(s, d, d.t.front(), d.t.back(), 1000);
  CHECK(j["model"] == "deadband");
  CHECK(j["estimation_end_s"].get<double>() == d.t[3500]);
  const std::size_t n = j["t"].size();
  REQUIRE(n <= 1000);
  REQUIRE(n >= 500);
  for (std::size_t k = 0; k < n; ++k) {
    const std::size_t i = j["index"][k];
    if (k > 0) CHECK(i > j["index"][k - 1].get<std::size_t>());
    CHECK(j["x"][k].get<double>() == s.fit.x_hat[i]);
    CHECK(j["op"][k].get<double>() == d.op[i]);
    CHECK(j["held_out"][k] == (i >= 3500));
  }
  // The path reaches the valve's full travel.
  double hi = -1e9;
  for (const auto& x : j["x"]) hi = std::max(hi, x.get<double>());
  CHECK(hi == *std::max_element(s.fit.x_hat.begin(), s.fit.x_hat.end()));
}

TEST_CASE("jobs: each model added to the ladder is appended to the loop's history file") {
  namespace fs = std::filesystem;
  const fs::path dir = fs::path(VALVEDIAG_TMP) / ("jobs_history_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  const std::string file = (dir / "history" / "loop.json").string();
  LoopModels models(file);
  JobControl control;
  const json fit = run_job(parse_job_request({{"action", "fit"}, {"model", "linear"}}),
                           sticky_loop(), models, {}, control);
  CHECK(fit["history"]["entries"] == 1);
  const json dg =
      run_job(parse_job_request({{"action", "diagnose"}}), sticky_loop(), models, {}, control);
  CHECK(dg["steps_added"] == 0);  // the model diagnosed is the ladder's last: no new step
  CHECK(dg["history"].is_null());
  const json band = run_job(parse_job_request({{"action", "fit"}, {"model", "deadband"}}),
                            sticky_loop(), models, {}, control);
  CHECK(band["history"]["entries"] == 2);
  // The file holds the ladder's rows, as `valvediag ladder` reads them.
  const auto h = load_history(file);
  const auto steps = models.steps();
  REQUIRE(h.size() == 2);
  REQUIRE(steps.size() == 2);
  for (std::size_t k = 0; k < 2; ++k) {
    CHECK(h[k].model == steps[k]->entry.model);
    CHECK(h[k].command == steps[k]->entry.command);
    CHECK(h[k].fitness_percent == doctest::Approx(steps[k]->fit.fitness_percent));
    CHECK(h[k].validation_fitness_percent ==
          doctest::Approx(steps[k]->fit.validation_fitness_percent));
  }
  CHECK(h[0].command == "workbench fit linear");
  CHECK(h[1].model == "deadband");
  // Without a file nothing is written; a file that cannot be written leaves the model standing.
  LoopModels none;
  CHECK(run_job(parse_job_request({{"action", "fit"}, {"model", "linear"}}), sticky_loop(), none,
                {}, control)["history"]
            .is_null());
  std::ofstream(dir / "a-file") << "not a folder";
  LoopModels blocked((dir / "a-file" / "history.json").string());
  const json b = run_job(parse_job_request({{"action", "fit"}, {"model", "linear"}}), sticky_loop(),
                         blocked, {}, control);
  CHECK(!b["history"]["error"].get<std::string>().empty());
  CHECK(blocked.steps().size() == 1);
  fs::remove_all(dir);
}

TEST_CASE("jobs: a full ladder refuses more models") {
  LoopModels models;
  JobControl control;
  const JobRequest fit = parse_job_request({{"action", "fit"}, {"model", "linear"}});
  for (int i = 0; i < 2; ++i) (void)run_job(fit, sticky_loop(), models, {}, control, 2);
  CHECK(models.steps().size() == 2);
  CHECK_THROWS_WITH_AS(run_job(fit, sticky_loop(), models, {}, control, 2),
                       doctest::Contains("holds 2 models"), std::invalid_argument);
  CHECK(models.steps().size() == 2);
}

TEST_CASE("jobs: bad bodies, content types, methods and unknown ids are JSON errors") {
  Api a;
  const std::string jobs = "/api/loops/0/jobs";
  for (const char* body :
       {"", "{", "not json", "[]", "42", "null", "{\"action\":1}", "{\"action\":\"\"}",
        "{\"action\":\"explode\"}", "{\"action\":\"fit\"}", "{\"action\":\"fit\",\"model\":\"x\"}",
        "{\"action\":\"add\"}", "{\"action\":\"add\",\"effect\":\"unicorn\"}",
        "{\"action\":\"add\",\"effect\":\"stiction\",\"extra\":1}",
        "{\"action\":\"diagnose\",\"climb\":\"yes\"}", "{\"action\":\"add\",\"effect\":[1]}",
        "{\"action\":\"fit\",\"model\":\"stiction+\"}", "\xff\xfe{}"}) {
    CAPTURE(body);
    const auto r = a.req("POST", jobs, body);
    check_error(r, 400);
    CHECK_NOTHROW((void)response_text(r));
  }
  check_error(a.req("POST", jobs, "{\"action\":\"diagnose\"}", "text/plain"), 415);
  check_error(a.req("POST", jobs, "{\"action\":\"diagnose\"}", ""), 415);
  check_error(a.req("POST", jobs, std::string(kMaxBody + 1, ' ')), 413);
  check_error(a.req("POST", "/api/loops/7/jobs", "{\"action\":\"diagnose\"}"), 404);
  check_error(a.req("POST", "/api/loops/0/jobs?x=1", "{\"action\":\"diagnose\"}"), 400);
  check_error(a.req("GET", jobs), 405);
  check_error(a.req("DELETE", jobs), 405);
  check_error(a.req("PUT", jobs, "{}"), 405);
  check_error(a.req("POST", "/api/loops/0/ladder", "{}"), 405);
  check_error(a.req("DELETE", "/api/loops/0/verdict"), 405);
  check_error(a.req("POST", "/api/jobs/1", "{}"), 405);
  check_error(a.req("PUT", "/"), 405);
  check_error(a.get("/api/jobs/1"), 404);
  check_error(a.req("DELETE", "/api/jobs/1"), 404);
  check_error(a.get("/api/jobs/..%2f1"), 404);
  check_error(a.get("/api/jobs/"), 404);
  check_error(a.get("/api/jobs"), 404);
  check_error(a.get("/api/jobs/1/x"), 404);
  check_error(a.get("/api/loops/0/models"), 404);
  check_error(a.get("/api/loops/0/models/0/simulation/x"), 404);
  check_error(a.get("/api/loops/0/ladder?x=1"), 400);
}

TEST_CASE("jobs: a running job cancelled ends cancelled and leaves the ladder as it was") {
  Api a;
  // A climb from linear fits many trial models: seconds, long enough to be caught running.
  const std::string id = a.post({{"action", "diagnose"}, {"climb", true}});
  const auto end = Clock::now() + std::chrono::seconds(120);
  while (a.get("/api/jobs/" + id).body["state"] == "queued" && Clock::now() < end)
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  std::this_thread::sleep_for(std::chrono::milliseconds(100));
  const auto del = a.req("DELETE", "/api/jobs/" + id);
  REQUIRE(del.status == 200);
  REQUIRE_MESSAGE(del.body["state"] == "running", "the climb ended before it was cancelled");
  CHECK(del.body["cancel_requested"] == true);
  const auto t0 = Clock::now();
  const json st = a.wait(id, 300.0);
  const double took = std::chrono::duration<double>(Clock::now() - t0).count();
  MESSAGE("cancelled after " << took << " s");
  CHECK(st["state"] == "cancelled");
  CHECK(took < (kSanitizedBuild ? 60.0 : 10.0));
  CHECK(a.get("/api/loops/0/ladder").body["steps"].empty());
  check_error(a.get("/api/loops/0/diagnosis"), 404);
}

TEST_CASE("jobs: concurrent jobs on two loops, and the queue's bound is a 503") {
  Api a("", {2, 1, 100}, 2);
  const auto running = [&](const std::string& id) {
    const auto end = Clock::now() + std::chrono::seconds(120);
    while (a.get("/api/jobs/" + id).body["state"] == "queued" && Clock::now() < end)
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
  };
  // Two fits at once, one per loop: both end with their own model.
  const std::string f0 = a.post({{"action", "fit"}, {"model", "stiction"}}, 0);
  running(f0);
  const std::string f1 = a.post({{"action", "fit"}, {"model", "linear"}}, 1);
  CHECK(a.wait(f0)["state"] == "done");
  CHECK(a.wait(f1)["state"] == "done");
  CHECK(a.get("/api/loops/0/ladder").body["steps"][0]["model"] == "stiction");
  CHECK(a.get("/api/loops/1/ladder").body["steps"][0]["model"] == "linear");

  // Two climbs running (seconds each), one job waiting: a burst beyond that gets a JSON 503.
  const std::string c0 = a.post({{"action", "diagnose"}, {"climb", true}}, 0);
  running(c0);
  const std::string c1 = a.post({{"action", "diagnose"}, {"climb", true}}, 1);
  running(c1);
  int refused = 0;
  std::vector<std::string> accepted{c0, c1};
  for (int i = 0; i < 4; ++i) {
    const auto r = a.req("POST", "/api/loops/1/jobs", json{{"action", "diagnose"}}.dump());
    if (r.status == 503) {
      ++refused;
      CHECK(r.body["error"].get<std::string>().find("full") != std::string::npos);
    } else {
      REQUIRE(r.status == 202);
      accepted.push_back(r.body["job"]);
    }
  }
  CHECK(refused == 3);
  for (const auto& id : accepted) a.req("DELETE", "/api/jobs/" + id);
  for (const auto& id : accepted) CHECK(a.wait(id)["state"] == "cancelled");

  // Many clients at once: every request answered, with a job or a 503.
  std::vector<std::thread> th;
  std::atomic<int> answered{0};
  for (int i = 0; i < 8; ++i)
    th.emplace_back([&] {
      const auto r = a.req("POST", "/api/loops/0/jobs", json{{"action", "diagnose"}}.dump());
      if (r.status == 202 || r.status == 503) ++answered;
      if (r.status == 202) a.req("DELETE", "/api/jobs/" + r.body["job"].get<std::string>());
    });
  for (auto& t : th) t.join();
  CHECK(answered == 8);
}

TEST_CASE("the page and dygraphs are served from the binary with their content types") {
  Api a;
  const struct {
    const char* path;
    const char* type;
    const char* holds;
  } files[] = {{"/", "text/html; charset=utf-8", "valvediag workbench"},
               {"/static/app.js", "text/javascript; charset=utf-8", "/api/loops"},
               {"/static/app.css", "text/css; charset=utf-8", "#loop-list"},
               {"/static/dygraph.min.js", "text/javascript; charset=utf-8", "Dygraph"},
               {"/static/dygraph.min.css", "text/css; charset=utf-8", "dygraph"}};
  for (const auto& f : files) {
    CAPTURE(f.path);
    const auto r = a.get(f.path);
    REQUIRE(r.status == 200);
    CHECK(r.content_type == f.type);
    CHECK(r.raw.find(f.holds) != std::string::npos);
    CHECK(response_text(r) == r.raw);
    CHECK(response_type(r) == f.type);
  }
  CHECK(a.get("/static/dygraph.min.js").raw.size() > 50000);  // the whole library, not a stub
  for (const char* p : {"/static/", "/static", "/index.html", "/static/../static/app.js",
                        "/static/app.js/", "/static/APP.JS", "//", "/static/%2e%2e/app.js"}) {
    CAPTURE(p);
    check_error(a.get(p), 404);
  }
  check_error(a.req("POST", "/static/app.js", "{}"), 405);
  check_error(a.req("DELETE", "/"), 405);
  ApiRequest q;
  q.path = "/";
  q.query.emplace("x", "1");
  check_error(a.api.handle(q), 400);
}

TEST_CASE("the token guards the page too: ?token= opens it and sets the cookie") {
  Api a("s3cret");
  const auto with = [&](const std::string& path, const std::string& cookie,
                        const std::string& token) {
    ApiRequest r;
    r.path = path;
    r.cookie = cookie;
    if (!token.empty()) r.query.emplace("token", token);
    return a.api.handle(r);
  };
  check_error(with("/", "", ""), 401);
  check_error(with("/static/app.js", "", ""), 401);
  check_error(with("/", "", "wrong"), 401);
  check_error(with("/", "valvediag_token=wrong", ""), 401);
  check_error(with("/", "valvediag_token=s3cre", ""), 401);
  const auto page = with("/", "", "s3cret");
  REQUIRE(page.status == 200);
  CHECK(page.set_cookie == "valvediag_token=s3cret; Path=/; HttpOnly; SameSite=Strict");
  // The page's scripts and requests carry the cookie.
  CHECK(with("/static/app.js", "theme=dark; valvediag_token=s3cret", "").status == 200);
  CHECK(with("/api/loops", "valvediag_token=s3cret", "").status == 200);
  CHECK(with("/api/loops", "", "s3cret").status == 200);  // a script may pass it so
  CHECK(with("/api/loops", "", "s3cret").set_cookie.empty());
  // Named after the port the page was opened on: two servers on one machine keep their own.
  ApiRequest at;
  at.path = "/";
  at.host = "127.0.0.1:8081";
  at.query.emplace("token", "s3cret");
  CHECK(a.api.handle(at).set_cookie ==
        "valvediag_token_8081=s3cret; Path=/; HttpOnly; SameSite=Strict");
  at.query.clear();
  at.path = "/api/loops";
  at.cookie = "valvediag_token_8080=s3cret";
  check_error(a.api.handle(at), 401);
  at.cookie = "valvediag_token_8080=other; valvediag_token_8081=s3cret";
  CHECK(a.api.handle(at).status == 200);
  CHECK(token_cookie_name("[::1]:9000") == "valvediag_token_9000");
  CHECK(token_cookie_name("localhost") == "valvediag_token");
  ApiRequest post;
  post.method = "POST";
  post.path = "/api/loops/0/jobs";
  post.content_type = "application/json";
  post.body = R"({"action":"diagnose"})";
  check_error(a.api.handle(post), 401);
}
