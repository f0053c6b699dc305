// Replays the fuzz seed corpus and every saved fuzz crash input (test/fuzz/regressions/csv):
// each must parse into consistent data or be refused with a DataError.
#include <doctest/doctest.h>

#include <filesystem>
#include <fstream>
#include <sstream>

#include "fuzz_csv_harness.hpp"

namespace fs = std::filesystem;

namespace {

std::size_t replay(const fs::path& dir) {
  std::size_t n = 0;
  if (!fs::is_directory(dir)) return 0;
  for (const auto& e : fs::directory_iterator(dir)) {
    if (!e.is_regular_file() || e.path().filename().string().front() == '.') continue;
    std::ifstream in(e.path(), std::ios::binary);
    std::stringstream ss;
    ss << in.rdbuf();
    INFO(e.path().string());
    std::string problem;
    CHECK_NOTHROW(problem = valvediag::fuzz::run_csv(ss.str()));
    CHECK(problem == "");
    ++n;
  }
  return n;
}

}  // namespace

TEST_CASE("fuzz seed corpus and saved crash inputs") {
  const fs::path fuzz = fs::path(VALVEDIAG_TEST_DIR) / "fuzz";
  CHECK(replay(fuzz / "corpus" / "csv") >= 10);
  MESSAGE("regression inputs replayed: " << replay(fuzz / "regressions" / "csv"));
}

TEST_CASE("the fuzz harness accepts the seeds it is meant to") {
  // Guards the option decoding: these seeds must parse, not merely be refused.
  const fs::path dir = fs::path(VALVEDIAG_TEST_DIR) / "fuzz" / "corpus" / "csv";
  for (const char* name :
       {"plain.csv", "historian_tab_date.txt", "plant_like.txt", "us_date_ampm.csv",
        "irregular_resample.csv", "quoted_by_number.csv", "no_time_space.txt", "wildcards.tsv",
        "bom_cr_only.csv", "month_names.csv", "semicolon_decimal_comma.csv",
        "comments_extra_columns.csv"}) {
    INFO(name);
    std::ifstream in(dir / name, std::ios::binary);
    REQUIRE(in);
    std::stringstream ss;
    ss << in.rdbuf();
    std::string text = ss.str();
    std::string_view view = text;
    const valvediag::CsvOptions o = valvediag::fuzz::options_from(view);
    CHECK_NOTHROW(valvediag::parse_loop_csv(view, o, name));
  }
}
