// Replays the fuzz seed corpus and every saved fuzz crash input (test/fuzz/regressions/csv):
// each must parse into consistent data or be refused with a DataError.
#include <doctest/doctest.h>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <utility>

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
        "comments_extra_columns.csv", "max_rows_4_ok.csv"}) {
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

TEST_CASE("the fuzz harness refuses the seeds it is meant to, at their line") {
  // Bad-value markers in OP and PV, and one row more than the harness's small max_rows.
  const fs::path dir = fs::path(VALVEDIAG_TEST_DIR) / "fuzz" / "corpus" / "csv";
  const std::pair<const char*, const char*> seeds[] = {
      {"op_1e308.csv", "op_1e308.csv:3: column 'op': '1e308' is no measurement (beyond +-1e12"},
      {"pv_double_max.csv",
       "pv_double_max.csv:3: column 'pv': '1.7976931348623157e308' is no measurement"},
      {"op_pv_markers.csv",
       "op_pv_markers.csv:2: column 'op': '1.7976931348623157e308' is no measurement"},
      {"max_rows_4.csv", "max_rows_4.csv:6: more than 4 data rows, the --max-rows limit"},
  };
  for (const auto& [name, start] : seeds) {
    INFO(std::string(name));
    std::ifstream in(dir / name, std::ios::binary);
    REQUIRE(in);
    std::stringstream ss;
    ss << in.rdbuf();
    const std::string text = ss.str();
    std::string_view view = text;
    const valvediag::CsvOptions o = valvediag::fuzz::options_from(view);
    std::string what = "no error";
    try {
      valvediag::parse_loop_csv(view, o, name);
    } catch (const valvediag::DataError& e) {
      what = e.what();
    }
    INFO(what);
    CHECK(what.rfind(start, 0) == 0);
    CHECK(valvediag::fuzz::run_csv(text) == "");
  }
}
