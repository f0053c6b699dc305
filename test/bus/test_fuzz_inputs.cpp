// Replays the bus fuzz targets' seed corpora and every saved crash input
// (test/fuzz/regressions/{site_config,dbc,codec}): each must be handled, never a crash.
#include <doctest/doctest.h>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <utility>

#include "fuzz_bus_harness.hpp"

namespace fs = std::filesystem;

namespace {
template <class F>
std::size_t replay(const fs::path& dir, F&& run) {
  std::size_t n = 0;
  if (!fs::is_directory(dir)) return 0;
  for (const auto& e : fs::directory_iterator(dir)) {
    if (!e.is_regular_file() || e.path().filename().string().front() == '.') continue;
    std::ifstream in(e.path(), std::ios::binary);
    std::stringstream ss;
    ss << in.rdbuf();
    INFO(e.path().string());
    std::string problem;
    CHECK_NOTHROW(problem = run(ss.str()));
    CHECK(problem == "");
    ++n;
  }
  return n;
}
const fs::path kFuzz = fs::path(VALVEDIAG_TEST_DIR) / "fuzz";
}  // namespace

TEST_CASE("bus fuzz corpora and saved crash inputs replay cleanly") {
  using namespace valvediag::fuzz;
  CHECK(replay(kFuzz / "corpus" / "site_config", run_site_config) >= 3);
  CHECK(replay(kFuzz / "corpus" / "dbc", run_dbc) >= 2);
  CHECK(replay(kFuzz / "corpus" / "codec", run_codec) >= 3);
  std::size_t saved = replay(kFuzz / "regressions" / "site_config", run_site_config);
  saved += replay(kFuzz / "regressions" / "dbc", run_dbc);
  saved += replay(kFuzz / "regressions" / "codec", run_codec);
  MESSAGE("saved crash inputs replayed: " << saved);
}

TEST_CASE("the seeds parse rather than being refused") {
  // Guards the harness: a seed that is refused tests only the error path.
  for (const char* name : {"site.toml", "sim-site.toml", "can-site.toml", "rtu_over_tcp.toml"}) {
    std::ifstream in(kFuzz / "corpus" / "site_config" / name);
    std::stringstream ss;
    ss << in.rdbuf();
    INFO(name);
    CHECK_NOTHROW(valvediag::parse_site_config(ss.str(), name, ""));
  }
  std::ifstream in(kFuzz / "corpus" / "dbc" / "mux_ext.dbc");
  std::stringstream ss;
  ss << in.rdbuf();
  CHECK(valvediag::parse_dbc(ss.str(), "mux_ext.dbc").messages.size() == 2);
}

TEST_CASE("the bad site seeds are refused at their line, saying what to do") {
  const std::pair<const char*, const char*> seeds[] = {
      {"bad_no_sample_period.toml",
       "bad_no_sample_period.toml:5:1: loop[0]: missing key 'sample_period'; add"},
      {"bad_port_0.toml", "bad_port_0.toml:4:14: bus[0].controller: port '0' is not 1..65535"},
      {"bad_byte_order_width.toml",
       "bad_byte_order_width.toml:9:72: loop[0].op.byte_order: 'CDAB' orders the 4 bytes"},
      {"bad_nul_in_string.toml",
       "bad_nul_in_string.toml:9:12: loop[0].simulate: holds a NUL character"},
      {"bad_names_differ_in_case.toml",
       "bad_names_differ_in_case.toml:12:8: loop[1].name: loop 'fic101' differs from loop "
       "'FIC101' (line 5) only in upper and lower case"},
  };
  for (const auto& [name, start] : seeds) {
    INFO(std::string(name));
    std::ifstream in(kFuzz / "corpus" / "site_config" / name);
    REQUIRE(in);
    std::stringstream ss;
    ss << in.rdbuf();
    std::string what = "no error";
    try {
      valvediag::parse_site_config(ss.str(), name, "");
    } catch (const valvediag::SiteConfigError& e) {
      what = e.what();
    }
    INFO(what);
    CHECK(what.rfind(start, 0) == 0);
  }
}
