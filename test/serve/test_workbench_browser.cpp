// The workbench in a real browser: `valvediag serve` on a simulated loop with stiction hidden in
// it, headless Chromium driven by Debian's chromium-driver over WebDriver (W3C, JSON over HTTP,
// sent with cpp-httplib's client). The page diagnoses the linear model by itself; the top finding
// must name stiction; clicking its "Add" must grow the ladder by a stiction step whose validation
// error is far below the linear model's; the screenshot, decoded with libpng, must show a page.
#include <doctest/doctest.h>
#include <netinet/in.h>
#include <png.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>
#include <vector>

#include "valvediag/drivers/sim_plc.hpp"
#include "valvediag/drivers/site_config.hpp"

// Last: it includes <httplib.h> (its `_res` macro breaks Eigen headers included after it).
#include "serve_process.hpp"

namespace fs = std::filesystem;
using nlohmann::json;
using Clock = std::chrono::steady_clock;

namespace {

const fs::path kTmp = VALVEDIAG_TMP;
const std::string kSimSite = std::string(VALVEDIAG_CONFIG_DIR) + "/sim-site.toml";
// The element key of W3C WebDriver's answers.
const char* kElement = "element-6066-11e4-a52e-4f735466cecf";

std::string on_path(const std::string& name) {
  const char* path = std::getenv("PATH");
  std::string dirs = path ? path : "";
  for (std::size_t b = 0; b <= dirs.size();) {
    std::size_t e = dirs.find(':', b);
    if (e == std::string::npos) e = dirs.size();
    const fs::path p = fs::path(dirs.substr(b, e - b)) / name;
    if (::access(p.c_str(), X_OK) == 0) return p.string();
    b = e + 1;
  }
  return "";
}

// A port no one listens on now (the kernel's pick), for chromedriver.
int free_port() {
  const int s = ::socket(AF_INET, SOCK_STREAM, 0);
  REQUIRE(s >= 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  REQUIRE(::bind(s, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0);
  socklen_t n = sizeof a;
  REQUIRE(::getsockname(s, reinterpret_cast<sockaddr*>(&a), &n) == 0);
  ::close(s);
  return ntohs(a.sin_port);
}

std::string base64_decode(const std::string& in) {
  std::string out;
  int bits = 0, value = 0;
  for (char c : in) {
    int d;
    if (c >= 'A' && c <= 'Z')
      d = c - 'A';
    else if (c >= 'a' && c <= 'z')
      d = c - 'a' + 26;
    else if (c >= '0' && c <= '9')
      d = c - '0' + 52;
    else if (c == '+')
      d = 62;
    else if (c == '/')
      d = 63;
    else
      continue;  // '=' padding, line breaks
    value = value << 6 | d;
    bits += 6;
    if (bits >= 8) {
      bits -= 8;
      out += static_cast<char>((value >> bits) & 0xff);
    }
  }
  return out;
}

// chromedriver in a process group of its own (it starts the browser), with a fresh HOME and
// profile: killed with everything it started when the object goes.
struct Driver {
  pid_t pid = -1;
  int port = 0;
  fs::path home;
  std::string session;
  std::unique_ptr<httplib::Client> http;

  Driver(const std::string& chromedriver, const std::string& chromium) {
    home = kTmp / ("webdriver_home_" + std::to_string(::getpid()));
    fs::remove_all(home);
    fs::create_directories(home);
    port = free_port();
    const std::vector<std::string> env{"HOME=" + home.string(),
                                       "XDG_CONFIG_HOME=" + (home / "config").string(),
                                       "XDG_CACHE_HOME=" + (home / "cache").string(),
                                       "TMPDIR=" + home.string(),
                                       "-DISPLAY",
                                       "-WAYLAND_DISPLAY"};
    pid = valvediag::test::spawn({chromedriver, "--port=" + std::to_string(port)},
                                 home / "chromedriver.log", env, "", true);
    REQUIRE(pid > 0);
    http = std::make_unique<httplib::Client>("127.0.0.1", port);
    http->set_connection_timeout(2, 0);
    http->set_read_timeout(60, 0);
    const auto end = Clock::now() + std::chrono::seconds(30);
    for (;;) {
      const auto r = http->Get("/status");
      if (r && r->status == 200 && json::parse(r->body)["value"]["ready"] == true) break;
      REQUIRE_MESSAGE(Clock::now() < end, "chromedriver did not start: "
                                              << valvediag::test::slurp(home / "chromedriver.log"));
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    const json caps{{"capabilities",
                     {{"alwaysMatch",
                       {{"browserName", "chrome"},
                        {"goog:chromeOptions",
                         {{"binary", chromium},
                          {"args",
                           {"--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
                            "--force-device-scale-factor=1", "--window-size=1400,2400",
                            "--user-data-dir=" + (home / "profile").string(), "--no-first-run",
                            "--no-default-browser-check", "--disable-background-networking",
                            "--disable-component-update", "--disable-sync", "--disable-extensions",
                            "--disable-default-apps", "--no-pings", "--disable-breakpad",
                            "--dns-prefetch-disable",
                            // No way out: every host name fails; the page is at an IP address.
                            "--host-resolver-rules=MAP * ~NOTFOUND, EXCLUDE 127.0.0.1"}}}}}}}}};
    const json s = call("POST", "/session", caps);
    session = s["sessionId"];
  }
  ~Driver() {
    if (!session.empty() && http) (void)http->Delete("/session/" + session);
    if (pid > 0) {
      ::kill(-pid, SIGKILL);  // chromedriver and the browser it started
      ::waitpid(pid, nullptr, 0);
    }
    std::error_code ec;
    fs::remove_all(home, ec);
  }
  // One WebDriver command; its "value".
  json call(const std::string& method, const std::string& path, const json& body = json::object()) {
    httplib::Result r = method == "GET"    ? http->Get(path)
                        : method == "POST" ? http->Post(path, body.dump(), "application/json")
                                           : http->Delete(path);
    REQUIRE_MESSAGE(r, "WebDriver " << method << " " << path << ": no answer");
    const json j = json::parse(r->body);
    REQUIRE_MESSAGE(r->status == 200, "WebDriver " << method << " " << path << ": " << r->body);
    return path == "/session" ? j["value"] : j["value"];
  }
  json session_call(const std::string& method, const std::string& path,
                    const json& body = json::object()) {
    return call(method, "/session/" + session + path, body);
  }
  json script(const std::string& js) {
    return session_call("POST", "/execute/sync", {{"script", js}, {"args", json::array()}});
  }
  // Clicks the element `css` selects. The page redraws its pickers and tables from the server's
  // answers, so an element found a moment before may be gone: then it is found again.
  void click(const std::string& css) {
    for (int attempt = 0;; ++attempt) {
      const json e = session_call("POST", "/element", {{"using", "css selector"}, {"value", css}});
      const std::string path =
          "/session/" + session + "/element/" + e[kElement].get<std::string>() + "/click";
      const httplib::Result r = http->Post(path, "{}", "application/json");
      REQUIRE_MESSAGE(r, "WebDriver POST " << path << ": no answer");
      if (r->status == 200) return;
      const bool stale =
          json::parse(r->body)["value"].value("error", "") == "stale element reference";
      REQUIRE_MESSAGE((stale && attempt < 5), "WebDriver click on " << css << ": " << r->body);
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
  }
  // Waits until `js` returns something other than null or false; its value.
  json wait_for(const std::string& js, double limit_s, const std::string& what) {
    const auto end = Clock::now() + std::chrono::duration<double>(limit_s);
    for (;;) {
      json v = script(js);
      if (!v.is_null() && v != false) return v;
      if (Clock::now() >= end) {
        // Asked here, not in the assertion's message: doctest builds that message under its
        // reporter's lock (with -s for every assertion), and script() asserts too.
        const json error = script("return document.getElementById('error').textContent");
        FAIL("the page did not show " << what << " within " << limit_s
                                      << " s; its error: " << error);
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
  }
};

struct Picture {
  int width = 0, height = 0;
  double content_share = 0.0;  // pixels not of the background colour
  long colour_pixels = 0;      // saturated colour: the charts' lines
  std::size_t colours = 0;
};

Picture look_at(const std::string& png) {
  png_image image{};
  image.version = PNG_IMAGE_VERSION;
  REQUIRE_MESSAGE(png_image_begin_read_from_memory(&image, png.data(), png.size()) != 0,
                  image.message);
  image.format = PNG_FORMAT_RGB;
  std::vector<std::uint8_t> rgb(PNG_IMAGE_SIZE(image));
  REQUIRE(png_image_finish_read(&image, nullptr, rgb.data(), 0, nullptr) != 0);
  Picture p;
  p.width = static_cast<int>(image.width);
  p.height = static_cast<int>(image.height);
  std::map<std::uint32_t, long> hist;
  for (std::size_t i = 0; i + 2 < rgb.size(); i += 3) {
    const int r = rgb[i], g = rgb[i + 1], b = rgb[i + 2];
    ++hist[std::uint32_t(r) << 16 | std::uint32_t(g) << 8 | std::uint32_t(b)];
    p.colour_pixels += std::max({r, g, b}) - std::min({r, g, b}) >= 60;
  }
  long most = 0;
  for (const auto& [c, n] : hist) most = std::max(most, n);
  p.colours = hist.size();
  p.content_share = 1.0 - static_cast<double>(most) / (static_cast<double>(rgb.size()) / 3.0);
  return p;
}

}  // namespace

// chromedriver and chromium from PATH, or the test fails saying how to install them.
std::pair<std::string, std::string> browser() {
  const std::string chromedriver = on_path("chromedriver"), chromium = on_path("chromium");
  if (chromedriver.empty() || chromium.empty())
    FAIL(
        "headless Chromium and its WebDriver (Debian packages chromium and chromium-driver) are "
        "not on PATH: run VALVEDIAG_TEST_DEPS=1 scripts/install-deps.sh");
  return {chromedriver, chromium};
}

TEST_CASE(
    "the workbench in Chromium: the top finding is the hidden stiction, Add lowers the "
    "validation error") {
  const auto [chromedriver, chromium] = browser();
  // The paper's Example 1 loop: He stiction hidden, the page starts from the linear model.
  const fs::path csv = kTmp / "workbench_browser_ex1.csv";
  const auto sim = valvediag::test::run_cli(VALVEDIAG_BIN,
                                            {"simulate", "--scenario", "paper-ex1", "--seed", "1",
                                             "--samples", "1500", "--out", csv.string()},
                                            kTmp, 60.0);
  REQUIRE_MESSAGE(sim.status == 0, sim.out);
  valvediag::test::ServeProcess server(
      VALVEDIAG_BIN, {"serve", csv.string(), "--port", "0", "--token"}, kTmp, "browser");
  REQUIRE(server.port > 0);
  Driver d(chromedriver, chromium);
  d.session_call(
      "POST", "/url",
      {{"url", "http://127.0.0.1:" + std::to_string(server.port) + "/?token=" + server.token}});

  // The page diagnoses the linear model by itself: the findings, ranked.
  const std::string idle = "document.body.dataset.job === 'idle'";
  const json top = d.wait_for(
      "const r = document.querySelector('#findings tbody tr');"
      "return " +
          idle + " && r ? r.dataset.effect : null;",
      120.0, "the findings");
  CHECK(top == "stiction");
  const json ladder0 = d.script("return document.querySelectorAll('#ladder tbody tr').length;");
  CHECK(ladder0 == 1);

  // Add the top finding: the ladder grows by its step.
  d.click("#findings tbody tr:first-child button.add");
  const json rows = d.wait_for(
      "const rows = [...document.querySelectorAll('#ladder tbody tr')];"
      "return rows.length >= 2 ? rows.map((r) => [r.dataset.model, Number(r.dataset.validation)])"
      " : null;",
      120.0, "a second ladder step");
  REQUIRE(rows.size() == 2);
  CHECK(rows[0][0] == "linear");
  CHECK(rows[1][0] == "stiction");
  // Fitness is 100 % minus the normalized error: the validation error fell by tens of points.
  const double before = 100.0 - rows[0][1].get<double>(), after = 100.0 - rows[1][1].get<double>();
  MESSAGE("validation error " << before << " % -> " << after << " %");
  CHECK(after < before - 20.0);
  CHECK(after < 10.0);

  // The page then diagnoses the new model; once it has, the picture.
  d.wait_for("return " + idle +
                 " && document.getElementById('findings-model').textContent.includes('stiction');",
             120.0, "the findings of the stiction model");
  CHECK(d.script("return document.getElementById('model-name').textContent;")
            .get<std::string>()
            .find("stiction") != std::string::npos);
  // The phase plots: the stiction model's valve signature and PV against OP, each a path with
  // its estimation part (blue) and its held-out part (orange) drawn. Model B, the linear model,
  // has no valve effect, so no signature of its own.
  const json xy = d.wait_for(
      "const x = wb.xy; return x.signature && x.phase && x.signature.points > 0 &&"
      " x.phase.points > 0 && x.signature.series.length === 2 && x.phase.series.length === 2"
      " ? [x.signature.series, x.phase.series] : null;",
      60.0, "the valve signature and PV against OP");
  MESSAGE("phase plots: " << xy.dump());
  CHECK(xy[0][0]["label"] == "A, estimation part");
  CHECK(xy[0][1]["label"] == "A, held out");
  CHECK(xy[1][0]["label"] == "estimation part");
  for (const auto& chart : xy)
    for (const auto& series : chart) CHECK(series["points"].get<int>() > 50);
  // Their canvases hold blue and orange lines, not a blank rectangle.
  const json ink = d.script(
      "return ['signature-chart', 'phase-chart'].map((id) => {"
      "  const c = document.getElementById(id);"
      "  const p = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;"
      "  let blue = 0, orange = 0;"
      "  for (let i = 0; i < p.length; i += 4) {"
      "    if (p[i + 3] < 128) continue;"
      "    if (p[i + 2] > p[i] + 60) ++blue; else if (p[i] > p[i + 2] + 100) ++orange; }"
      "  return [c.width, c.height, blue, orange]; });");
  MESSAGE("phase plot pixels (width, height, blue, orange): " << ink.dump());
  for (const auto& c : ink) {
    CHECK(c[0].get<int>() > 300);
    CHECK(c[2].get<int>() > 500);
    CHECK(c[3].get<int>() > 200);
  }
  // Model A and model B side by side: the new model beside the one before it.
  const json compared = d.wait_for(
      "const rows = [...document.querySelectorAll('#compare-table tbody tr[data-tag]')];"
      "return rows.length === 2 ? rows.map((r) => [r.dataset.tag, Number(r.dataset.step)]) : null;",
      30.0, "models A and B compared");
  CHECK(compared == json::parse(R"([["A", 1], ["B", 0]])"));
  std::this_thread::sleep_for(std::chrono::milliseconds(500));  // the charts' last redraw
  MESSAGE("jobs: " << d.script("return wb.history;").dump());
  const std::string png = base64_decode(d.session_call("GET", "/screenshot").get<std::string>());
  const fs::path shot = kTmp / "workbench.png";
  std::ofstream(shot, std::ios::binary) << png;
  const Picture p = look_at(png);
  MESSAGE(shot.string() << ": " << p.width << "x" << p.height << ", content " << p.content_share
                        << ", " << p.colours << " colours, " << p.colour_pixels
                        << " colour pixels");
  CHECK(p.width >= 1000);
  CHECK(p.content_share > 0.2);    // not a blank page
  CHECK(p.colours > 200);          // text, charts, shading
  CHECK(p.colour_pixels > 20000);  // the charts' lines and shaded parts

  // Zoom to 100 s of the record: the page asks the server again for that window, so every one of
  // its 201 samples is drawn (the whole record's buckets hold about one and a quarter each).
  d.script("zoomTo(200, 300); return true;");
  const json inside = d.wait_for(
      "const g = wb.charts.trend; let n = 0;"
      "for (let i = 0; i < g.numRows(); ++i) { const x = g.getValue(i, 0);"
      "  if (x >= 200 && x <= 300) ++n; }"
      "return n >= 201 ? n : null;",
      60.0, "the zoomed window's samples");
  CHECK(inside == 201);
  // The phase plots follow the window: PV against OP through its 201 samples, all estimation.
  const json phase = d.wait_for(
      "const p = wb.xy.phase;"
      "return p && p.series.length === 1 && p.points === 201 ? p.series[0].label : null;",
      60.0, "PV against OP of the zoomed window");
  CHECK(phase == "estimation part");
  const json dw = d.script("return wb.charts.trend.xAxisRange();");
  CHECK(dw[0] == 200);
  CHECK(dw[1] == 300);
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  const std::string zoomed = base64_decode(d.session_call("GET", "/screenshot").get<std::string>());
  std::ofstream(kTmp / "workbench_zoomed.png", std::ios::binary) << zoomed;
  CHECK(look_at(zoomed).content_share > 0.2);

  // Remove goes back down: the ladder's third step is the linear model again.
  d.click("#remove-btn");
  const json third = d.wait_for(
      "const rows = document.querySelectorAll('#ladder tbody tr');"
      "return rows.length >= 3 ? rows[2].dataset.model : null;",
      120.0, "the ladder's step after Remove");
  CHECK(third == "linear");

  // Compare any two models: A the stiction model (step 1), B the later linear one (step 2), picked
  // in the selectors above the chart.
  // Remove's job, then the diagnosis of the model it left (a job done moves A to the last step).
  d.wait_for("return wb.history.length >= 5 && " + idle + ";", 120.0, "the diagnosis after Remove");
  const auto pick = [&](const std::string& select, const std::string& value) {
    d.click("#" + select + " option[value=\"" + value + "\"]");
  };
  pick("model-a", "1");
  d.wait_for(
      "const l = wb.charts.fit.getLabels();"
      "return l.length === 4 && l[2].startsWith('A: step 1') && l[3].startsWith('B: step 0');",
      30.0, "model A picked, with the step before it as B");
  pick("model-b", "2");
  const json labels = d.wait_for(
      "const l = wb.charts.fit.getLabels();"
      "return l.length === 4 && l[3].startsWith('B: step 2') ? l : null;",
      30.0, "the chart of models A and B");
  CHECK(labels[2] == "A: step 1, stiction");
  CHECK(labels[3] == "B: step 2, linear");
  // Both simulated PVs are drawn, and the fitness table holds the ladder's figures of each.
  const json drawn = d.script(
      "const g = wb.charts.fit; let a = 0, b = 0;"
      "for (let i = 0; i < g.numRows(); ++i) { if (g.getValue(i, 2)) ++a; if (g.getValue(i, 3)) "
      "++b; }"
      "return [a, b];");
  CHECK(drawn[0].get<int>() > 100);
  CHECK(drawn[1].get<int>() > 100);
  const json table = d.script(
      "return [...document.querySelectorAll('#compare-table tbody tr[data-tag]')].map((r) =>"
      " [r.dataset.tag, Number(r.dataset.step), Number(r.dataset.validation)]);");
  const json ladder = d.script(
      "return [...document.querySelectorAll('#ladder tbody tr')].map((r) =>"
      " Number(r.dataset.validation));");
  REQUIRE(table.size() == 2);
  CHECK(table[0][0] == "A");
  CHECK(table[0][1] == 1);
  CHECK(table[0][2].get<double>() == ladder[1].get<double>());
  CHECK(table[1][0] == "B");
  CHECK(table[1][1] == 2);
  CHECK(table[1][2].get<double>() == ladder[2].get<double>());
  CHECK(table[0][2].get<double>() > table[1][2].get<double>() + 20.0);

  // Drag the split's edge on the trends from 30 % held out to half: on release the next job
  // holds out that share. The whole record shown first (the split lies outside the zoom).
  d.script("window.scrollTo(0, 0); zoomTo(wb.loop.start_s, wb.loop.end_s); return true;");
  d.wait_for(
      "const r = wb.charts.trend.xAxisRange(); return r[0] === wb.loop.start_s &&"
      " r[1] === wb.loop.end_s;",
      30.0, "the whole record on the trends");
  CHECK(d.script("return nextShare();") == 0.3);
  const json at = d.script(
      "const g = wb.charts.trend, r = g.graphDiv.getBoundingClientRect(), a = g.getArea();"
      "return [r.left + g.toDomXCoord(nextSplitTime()), r.left + g.toDomXCoord(nextSplitTime(0.5)),"
      " r.top + a.y + a.h / 2];");
  const auto px = [](const json& v) { return static_cast<int>(std::lround(v.get<double>())); };
  const json range_before = d.script("return wb.charts.trend.xAxisRange();");
  d.session_call(
      "POST", "/actions",
      {{"actions",
        {{{"type", "pointer"},
          {"id", "mouse"},
          {"parameters", {{"pointerType", "mouse"}}},
          {"actions",
           {{{"type", "pointerMove"}, {"duration", 0}, {"x", px(at[0])}, {"y", px(at[2])}},
            {{"type", "pointerDown"}, {"button", 0}},
            {{"type", "pointerMove"}, {"duration", 300}, {"x", px(at[1])}, {"y", px(at[2])}},
            {{"type", "pointerUp"}, {"button", 0}}}}}}}});
  const json share = d.wait_for("return wb.validate;", 10.0, "the split dragged");
  MESSAGE("held out after the drag: " << share.dump());
  CHECK(share.get<double>() == doctest::Approx(0.5).epsilon(0.02));
  CHECK(d.script("return wb.charts.trend.xAxisRange();") == range_before);  // a drag, no zoom
  CHECK(d.script("return document.getElementById('split-info').textContent;")
            .get<std::string>()
            .find("(for the next jobs)") != std::string::npos);
  // The next job, a diagnosis of model A's model, asks for that share and fits with it.
  const std::size_t jobs_before = d.script("return wb.history.length;").get<std::size_t>();
  d.click("#diagnose-btn");
  d.wait_for("return wb.history.length > " + std::to_string(jobs_before) + " && " + idle + ";",
             120.0, "the diagnosis with the dragged split");
  CHECK(d.script("return wb.jobs[wb.jobs.length - 1].validate;") == share);
  const json used = d.session_call(
      "POST", "/execute/async",
      {{"script",
        "const done = arguments[arguments.length - 1];"
        "fetch('/api/loops/0/diagnosis').then((r) => r.json()).then((j) => done(j.data));"},
       {"args", json::array()}});
  INFO(used.dump());
  CHECK(used["validate"] == share);
  CHECK(used["samples"] == 1500);
  CHECK(server.stop() == 0);
}

TEST_CASE(
    "the workbench in Chromium on a live recording: the trends and the bus status follow it, "
    "nothing is written to the PLC") {
  const auto [chromedriver, chromium] = browser();
  // The simulated PLC at 100 times real time; the site records its FIC101 every 5 ms.
  valvediag::SimPlc plc(valvediag::load_site_config(kSimSite), valvediag::SimPlcOptions{100.0, 0});
  plc.start();
  const fs::path site = kTmp / "workbench_browser_live.toml";
  std::ofstream(site) << "[[bus]]\nname = \"plc\"\nprotocol = \"modbus-tcp\"\n"
                      << "controller = \"tcp://127.0.0.1:" << plc.port() << "\"\n"
                      << "timeout = \"100ms\"\nretries = 0\nreconnect_max = \"500ms\"\n"
                      << "[[loop]]\nname = \"FIC101\"\nbus = \"plc\"\nsample_period = 0.005\n"
                      << "op = { register = \"holding\", address = 0, type = \"FLOAT32\" }\n"
                      << "pv = { register = \"holding\", address = 2, type = \"FLOAT32\" }\n"
                      << "sp = { register = \"holding\", address = 4, type = \"FLOAT32\" }\n";
  const fs::path db = kTmp / ("workbench_browser_live_" + std::to_string(::getpid()) + ".sqlite");
  const fs::path state = kTmp / ("workbench_browser_live_state_" + std::to_string(::getpid()));
  for (const char* suffix : {"", "-wal", "-shm", ".lock"}) fs::remove(db.string() + suffix);
  fs::remove_all(state);
  valvediag::test::ServeProcess server(
      VALVEDIAG_BIN, {"serve", "--config", site.string(), "--db", db.string(), "--port", "0"}, kTmp,
      "browser_live", 60.0, {"XDG_STATE_HOME=" + state.string()});
  REQUIRE(server.port > 0);
  Driver d(chromedriver, chromium);
  d.session_call("POST", "/url",
                 {{"url", "http://127.0.0.1:" + std::to_string(server.port) + "/"}});

  // The live bar: the recording and the bus's counters, from the recorder.
  const json bar = d.wait_for(
      "const t = document.getElementById('live-text').textContent;"
      "return !document.getElementById('live').hidden && t.includes('bus plc up') ? t : null;",
      60.0, "the live bar");
  MESSAGE("live bar: " << bar.get<std::string>());
  CHECK(bar.get<std::string>().find("samples stored") != std::string::npos);
  // The trends follow the recording: the page's loop and the trend's last time grow by
  // themselves, polled once a second, with no click.
  const std::string now =
      "const g = wb.charts.trend; return wb.loop && g && g.numRows() > 0 ?"
      " [wb.loop.samples, g.getValue(g.numRows() - 1, 0)] : null;";
  const json a = d.wait_for(now, 60.0, "the live trends");
  const json b = d.wait_for(
      "const g = wb.charts.trend; const s = wb.loop.samples, t = g.getValue(g.numRows() - 1, 0);"
      "return s >= " +
          std::to_string(a[0].get<long>() + 200) +
          " && t >= " + std::to_string(a[1].get<double>() + 1.0) + " ? [s, t] : null;",
      60.0, "the trends growing");
  MESSAGE("samples " << a[0] << " -> " << b[0] << ", last time " << a[1] << " s -> " << b[1]
                     << " s");
  // No model yet: the model's panel shows the measured PV, and follows the recording too.
  const json fit = d.wait_for(
      "const g = wb.charts.fit; return !wb.shown && g && g.numRows() > 1 &&"
      " g.getLabels()[1] === 'PV measured' && g.getValue(g.numRows() - 1, 0) >= " +
          std::to_string(b[1].get<double>()) + " ? g.getValue(g.numRows() - 1, 0) : null;",
      30.0, "the measured PV in the model's panel");
  MESSAGE("model panel without a model: measured PV to " << fit << " s");
  // The loop list's entry says so too, with the sample period as set (5 ms, not 0.01 s).
  const json listed =
      d.script("return document.querySelector('#loop-list li .muted').textContent;");
  CHECK(listed.get<std::string>().find("samples, 5 ms") != std::string::npos);
  CHECK(d.script("return document.getElementById('loop-info').textContent;")
            .get<std::string>()
            .find("every 5 ms") != std::string::npos);
  const std::string png = base64_decode(d.session_call("GET", "/screenshot").get<std::string>());
  std::ofstream(kTmp / "workbench_live.png", std::ios::binary) << png;
  CHECK(look_at(png).content_share > 0.2);
  // The page's own requests: reads only, on every path; the PLC saw not one write.
  CHECK(server.stop() == 0);
  CHECK(plc.write_requests() == 0);
  fs::remove_all(state);
  for (const char* suffix : {"", "-wal", "-shm", ".lock"}) fs::remove(db.string() + suffix);
}
