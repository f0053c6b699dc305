// valvediag serve as a user starts it: the binary on a free port, asked over HTTP with
// cpp-httplib's client. Every wait is bounded; a server left running is killed.
#include <doctest/doctest.h>
#include <signal.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <thread>

#include "../common/run_cli.hpp"
#include "../common/sanitized.hpp"
#include "valvediag/io/csv_reader.hpp"

// Last: it includes <httplib.h>, whose <resolv.h> defines `_res`, which breaks Eigen headers
// included after it.
#include "serve_process.hpp"

namespace fs = std::filesystem;
using nlohmann::json;
using valvediag::test::run_cli;

namespace {

const fs::path kTmp = VALVEDIAG_TMP;

using valvediag::test::slurp;

struct Server : valvediag::test::ServeProcess {
  Server(const std::vector<std::string>& args, const std::string& tag,
         const std::vector<std::string>& env = {})
      : ServeProcess(VALVEDIAG_BIN, with_serve(args), kTmp, tag, 30.0, env) {}
  static std::vector<std::string> with_serve(std::vector<std::string> args) {
    args.insert(args.begin(), "serve");
    return args;
  }
};

json body(const httplib::Result& r) {
  REQUIRE(r);
  CHECK(r->get_header_value("Content-Type") == "application/json");
  return json::parse(r->body);
}

void check_error(const httplib::Result& r, int status) {
  REQUIRE(r);
  CHECK(r->status == status);
  const json j = body(r);
  REQUIRE(j.contains("error"));
  CHECK(!j["error"].get<std::string>().empty());
  CHECK(r->body.find("root:") == std::string::npos);
}

// The simulated loop every case serves (made once).
fs::path loop_csv() {
  const fs::path csv = kTmp / "serve_paper_ex1.csv";
  static const bool made = [&] {
    const auto r = run_cli(VALVEDIAG_BIN,
                           {"simulate", "--scenario", "paper-ex1", "--seed", "1", "--samples",
                            "1500", "--out", csv.string()},
                           kTmp, 60.0);
    return r.status == 0;
  }();
  REQUIRE(made);
  return csv;
}

// 150 samples: under the 200 a verdict needs, so its verdict is quick.
fs::path short_csv() {
  const fs::path csv = kTmp / "serve_short.csv";
  static const bool made = [&] {
    const auto r = run_cli(VALVEDIAG_BIN,
                           {"simulate", "--scenario", "paper-ex1", "--seed", "2", "--samples",
                            "150", "--out", csv.string()},
                           kTmp, 60.0);
    return r.status == 0;
  }();
  REQUIRE(made);
  return csv;
}

}  // namespace

TEST_CASE("serve answers every endpoint over HTTP and stops on Ctrl-C") {
  const fs::path csv = loop_csv();
  valvediag::CsvOptions o;
  const valvediag::LoopData raw = valvediag::read_loop_csv(csv.string(), o);
  Server s({csv.string(), short_csv().string(), "--port", "0"}, "main");
  REQUIRE(s.port > 0);
  auto c = s.client();

  const json loops = body(c.Get("/api/loops"));
  REQUIRE(loops["loops"].size() == 2);
  CHECK(loops["loops"][0]["id"] == 0);
  CHECK(loops["loops"][0]["name"] == "serve_paper_ex1");
  CHECK(loops["loops"][0]["samples"] == raw.size());

  // Each bucket's min and max are the raw data's over the samples it spans.
  const json ser = body(c.Get("/api/loops/0/series?buckets=50"));
  REQUIRE(ser["buckets"] == 50);
  std::size_t covered = 0;
  for (std::size_t k = 0; k < 50; ++k) {
    const auto b = std::lower_bound(raw.t.begin(), raw.t.end(), ser["t"][k].get<double>());
    const auto e = std::upper_bound(raw.t.begin(), raw.t.end(), ser["t_end"][k].get<double>());
    const auto i0 = b - raw.t.begin(), i1 = e - raw.t.begin();
    REQUIRE(i1 - i0 == ser["n"][k].get<long>());
    covered += static_cast<std::size_t>(i1 - i0);
    for (const auto& [name, x] : {std::pair{"op", &raw.op}, {"pv", &raw.pv}}) {
      const auto [lo, hi] = std::minmax_element(x->begin() + i0, x->begin() + i1);
      CHECK(ser[name]["min"][k].get<double>() == doctest::Approx(*lo).epsilon(1e-12));
      CHECK(ser[name]["max"][k].get<double>() == doctest::Approx(*hi).epsilon(1e-12));
    }
  }
  CHECK(covered == raw.size());
  const json part = body(c.Get("/api/loops/0/series?from=10&to=20&buckets=3"));
  CHECK(part["buckets"] == 3);
  CHECK(part["t"][0].get<double>() >= 10.0);
  CHECK(part["t_end"][2].get<double>() <= 20.0);

  // The verdict path, on a record too short to judge (fast; a full verdict is the next case's).
  const json v1 = body(c.Get("/api/loops/1/verdict"));
  CHECK(v1["verdict"] == "not-enough-data");
  CHECK(v1["cached"] == false);
  CHECK(body(c.Get("/api/loops/1/verdict"))["cached"] == true);
  CHECK(body(c.Get("/api/loops"))["loops"][1]["verdict"] == "not-enough-data");

  // Bad requests: JSON errors, the server still up afterwards.
  check_error(c.Get("/api/loops/0/series?buckets=0"), 400);
  check_error(c.Get("/api/loops/0/series?buckets=10001"), 400);
  check_error(c.Get("/api/loops/0/series?from=20&to=10"), 400);
  check_error(c.Get("/api/loops/0/series?from=nan"), 400);
  check_error(c.Get("/api/loops/2/series"), 404);
  check_error(c.Get("/api/loops/x/verdict"), 404);
  check_error(c.Get("/nope"), 404);
  check_error(c.Post("/api/loops", "{}", "application/json"), 405);
  check_error(c.Delete("/api/loops/0/verdict"), 405);
  // Traversal, plain and URL-encoded (httplib decodes the path: the API sees the dots).
  for (const char* p :
       {"/api/loops/../../etc/passwd", "/../../../../etc/passwd",
        "/api/loops/%2e%2e/%2e%2e/etc/passwd", "/api/loops/0/%2e%2e%2f%2e%2e%2fetc%2fpasswd",
        "/%2e%2e/%2e%2e/etc/passwd", "/api/loops/0/series/..%2f..%2f..%2fetc%2fpasswd",
        "/api/loops/%00/verdict"}) {
    CAPTURE(p);
    check_error(c.Get(p), 404);
  }
  // A page that rebound its own name to 127.0.0.1 still sends that name (DNS-rebinding guard).
  check_error(c.Get("/api/loops", {{"Host", "evil.example:80"}}), 403);
  CHECK(body(c.Get("/api/loops"))["loops"].size() == 2);
  // A second server on the same port is refused, not let in beside the first (SO_REUSEPORT).
  const auto twice =
      run_cli(VALVEDIAG_BIN, {"serve", csv.string(), "--port", std::to_string(s.port)}, kTmp, 30.0);
  CHECK(twice.status == 1);
  CHECK(twice.out.find("cannot listen") != std::string::npos);

  const int st = s.stop();
  CHECK(st == 0);
  const std::string out = slurp(s.out);
  CHECK(out.find("stopped") != std::string::npos);
}

// A full verdict takes a minute under the sanitizers: their build runs the path above, with the
// short record, and leaves this comparison to Release.
TEST_CASE("serve's verdict is the one diagnose gives for the same file" *
          valvediag::test::release_only()) {
  const fs::path csv = loop_csv();
  Server s({csv.string(), "--port", "0"}, "verdict");
  REQUIRE(s.port > 0);
  auto c = s.client();
  const fs::path dj = kTmp / "serve_diagnose.json";
  const auto diag =
      run_cli(VALVEDIAG_BIN, {"diagnose", csv.string(), "--json", dj.string(), "--no-history"},
              kTmp, 300.0);
  REQUIRE_MESSAGE(diag.status == 0, diag.out);
  const json want = json::parse(slurp(dj));
  const json v = body(c.Get("/api/loops/0/verdict"));
  CHECK(v["verdict"] == want["verdict"]);
  CHECK(v["verdict_model"] == want["verdict_model"]);
  REQUIRE(v["stiction_percent"].is_number() == want["stiction_percent"].is_number());
  if (want["stiction_percent"].is_number())
    CHECK(v["stiction_percent"].get<double>() ==
          doctest::Approx(want["stiction_percent"].get<double>()).epsilon(1e-9));
  CHECK(v["cached"] == false);
  CHECK(body(c.Get("/api/loops/0/verdict"))["cached"] == true);

  CHECK(s.stop() == 0);
}

TEST_CASE("serve --token: 401 without the token, 200 with it") {
  const fs::path csv = loop_csv();
  Server s({csv.string(), "--port", "0", "--token"}, "token");
  REQUIRE(s.port > 0);
  REQUIRE(s.token.size() == 32);
  auto c = s.client();
  check_error(c.Get("/api/loops"), 401);
  check_error(c.Get("/api/loops", {{"Authorization", "Bearer 0123"}}), 401);
  const auto ok = c.Get("/api/loops", {{"Authorization", "Bearer " + s.token}});
  REQUIRE(ok);
  CHECK(ok->status == 200);
  CHECK(s.stop() == 0);
}

TEST_CASE("serve refuses a non-loopback --bind without --token, and bad options") {
  const fs::path csv = loop_csv();
  auto r = run_cli(VALVEDIAG_BIN, {"serve", csv.string(), "--bind", "0.0.0.0", "--port", "0"}, kTmp,
                   30.0);
  CHECK(r.status == 2);
  CHECK(r.out.find("--token") != std::string::npos);
  r = run_cli(VALVEDIAG_BIN, {"serve", csv.string(), "--port", "70000"}, kTmp, 30.0);
  CHECK(r.status == 2);
  r = run_cli(VALVEDIAG_BIN, {"serve", (kTmp / "no_such.csv").string(), "--port", "0"}, kTmp, 30.0);
  CHECK(r.status == 2);
  r = run_cli(VALVEDIAG_BIN, {"serve"}, kTmp, 30.0);
  CHECK(r.status == 2);
  // A held-out share the page's split could not reach (the API takes 0.05 to 0.6).
  r = run_cli(VALVEDIAG_BIN, {"serve", csv.string(), "--port", "0", "--validate", "0.7"}, kTmp,
              30.0);
  CHECK(r.status == 2);
  CHECK(r.out.find("--validate 0.7: the workbench holds out at most 0.6") != std::string::npos);
}

TEST_CASE("serve over HTTP: the page, a job, bad bodies, a client that hangs up") {
  const fs::path csv = loop_csv();
  Server s({csv.string(), "--port", "0", "--token"}, "page");
  REQUIRE(s.port > 0);
  auto c = s.client();
  // The page needs the token too; the address printed with ?token= opens it and sets a cookie.
  check_error(c.Get("/"), 401);
  const std::string out = slurp(s.out);
  CHECK(out.find("/?token=" + s.token) != std::string::npos);
  const auto page = c.Get("/?token=" + s.token);
  REQUIRE(page);
  CHECK(page->status == 200);
  CHECK(page->get_header_value("Content-Type") == "text/html; charset=utf-8");
  CHECK(page->body.find("/static/dygraph.min.js") != std::string::npos);
  const std::string cookie = page->get_header_value("Set-Cookie");
  CHECK(cookie.find("HttpOnly") != std::string::npos);
  const httplib::Headers with_cookie{{"Cookie", cookie.substr(0, cookie.find(';'))}};
  const auto js = c.Get("/static/dygraph.min.js", with_cookie);
  REQUIRE(js);
  CHECK(js->status == 200);
  CHECK(js->get_header_value("Content-Type") == "text/javascript; charset=utf-8");
  CHECK(js->body.size() > 50000);

  // A job over HTTP, and a malformed body: a JSON 400, the server still up.
  const httplib::Headers auth{{"Authorization", "Bearer " + s.token}};
  const auto bad = c.Post("/api/loops/0/jobs", auth, "{\"action\":", "application/json");
  check_error(bad, 400);
  check_error(c.Post("/api/loops/0/jobs", auth, "{\"action\":\"diagnose\"}", "text/plain"), 415);
  check_error(c.Post("/api/loops/0/jobs", auth, std::string(200000, '{'), "application/json"), 413);
  const auto posted = c.Post("/api/loops/0/jobs", auth, R"({"action":"fit","model":"stiction"})",
                             "application/json");
  REQUIRE(posted);
  REQUIRE(posted->status == 202);
  const std::string job = json::parse(posted->body)["job"];
  json st;
  const auto end = std::chrono::steady_clock::now() + std::chrono::seconds(300);
  do {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    st = body(c.Get("/api/jobs/" + job, auth));
  } while ((st["state"] == "queued" || st["state"] == "running") &&
           std::chrono::steady_clock::now() < end);
  CHECK(st["state"] == "done");
  const auto model = c.Get("/api/loops/0/models/0", auth);
  REQUIRE(model);
  CHECK(model->status == 200);
  CHECK(model->get_header_value("Content-Disposition") ==
        "attachment; filename=\"serve_paper_ex1-model-0.json\"");
  CHECK(json::parse(model->body)["model"] == "stiction");
  check_error(c.Delete("/api/jobs/12345", auth), 404);

  // A client that gives up on a slow answer (a verdict takes seconds) and hangs up: the server
  // answers the next one.
  {
    httplib::Client impatient("127.0.0.1", s.port);
    impatient.set_read_timeout(0, 50000);
    (void)impatient.Get("/api/loops/0/verdict", auth);
  }
  CHECK(body(c.Get("/api/loops", auth))["loops"].size() == 1);
  CHECK(s.stop() == 0);
}

// Posts a job and waits (bounded) for its end; its status.
json run_job(httplib::Client& c, const std::string& body_text) {
  const auto posted = c.Post("/api/loops/0/jobs", body_text, "application/json");
  REQUIRE(posted);
  REQUIRE(posted->status == 202);
  const std::string job = json::parse(posted->body)["job"];
  json st;
  const auto end = std::chrono::steady_clock::now() + std::chrono::seconds(300);
  do {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    st = body(c.Get("/api/jobs/" + job));
  } while ((st["state"] == "queued" || st["state"] == "running") &&
           std::chrono::steady_clock::now() < end);
  return st;
}

TEST_CASE("serve adds its models to the file's history in the state directory: ladder lists them") {
  const fs::path csv = loop_csv();
  const fs::path state = kTmp / ("serve_history_state_" + std::to_string(::getpid()));
  fs::remove_all(state);
  const std::vector<std::string> env{"XDG_STATE_HOME=" + state.string()};
  {
    Server s({csv.string(), "--port", "0"}, "history", env);
    REQUIRE(s.port > 0);
    CHECK(slurp(s.out).find("model history of " + csv.string() + ": " + state.string()) !=
          std::string::npos);
    auto c = s.client();
    const json a = run_job(c, R"({"action":"fit","model":"linear"})");
    REQUIRE(a["state"] == "done");
    CHECK(a["result"]["history"]["entries"] == 1);
    const json b = run_job(c, R"({"action":"add","effect":"stiction"})");
    REQUIRE(b["state"] == "done");
    CHECK(b["result"]["history"]["entries"] == 2);
    CHECK(s.stop() == 0);
  }
  // The CLI's ladder finds them by the data's content and reading options, as fit's and
  // diagnose's.
  const auto lad = run_cli(VALVEDIAG_BIN, {"ladder", csv.string()}, kTmp, 60.0, env);
  CHECK_MESSAGE(lad.status == 0, lad.out);
  CHECK(lad.out.find("\n1     linear ") != std::string::npos);
  CHECK(lad.out.find("\n2     stiction ") != std::string::npos);

  // --no-history writes nothing.
  fs::remove_all(state);
  {
    Server s({csv.string(), "--port", "0", "--no-history"}, "no_history", env);
    REQUIRE(s.port > 0);
    auto c = s.client();
    const json a = run_job(c, R"({"action":"fit","model":"linear"})");
    REQUIRE(a["state"] == "done");
    CHECK(a["result"]["history"].is_null());
    CHECK(s.stop() == 0);
  }
  CHECK(!fs::exists(state));
}

// The demo's recording in the workbench: the offline demo (simulated, fitted, reported) then the
// server on it. Release only: the demo's fit over the paper's grid takes minutes under the
// sanitizers.
TEST_CASE("demo --serve opens the workbench on the demo's loop" * valvediag::test::release_only()) {
  const fs::path dir = kTmp / "demo_serve";
  fs::remove_all(dir);
  valvediag::test::ServeProcess s(VALVEDIAG_BIN,
                                  {"demo", "--offline", "--samples", "1500", "--serve", "--port",
                                   "0", "--out-dir", dir.string()},
                                  kTmp, "demo", 300.0);
  REQUIRE(s.port > 0);
  auto c = s.client();
  const json loops = body(c.Get("/api/loops"));
  REQUIRE(loops["loops"].size() == 1);
  CHECK(loops["loops"][0]["name"] == "FIC101");
  CHECK(loops["loops"][0]["samples"] == 1500);
  const auto page = c.Get("/");
  REQUIRE(page);
  CHECK(page->status == 200);
  CHECK(s.stop() == 0);
}

TEST_CASE("Ctrl-C stops serve promptly while a verdict is being computed") {
  const fs::path csv = loop_csv();
  Server s({csv.string(), "--port", "0"}, "ctrlc");
  REQUIRE(s.port > 0);
  std::thread asker([port = s.port] {
    httplib::Client c("127.0.0.1", port);
    c.set_read_timeout(120, 0);
    const auto r = c.Get("/api/loops/0/verdict");
    // Cancelled (503), or done before the signal came (200), or cut off by the exit.
    if (r) CHECK((r->status == 503 || r->status == 200));
  });
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  const auto t0 = std::chrono::steady_clock::now();
  CHECK(s.stop() == 0);
  CHECK(std::chrono::steady_clock::now() - t0 < std::chrono::seconds(10));
  asker.join();
}
