// Replays the bus fuzz targets' seed corpora and every saved crash input
// (test/fuzz/regressions/{site_config,dbc,codec}): each must be handled, never a crash.
#include <doctest/doctest.h>

#include <filesystem>
#include <fstream>
#include <sstream>

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
  for (const char* name : {"site.toml", "sim-site.toml", "can-site.toml"}) {
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
