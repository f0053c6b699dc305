// The report and the sweep page as a browser shows them: each is rendered 1280 px wide by headless
// Chromium (Debian `chromium`), and the screenshot, decoded with libpng, must show a page: text,
// the plots drawn in colour, nothing wider than the window. A control page that is blank and too
// wide shows that each measurement can fail.
#include <doctest/doctest.h>
#include <png.h>
#include <signal.h>
#include <stdlib.h>
#include <unistd.h>

#include <algorithm>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <regex>
#include <sstream>
#include <string>
#include <tuple>
#include <vector>

#include "../common/run_cli.hpp"
#include "../common/text.hpp"
#include "page_checks.hpp"

namespace fs = std::filesystem;

namespace {

constexpr int kWidth = 1280;
// The browser's time limit: a page this size renders in a few seconds.
constexpr double kBrowserLimitS = 60.0;

const fs::path kTmp = VALVEDIAG_TMP;

using valvediag::test::slurp;

valvediag::test::CliResult valvediag_cli(const std::vector<std::string>& args) {
  return valvediag::test::run_cli(VALVEDIAG_BIN, args, kTmp, 120.0);
}

// `chromium` on PATH, or "" when it is not installed.
std::string find_chromium() {
  const char* path = std::getenv("PATH");
  std::istringstream dirs(path ? path : "");
  for (std::string d; std::getline(dirs, d, ':');) {
    const fs::path p = fs::path(d.empty() ? "." : d) / "chromium";
    if (::access(p.c_str(), X_OK) == 0) return p.string();
  }
  return "";
}

// A folder of its own under the system's temp folder, removed with the object.
struct TempDir {
  fs::path path;
  TempDir() {
    std::string t = (fs::temp_directory_path() / "valvediag-chromium-XXXXXX").string();
    REQUIRE(::mkdtemp(t.data()) != nullptr);
    path = t;
  }
  ~TempDir() {
    std::error_code ec;
    fs::remove_all(path, ec);
  }
};

// Screenshots `page` (a local file) in a window kWidth x `height` into `png`. The browser gets a
// fresh profile and HOME in a temp folder, so it writes nothing elsewhere, and no way out to the
// network: the pages are self-contained, and any request (a page's or the browser's own) meets
// a proxy on a closed local port and a resolver that finds no host. It runs in a process group of
// its own, so that on its time limit the whole browser (renderer, GPU and utility processes) is
// killed, not just the first process.
void screenshot(const std::string& chromium, const fs::path& page, const fs::path& png,
                int height) {
  TempDir profile;
  fs::remove(png);
  const std::vector<std::string> args{
      chromium,
      "--headless",
      "--no-sandbox",  // CI runs as root
      "--disable-gpu",
      "--hide-scrollbars",
      "--force-device-scale-factor=1",
      "--user-data-dir=" + (profile.path / "profile").string(),
      "--no-first-run",
      "--no-default-browser-check",
      "--disable-background-networking",
      "--disable-component-update",
      "--disable-sync",
      "--disable-extensions",
      "--disable-default-apps",
      "--disable-domain-reliability",
      "--no-pings",
      "--disable-client-side-phishing-detection",
      "--disable-breakpad",
      "--metrics-recording-only",
      "--dns-prefetch-disable",
      "--proxy-server=127.0.0.1:9",
      "--host-resolver-rules=MAP * ~NOTFOUND",
      "--disable-features=Translate,OptimizationHints,MediaRouter,AutofillServerCommunication",
      "--window-size=" + std::to_string(kWidth) + "," + std::to_string(height),
      "--screenshot=" + png.string(),
      "file://" + fs::absolute(page).string()};
  const std::vector<std::string> env{"HOME=" + profile.path.string(),
                                     "XDG_CONFIG_HOME=" + (profile.path / "config").string(),
                                     "XDG_CACHE_HOME=" + (profile.path / "cache").string(),
                                     "TMPDIR=" + profile.path.string(),
                                     "-DISPLAY",
                                     "-WAYLAND_DISPLAY"};
  const fs::path log = profile.path / "chromium.log";
  const pid_t pid = valvediag::test::spawn(args, log, env, "", true);
  REQUIRE(pid > 0);
  const int status = valvediag::test::wait_child(pid, kBrowserLimitS);
  ::kill(-pid, SIGKILL);  // what is left of the browser, or all of it on the time limit
  INFO("chromium's output:\n", slurp(log));
  REQUIRE_MESSAGE(status != -1, "chromium did not finish rendering "
                                    << page << " in " << kBrowserLimitS << " s; killed");
  REQUIRE_MESSAGE(status == 0, "chromium failed on " << page << " (status " << status << ")");
  REQUIRE_MESSAGE(fs::exists(png), "chromium wrote no screenshot " << png);
}

struct Shot {
  int width = 0, height = 0;
  std::vector<std::uint8_t> rgb;  // width * height * 3
};

Shot decode(const fs::path& png) {
  png_image image{};
  image.version = PNG_IMAGE_VERSION;
  REQUIRE_MESSAGE(png_image_begin_read_from_file(&image, png.c_str()) != 0, image.message);
  image.format = PNG_FORMAT_RGB;
  Shot s;
  s.width = static_cast<int>(image.width);
  s.height = static_cast<int>(image.height);
  s.rgb.resize(PNG_IMAGE_SIZE(image));
  REQUIRE_MESSAGE(png_image_finish_read(&image, nullptr, s.rgb.data(), 0, nullptr) != 0,
                  image.message);
  return s;
}

// What the screenshot shows, in figures a blank or broken page would fail.
struct Measures {
  double content_share = 0;  // pixels not of the background colour
  std::size_t colours = 0;   // distinct colours
  long plot_pixels = 0;  // saturated colour: the plots' lines and bars (text and tables are grey)
  int plot_bands = 0;    // 100-row bands holding at least 200 of them: how many plots drew
  int rightmost = -1;    // right-most column that is not background
  int bottom = -1;       // lowest row that is not background
};

Measures measure(const Shot& s) {
  std::map<std::uint32_t, long> hist;
  auto at = [&](int x, int y) {
    const std::uint8_t* p = &s.rgb[3 * (static_cast<std::size_t>(y) * s.width + x)];
    return std::uint32_t{p[0]} << 16 | std::uint32_t{p[1]} << 8 | p[2];
  };
  for (int y = 0; y < s.height; ++y)
    for (int x = 0; x < s.width; ++x) ++hist[at(x, y)];
  std::uint32_t bg = 0;
  long most = -1;
  for (const auto& [c, n] : hist)
    if (n > most) most = n, bg = c;
  Measures m;
  m.colours = hist.size();
  std::map<int, long> band;
  long content = 0;
  for (int y = 0; y < s.height; ++y)
    for (int x = 0; x < s.width; ++x) {
      const std::uint32_t c = at(x, y);
      if (c == bg) continue;
      ++content;
      m.rightmost = std::max(m.rightmost, x);
      m.bottom = y;
      const int r = c >> 16, g = (c >> 8) & 255, b = c & 255;
      // Chroma of at least 60: the pages' pale row and note backgrounds stay below 40.
      if (std::max({r, g, b}) - std::min({r, g, b}) >= 60) {
        ++m.plot_pixels;
        ++band[y / 100];
      }
    }
  for (const auto& [b, n] : band) m.plot_bands += n >= 200;
  m.content_share = static_cast<double>(content) / (static_cast<double>(s.width) * s.height);
  return m;
}

// Renders `page`, checks that it is one picture of a page 1280 px wide, and gives its measures.
Measures render(const std::string& chromium, const fs::path& page, const fs::path& png,
                int height) {
  screenshot(chromium, page, png, height);
  const Shot s = decode(png);
  REQUIRE(s.width == kWidth);
  REQUIRE(s.height == height);
  const Measures m = measure(s);
  MESSAGE(png.filename().string() << ": content " << m.content_share << ", " << m.colours
                                  << " colours, " << m.plot_pixels << " plot pixels in "
                                  << m.plot_bands << " bands, right-most column " << m.rightmost
                                  << ", lowest row " << m.bottom);
  return m;
}

// A page whose content reaches the window's right edge is cut off there (the screenshot is the
// window): the body's margin keeps a page that fits at least 8 px off it.
bool fits_width(const Measures& m) {
  return m.rightmost < kWidth - 8;
}

// "NaN", "nan", "-nan" as a word: a number the page failed to print (plain words such as
// "resonance" hold the letters too).
bool has_nan_text(const std::string& html) {
  static const std::regex nan(R"((^|[^A-Za-z])[-+]?nan([^A-Za-z]|$))", std::regex::icase);
  return std::regex_search(html, nan);
}

std::string chromium_or_fail() {
  const std::string c = find_chromium();
  if (c.empty())
    FAIL(
        "headless Chromium (Debian package chromium) is not on PATH: run "
        "scripts/install-deps.sh");
  return c;
}

// Where the screenshots stay after the run (the build tree), for a person to look at.
fs::path shots() {
  const fs::path dir = kTmp / "browser";
  fs::create_directories(dir);
  return dir;
}

// Short records keep the diagnoses to seconds: a sticky loop, a healthy one, and one too short to
// judge (a grey row without a bar on the sweep page).
std::vector<std::string> loops() {
  std::vector<std::string> files;
  for (const auto& [scenario, seed, samples] :
       {std::tuple{"paper-ex1", "1", "1500"}, std::tuple{"linear-clean", "2", "1500"},
        std::tuple{"linear-clean", "3", "120"}}) {
    files.push_back((shots() / (std::string(scenario) + "-" + seed + ".csv")).string());
    const auto r = valvediag_cli({"simulate", "--scenario", scenario, "--seed", seed, "--samples",
                                  samples, "--out", files.back()});
    INFO(r.out);
    REQUIRE(r.status == 0);
  }
  return files;
}

}  // namespace

TEST_CASE("the report in headless Chromium at 1280 px: a page with its plots, not a blank") {
  const std::string chromium = chromium_or_fail();
  const fs::path html = shots() / "report.html", history = shots() / "history.json";
  // With a Preisach model and a history the page draws all of its 10 plots (the Preisach
  // triangle and the ladder too).
  fs::remove(history);
  const auto r = valvediag_cli({"report", loops()[0], "--model", "preisach:general", "--history",
                                history.string(), "--out", html.string()});
  INFO(r.out);
  REQUIRE(r.status == 0);
  REQUIRE(r.out.find("10 plots") != std::string::npos);
  const std::string h = slurp(html);
  report_test::check_self_contained(h);
  CHECK_MESSAGE(!has_nan_text(h), "the report prints a NaN");
  // The page is about 6900 px tall here; the window holds all of it.
  const Measures m = render(chromium, html, shots() / "report.png", 8000);
  // Thresholds, about half of what this page gave when they were set (content 0.094 of the
  // window, 6674 colours, 60047 plot pixels in 31 bands of 100 rows, lowest row 6872): a blank
  // page, plots that did not draw, or a page cut short fail them.
  CHECK(m.content_share > 0.045);
  CHECK(m.colours > 3000);
  CHECK(m.plot_pixels > 30000);
  CHECK(m.plot_bands >= 15);
  CHECK(m.bottom > 5000);
  CHECK_MESSAGE(fits_width(m), "the report is wider than " << kWidth << " px");
}

TEST_CASE("the sweep page in headless Chromium at 1280 px: the table and the severity chart") {
  const std::string chromium = chromium_or_fail();
  const fs::path html = shots() / "sweep.html";
  std::vector<std::string> args{"sweep", "--jobs", "2", "--quiet", "--html", html.string()};
  for (const auto& f : loops()) args.push_back(f);
  const auto r = valvediag_cli(args);
  INFO(r.out);
  REQUIRE(r.status == 0);
  const std::string h = slurp(html);
  report_test::check_self_contained(h);
  CHECK_MESSAGE(!has_nan_text(h), "the sweep page prints a NaN");
  const Measures m = render(chromium, html, shots() / "sweep.png", 1000);
  // Thresholds, about half of what this page gave when they were set (content 0.143, 626
  // colours, 6760 plot pixels: the severity chart's bars, in 1 band).
  CHECK(m.content_share > 0.07);
  CHECK(m.colours > 300);
  CHECK(m.plot_pixels > 3000);
  CHECK(m.plot_bands >= 1);
  CHECK_MESSAGE(fits_width(m), "the sweep page is wider than " << kWidth << " px");
}

TEST_CASE("control: a blank page too wide for the window fails the measures") {
  const std::string chromium = chromium_or_fail();
  const fs::path html = shots() / "control.html";
  std::ofstream(html) << "<!DOCTYPE html><html><body><div style=\"width:1600px;height:2px;"
                         "background:#222\"></div></body></html>\n";
  const Measures m = render(chromium, html, shots() / "control.png", 400);
  CHECK(m.content_share < 0.01);
  CHECK(m.plot_pixels == 0);
  CHECK(!fits_width(m));
  CHECK(has_nan_text("<td>nan</td>"));
  CHECK(has_nan_text("x=-NaN"));
  CHECK(!has_nan_text("resonance, financial"));
}
