// The real historian exports in shared/data/plant-loops must be readable with options alone.
#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "valvediag/io/csv_reader.hpp"
#include "valvediag/io/data_checks.hpp"
#include "valvediag/io/data_error.hpp"

namespace fs = std::filesystem;
using valvediag::CsvOptions;
using valvediag::DataError;
using valvediag::LoopData;

namespace {

// The one option set for all of them (the CLI equivalent is in the report / README):
// --delimiter tab --skip-lines 2 --skip-after-header 2 --time-format "%Y-%m-%d %H:%M:%S"
// --t tagname --op "*.MV" --pv "*.PV" --sp "*.SV"
// by_number: the same columns as --t 1 --op 2 --pv 3 --sp 4, with --delimiter auto.
CsvOptions plant_options(bool by_number = false) {
  CsvOptions o;
  o.delimiter = by_number ? "auto" : "tab";
  o.skip_lines = 2;         // title line; column count / sample period / start / row count
  o.skip_after_header = 2;  // descriptions; identification settings
  o.time_format = "%Y-%m-%d %H:%M:%S";
  o.t_column = by_number ? "1" : "tagname";
  o.op_column = by_number ? "2" : "*.MV";  // the controller output tag
  o.pv_column = by_number ? "3" : "*.PV";
  o.sp_column = by_number ? "4" : "*.SV";
  return o;
}

// This export repeats a stamp every 5 minutes and skips the next one (the rows themselves are
// 10 s apart), so its time stamps cannot be used as they are.
const std::string kBadStamps = "stic_RHT.7050-342_FIC10112_0702_0009_Stick1=1.txt";

std::vector<std::string> split_tabs(const std::string& line) {
  std::vector<std::string> out;
  std::stringstream ss(line);
  std::string cell;
  while (std::getline(ss, cell, '\t')) out.push_back(cell);
  return out;
}

// What the export says about itself, read independently of the reader under test: line 2 holds
// "columns <tab> sample period <tab> start <tab> rows"; line 6 is the first data row.
struct Header {
  std::size_t rows = 0;
  double period = 0;
  double first_op = 0, first_pv = 0, first_sp = 0;
};

Header read_header(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::string line;
  std::vector<std::string> lines;
  while (lines.size() < 6 && std::getline(in, line)) {
    if (!line.empty() && line.back() == '\r') line.pop_back();
    lines.push_back(line);
  }
  REQUIRE(lines.size() == 6);
  const auto meta = split_tabs(lines[1]);
  const auto first = split_tabs(lines[5]);
  REQUIRE(meta.size() == 4);
  REQUIRE(first.size() == 9);
  Header h;
  h.period = std::strtod(meta[1].c_str(), nullptr);
  h.rows = std::strtoul(meta[3].c_str(), nullptr, 10);
  h.first_op = std::strtod(first[1].c_str(), nullptr);
  h.first_pv = std::strtod(first[2].c_str(), nullptr);
  h.first_sp = std::strtod(first[3].c_str(), nullptr);
  return h;
}

std::vector<fs::path> plant_files(const char* group) {
  std::vector<fs::path> files;
  const fs::path dir = fs::path(VALVEDIAG_DATA_DIR) / "plant-loops" / group;
  REQUIRE_MESSAGE(fs::is_directory(dir), dir.string());
  for (const auto& e : fs::directory_iterator(dir))
    if (e.is_regular_file()) files.push_back(e.path());
  std::sort(files.begin(), files.end());
  return files;
}

bool all_finite(const std::vector<double>& v) {
  return std::all_of(v.begin(), v.end(), [](double x) { return std::isfinite(x); });
}

}  // namespace

TEST_CASE("all 41 plant-loop exports read with one set of options") {
  const auto stiction = plant_files("stiction");
  const auto clean = plant_files("no-stiction");
  CHECK(stiction.size() == 18);
  CHECK(clean.size() == 23);
  std::vector<fs::path> files = stiction;
  files.insert(files.end(), clean.begin(), clean.end());

  std::size_t read = 0, rows751 = 0;
  for (const fs::path& p : files) {
    INFO(p.string());
    const Header h = read_header(p);
    if (p.filename() == kBadStamps) {
      try {
        valvediag::read_loop_csv(p.string(), plant_options());
        FAIL("the repeated time stamp was not noticed");
      } catch (const DataError& e) {
        CHECK(e.line == 36);
        CHECK(e.column == "tagname");
        CHECK(std::string(e.what()).find("time '2024-07-01 21:59:50' is not after the previous "
                                         "row's '2024-07-01 21:59:50' (line 35): duplicate") !=
              std::string::npos);
      }
      continue;
    }
    std::vector<std::string> notes;
    const LoopData d = valvediag::read_loop_csv(p.string(), plant_options(), &notes);
    ++read;
    CHECK(d.size() == h.rows);
    rows751 += d.size() == 751;
    REQUIRE(d.size() >= 2);
    CHECK(d.t.front() == 0.0);
    CHECK(d.sample_period() == h.period);
    CHECK(d.t.back() == doctest::Approx(h.period * static_cast<double>(h.rows - 1)));
    for (std::size_t i = 1; i < d.size(); ++i) REQUIRE(d.t[i] - d.t[i - 1] == h.period);
    CHECK(d.op.front() == h.first_op);
    CHECK(d.pv.front() == h.first_pv);
    CHECK(d.sp.front() == h.first_sp);
    CHECK(d.pv.size() == d.size());
    CHECK(d.sp.size() == d.size());
    CHECK_FALSE(d.has_mv());
    CHECK(all_finite(d.op));
    CHECK(all_finite(d.pv));
    CHECK(all_finite(d.sp));
    CHECK(notes.size() == 2);  // columns used, time origin; no resampling
  }
  CHECK(read == 40);
  // The data README says 751 rows at 10 s; one export (CDU LIC63001) has 126 rows at 60 s.
  CHECK(rows751 == 39);
}

TEST_CASE("plant-loop exports by column number give the same data") {
  const fs::path p = fs::path(VALVEDIAG_DATA_DIR) / "plant-loops" / "stiction" /
                     "stic_2411FIC20102_1004_0005_Stick1=0.93178.txt";
  const LoopData a = valvediag::read_loop_csv(p.string(), plant_options(true));
  const LoopData b = valvediag::read_loop_csv(p.string(), plant_options());
  CHECK(a.size() == 751);
  CHECK(a.t == b.t);
  CHECK(a.op == b.op);
  CHECK(a.pv == b.pv);
  CHECK(a.sp == b.sp);
  // Last row of the file: 2024-10-04 00:00:00, 26.48940519, 106.87678043999999, 106.999924.
  CHECK(a.t.back() == 7500.0);
  CHECK(a.op.back() == 26.48940519);
  CHECK(a.pv.back() == 106.87678043999999);
  CHECK(a.sp.back() == 106.999924);
}

TEST_CASE("the export with broken time stamps reads with --t none, and its PV is dead") {
  const fs::path p = fs::path(VALVEDIAG_DATA_DIR) / "plant-loops" / "stiction" / kBadStamps;
  CsvOptions o = plant_options();
  o.t_column = "none";
  o.sample_period = 10;
  const LoopData d = valvediag::read_loop_csv(p.string(), o);
  CHECK(d.size() == 751);
  CHECK(d.t.back() == 7500.0);
  CHECK(d.op.front() == 0.7802873);
  // Its PV is 3.503246E-44 in every row: a dead measurement, refused for identification.
  CHECK(d.pv.front() == 3.503246e-44);
  CHECK_THROWS_WITH_AS(
      valvediag::check_identifiable_data(d, 100),
      (p.string() + ": column 'pv': constant at 3.50325e-44 in all 751 samples: nothing to "
                    "identify (a dead sensor or the wrong column?)")
          .c_str(),
      DataError);
}

TEST_CASE("all 41 plant-loop exports read with no options at all (format auto) as with them") {
  std::vector<fs::path> files = plant_files("stiction");
  const auto clean = plant_files("no-stiction");
  files.insert(files.end(), clean.begin(), clean.end());
  CsvOptions automatic;
  automatic.format = "auto";
  std::size_t same = 0;
  for (const fs::path& p : files) {
    INFO(p.string());
    if (p.filename() == kBadStamps) {
      try {
        valvediag::read_loop_csv(p.string(), automatic);
        FAIL("the repeated time stamp was not noticed");
      } catch (const DataError& e) {
        CHECK(e.line == 36);
        CHECK(e.column == "tagname");
      }
      continue;
    }
    std::vector<std::string> notes;
    const LoopData a = valvediag::read_loop_csv(p.string(), automatic, &notes);
    const LoopData b = valvediag::read_loop_csv(p.string(), plant_options());
    CHECK(a.size() == b.size());
    CHECK(a.sample_period() == b.sample_period());
    CHECK(a.t == b.t);
    CHECK(a.op == b.op);
    CHECK(a.pv == b.pv);
    CHECK(a.sp == b.sp);
    CHECK_FALSE(a.has_mv());
    REQUIRE(notes.size() == 3);
    CHECK(notes[0] ==
          "read as --skip-lines 2 --skip-after-header 2 --time-format '%Y-%m-%d %H:%M:%S' --t 1 "
          "--op '*.MV' --pv '*.PV' --sp '*.SV' (found by --format auto)");
    same += a.op == b.op && a.t == b.t;
  }
  CHECK(same == 40);
}
