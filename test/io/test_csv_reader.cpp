#include <doctest/doctest.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <charconv>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>

#include "csv_text.hpp"
#include "valvediag/io/csv_reader.hpp"
#include "valvediag/io/data_error.hpp"

namespace fs = std::filesystem;
using valvediag::CsvOptions;
using valvediag::DataError;
using valvediag::LoopData;
using valvediag::parse_loop_csv;
using valvediag::read_loop_csv;

namespace {

using valvediag::test::parse;

// The DataError that parsing `text` must raise; fails the test when none is raised.
DataError parse_error(const std::string& text, const CsvOptions& o = {}) {
  try {
    parse(text, o);
  } catch (const DataError& e) {
    return e;
  }
  FAIL("no DataError for: " << text.substr(0, 200));
  return DataError("", 0, "", "");
}

// A scratch directory removed at the end of the test.
struct TempDir {
  fs::path path;
  TempDir() {
    path = fs::temp_directory_path() /
           ("valvediag_test_io_" + std::to_string(::getpid()) + "_" + std::to_string(counter()++));
    fs::create_directories(path);
  }
  ~TempDir() {
    std::error_code ec;
    fs::remove_all(path, ec);
  }
  std::string write(const std::string& name, const std::string& text) const {
    const fs::path p = path / name;
    std::ofstream(p, std::ios::binary) << text;
    return p.string();
  }
  static int& counter() {
    static int c = 0;
    return c;
  }
};

}  // namespace

TEST_CASE("plain CSV with the default column names") {
  const LoopData d = parse("t,op,pv\n0,1,2\n0.5,2,3.25\n1,4,-5e-3\n");
  CHECK(d.source == "data.csv");
  CHECK(d.t == std::vector<double>{0, 0.5, 1});
  CHECK(d.op == std::vector<double>{1, 2, 4});
  CHECK(d.pv == std::vector<double>{2, 3.25, -0.005});
  CHECK_FALSE(d.has_sp());
  CHECK_FALSE(d.has_mv());
  CHECK(std::isnan(d.clock_at_zero_s));  // seconds, no date-time stamps
}

TEST_CASE("sp and mv are read when present; names match case-insensitively") {
  const LoopData d = parse("T,OP,PV,SP,MV\n10,1,2,3,0.9\n20,2,3,3,1.8\n");
  CHECK(d.t == std::vector<double>{10, 20});
  CHECK(d.sp == std::vector<double>{3, 3});
  CHECK(d.mv == std::vector<double>{0.9, 1.8});
  CsvOptions o;
  o.sp_column = "none";
  o.mv_column = "none";
  const LoopData e = parse("T,OP,PV,SP,MV\n10,1,2,3,0.9\n20,2,3,3,1.8\n", o);
  CHECK_FALSE(e.has_sp());
  CHECK_FALSE(e.has_mv());
}

TEST_CASE("extra columns, comments and blank lines") {
  const std::string text =
      "# exported 2024-10-03\n"
      "\n"
      "status,t,op,note,pv\n"
      "# first block\n"
      "OK,0,1,x,2\n"
      "\n"
      "   # indented comment\n"
      "BAD,1,2,y,3\n"
      "OK,2,3,z,4\n";
  const LoopData d = parse(text);
  CHECK(d.t == std::vector<double>{0, 1, 2});
  CHECK(d.op == std::vector<double>{1, 2, 3});
  CHECK(d.pv == std::vector<double>{2, 3, 4});
}

TEST_CASE("columns remapped by name, by number and by wildcard") {
  const std::string text = "time,OUT1,TEMP,SETP,POS\n0,1,20,21,0.5\n1,2,21,21,1.5\n2,3,22,21,2.5\n";
  CsvOptions o;
  o.t_column = "time";
  o.op_column = "OUT1";
  o.pv_column = "TEMP";
  o.sp_column = "SETP";
  o.mv_column = "POS";
  std::vector<std::string> notes;
  const LoopData d = parse(text, o, &notes);
  CHECK(d.op == std::vector<double>{1, 2, 3});
  CHECK(d.pv == std::vector<double>{20, 21, 22});
  CHECK(d.sp == std::vector<double>{21, 21, 21});
  CHECK(d.mv == std::vector<double>{0.5, 1.5, 2.5});
  REQUIRE(notes.size() == 1);
  CHECK(notes[0] ==
        "columns: t = 'time' (1), op = 'OUT1' (2), pv = 'TEMP' (3), sp = 'SETP' (4), mv = 'POS' "
        "(5)");

  CsvOptions n;
  n.t_column = "1";
  n.op_column = "2";
  n.pv_column = "3";
  n.sp_column = "4";
  const LoopData e = parse(text, n);
  CHECK(e.op == d.op);
  CHECK(e.pv == d.pv);
  CHECK(e.sp == d.sp);

  CsvOptions w;
  w.t_column = "tim?";
  w.op_column = "out*";
  w.pv_column = "*EMP";
  const LoopData f = parse(text, w);
  CHECK(f.op == d.op);
  CHECK(f.pv == d.pv);
  CHECK(f.tag.empty());  // OUT1 and TEMP name no loop
}

TEST_CASE("a historian's point names give the loop's tag") {
  CsvOptions o;
  o.op_column = "*.MV";
  o.pv_column = "*.PV";
  CHECK(parse("t,2111FIC46005.MV,2111FIC46005.PV\n0,1,2\n1,2,3\n", o).tag == "2111FIC46005");
  // Points of two loops, or no loop part: no tag.
  CHECK(parse("t,FIC1.MV,FIC2.PV\n0,1,2\n1,2,3\n", o).tag.empty());
  CHECK(parse("t,.MV,.PV\n0,1,2\n1,2,3\n", o).tag.empty());
}

TEST_CASE("semicolon, tab, space and auto-detected delimiters") {
  CsvOptions semi;
  semi.delimiter = ";";
  CHECK(parse("t;op;pv\n0;1;2\n1;2;3\n", semi).pv == std::vector<double>{2, 3});
  CsvOptions tab;
  tab.delimiter = "tab";
  CHECK(parse("t\top\tpv\n0\t1\t2\n1\t2\t3\n", tab).pv == std::vector<double>{2, 3});
  CsvOptions space;
  space.delimiter = "space";
  CHECK(parse("  t   op pv\n0 1   2\n\t1 2 3  \n", space).pv == std::vector<double>{2, 3});
  // auto: the header row decides.
  CHECK(parse("t;op;pv\n0;1;2\n1;2;3\n").op == std::vector<double>{1, 2});
  CHECK(parse("t\top\tpv\n0\t1\t2\n1\t2\t3\n").op == std::vector<double>{1, 2});
  CHECK(parse("t op pv\n0 1 2\n1 2 3\n").op == std::vector<double>{1, 2});
  // Blanks around cells are trimmed; a trailing delimiter adds an ignored empty cell.
  CHECK(parse("t , op , pv,\n 0 , 1 , 2 ,\n1,2,3,\n").op == std::vector<double>{1, 2});
}

TEST_CASE("decimal comma") {
  CsvOptions o;
  o.delimiter = "auto";
  o.decimal = ',';
  const LoopData d = parse("t;op;pv\n0;1,5;2\n0,5;2,25;-3,0\n", o);
  CHECK(d.t == std::vector<double>{0, 0.5});
  CHECK(d.op == std::vector<double>{1.5, 2.25});
  CHECK(d.pv == std::vector<double>{2, -3});
  const DataError e = parse_error("t;op;pv\n0;1.234;2\n1;2;3\n", o);
  CHECK(std::string(e.what()) ==
        "data.csv:2: column 'op': '1.234' is not a number (fix the cell or remove the row; '.' "
        "is not allowed with --decimal ,)");
}

TEST_CASE("quoted cells may hold the delimiter and quotes") {
  CsvOptions o;
  o.op_column = "out, %";
  o.pv_column = "pv \"raw\"";
  const LoopData d =
      parse("\"t\",\"out, %\",\"pv \"\"raw\"\"\"\n\"0\",\"1.5\", 2 \n1,\"2\",\"3\"\n", o);
  CHECK(d.t == std::vector<double>{0, 1});
  CHECK(d.op == std::vector<double>{1.5, 2});
  CHECK(d.pv == std::vector<double>{2, 3});
}

TEST_CASE("line ends, byte-order mark and a leading plus sign") {
  const std::vector<double> op = {1, 2};
  CHECK(parse("t,op,pv\r\n0,1,2\r\n1,2,3\r\n").op == op);
  CHECK(parse("t,op,pv\r0,1,2\r1,2,3\r").op == op);
  CHECK(parse("\xEF\xBB\xBFt,op,pv\n0,+1,2\n1,2,3").op == op);
  CHECK(parse("t,op,pv\r\r\n0,1,2\r\r\n\r\r\n1,2,3\r\r\n").op == op);
}

TEST_CASE("skip lines before and after the header row") {
  CsvOptions o;
  o.skip_lines = 2;
  o.skip_after_header = 1;
  o.delimiter = "tab";
  const LoopData d = parse("title line\n8\t10\nt\top\tpv\nunits\t%\tdegC\n0\t1\t2\n1\t2\t3\n", o);
  CHECK(d.t == std::vector<double>{0, 1});
  CHECK(d.pv == std::vector<double>{2, 3});
}

TEST_CASE("date-time stamps become seconds since the first sample") {
  CsvOptions o;
  o.time_format = "%Y-%m-%d %H:%M:%S";
  std::vector<std::string> notes;
  // Across a leap day, with fractional seconds.
  const LoopData d = parse(
      "t,op,pv\n2024-02-28 23:59:59.5,1,2\n2024-02-29 00:00:00,2,3\n2024-02-29 00:00:00.5,3,4\n", o,
      &notes);
  CHECK(d.t == std::vector<double>{0, 0.5, 1.0});
  // t = 0 on the data's clock: 2024-02-28 is day 19781 since 1970-01-01.
  CHECK(d.clock_at_zero_s == doctest::Approx(19781.0 * 86400 + 86399.5).epsilon(1e-15));
  REQUIRE(notes.size() == 2);
  CHECK(notes[1] ==
        "t = 0 s is '2024-02-28 23:59:59.5' (line 2); time stamps are read as given, without time "
        "zone or daylight saving");
  // Across a year end, US month/day order.
  o.time_format = "%m/%d/%Y %H:%M:%S";
  const LoopData e = parse("t,op,pv\n12/31/2023 23:59:50,1,2\n01/01/2024 00:00:00,2,3\n", o);
  CHECK(e.t == std::vector<double>{0, 10});
  CHECK(e.clock_at_zero_s == doctest::Approx(19722.0 * 86400 + 86390).epsilon(1e-15));
  // 12-hour clock.
  o.time_format = "%m/%d/%Y %I:%M:%S %p";
  const LoopData f = parse(
      "t,op,pv\n10/3/2024 11:59:30 AM,1,2\n10/3/2024 12:00:00 PM,2,3\n10/3/2024 12:00:30 "
      "PM,3,4\n",
      o);
  CHECK(f.t == std::vector<double>{0, 30, 60});
}

TEST_CASE("a time stamp split over a date and a time column: --t DATE+TIME") {
  CsvOptions o;
  o.time_format = "%d.%m.%Y %H:%M:%S";
  o.t_column = "Date+Time";
  o.delimiter = ";";
  std::vector<std::string> notes;
  // Across midnight: the date column carries the day.
  const std::string text =
      "Date;Time;op;pv\n31.12.2023;23:59:50;1;2\n31.12.2023;23:59:55;2;3\n01.01.2024;00:00:00;3;"
      "4\n";
  const LoopData d = parse(text, o, &notes);
  CHECK(d.t == std::vector<double>{0, 5, 10});
  CHECK(d.op == std::vector<double>{1, 2, 3});
  REQUIRE(notes.size() == 2);
  CHECK(notes[0] == "columns: t = 'Date+Time' (1+2), op = 'op' (3), pv = 'pv' (4)");
  CHECK(notes[1].find("t = 0 s is '31.12.2023 23:59:50' (line 2)") == 0);
  // By numbers, and the columns need not be neighbours.
  o.t_column = "4+1";
  const LoopData e =
      parse("Time;op;pv;Date\n12:00:00;1;2;03.10.2024\n12:00:01;2;3;03.10.2024\n", o);
  CHECK(e.t == std::vector<double>{0, 1});
  // A column whose own name holds '+' is that one column.
  o.t_column = "a+b";
  o.time_format = "seconds";
  CHECK(parse("a+b;op;pv\n0;1;2\n1;2;3\n", o).t == std::vector<double>{0, 1});
  // Errors name the stamp as given, its line, and what to do.
  o.t_column = "Date+Time";
  o.time_format = "%d.%m.%Y %H:%M:%S";
  DataError err =
      parse_error("Date;Time;op;pv\n31.12.2023;23:59:50;1;2\n31.12.2023;25:00:00;2;3\n", o);
  CHECK(err.line == 3);
  CHECK(err.column == "Date+Time");
  CHECK(std::string(err.what()).find("'31.12.2023 25:00:00' does not match --time-format") !=
        std::string::npos);
  err = parse_error("Date;Time;op;pv\n31.12.2023;23:59:50;1;2\n31.12.2023\n", o);
  CHECK(err.line == 3);
  err = parse_error("Date;Time;op;pv\n31.12.2023;23:59:50;1;2\n", [&] {
    CsvOptions b = o;
    b.t_column = "Date+Clock";
    return b;
  }());
  CHECK(std::string(err.what()).find("column 'Clock' (t): not found in the header row") !=
        std::string::npos);
  o.t_column = "Date+";
  err = parse_error("Date;Time;op;pv\n31.12.2023;23:59:50;1;2\n31.12.2023;23:59:51;1;2\n", o);
  CHECK(std::string(err.what()).find("a split time stamp is DATE+TIME") != std::string::npos);
  o.t_column = "Date+op";
  err = parse_error("Date;Time;op;pv\n31.12.2023;23:59:50;1;2\n31.12.2023;23:59:51;1;2\n", o);
  CHECK(std::string(err.what()).find("chosen for both the time of day") != std::string::npos);
}

TEST_CASE("numeric time is kept as given") {
  const LoopData d = parse("t,op,pv\n1727992500,1,2\n1727992510,2,3\n");
  CHECK(d.t == std::vector<double>{1727992500, 1727992510});
}

TEST_CASE("no time column: rows sample_period apart") {
  CsvOptions o;
  o.t_column = "none";
  o.sample_period = 0.5;
  const LoopData d = parse("op,pv\n1,2\n2,3\n3,4\n", o);
  CHECK(d.t == std::vector<double>{0, 0.5, 1.0});
  o.sample_period.reset();
  CHECK(std::string(parse_error("op,pv\n1,2\n2,3\n", o).what()) ==
        "data.csv: without a time column (--t none) --sample-period is needed");
}

TEST_CASE("resampling an irregular series onto the median period") {
  // Steps 1, 1.5, 0.5, 1.2, 0.8: median 1 s. pv = t^2, op = sample number.
  const std::string text = "t,op,pv\n0,1,0\n1,2,1\n2.5,3,6.25\n3,4,9\n4.2,5,17.64\n5,6,25\n";
  const DataError e = parse_error(text);
  CHECK(e.line == 4);
  CHECK(e.column == "t");
  CHECK(std::string(e.what()) ==
        "data.csv:4: column 't': irregular sampling: the step to this row is 1.5 s, the median "
        "step is 1 s (max deviation 0.5 s; 4 of 5 steps are more than 1 % off); use --resample "
        "to interpolate onto a uniform grid");

  CsvOptions o;
  o.resample = true;
  std::vector<std::string> notes;
  const LoopData d = parse(text, o, &notes);
  REQUIRE(d.size() == 6);
  CHECK(d.t == std::vector<double>{0, 1, 2, 3, 4, 5});
  const double pv[] = {0, 1, 1 + 5.25 / 1.5, 9, 9 + 8.64 / 1.2, 25};
  const double op[] = {1, 2, 2 + 1 / 1.5, 4, 4 + 1 / 1.2, 6};
  for (std::size_t i = 0; i < 6; ++i) {
    CHECK(d.pv[i] == doctest::Approx(pv[i]).epsilon(1e-12));
    CHECK(d.op[i] == doctest::Approx(op[i]).epsilon(1e-12));
  }
  CHECK(d.pv[2] == doctest::Approx(4.5).epsilon(1e-12));
  CHECK(d.pv[4] == doctest::Approx(16.2).epsilon(1e-12));
  REQUIRE(notes.size() == 2);
  CHECK(notes[1] ==
        "resampled 6 rows onto a uniform 1 s grid (the median step): 6 samples; the steps in the "
        "file ranged from 0.5 to 1.5 s (largest before line 4)");
}

TEST_CASE("resampling onto a given sample period") {
  // pv = t^2 sampled at 0, 2, 3, 4, 6, 8; grid 0, 1.5, ..., 7.5.
  const std::string text = "t,op,pv,sp\n0,0,0,1\n2,1,4,1\n3,0,9,1\n4,1,16,2\n6,0,36,2\n8,1,64,2\n";
  CsvOptions o;
  o.resample = true;
  o.sample_period = 1.5;
  const LoopData d = parse(text, o);
  REQUIRE(d.size() == 6);
  const double t[] = {0, 1.5, 3, 4.5, 6, 7.5};
  const double pv[] = {0, 3, 9, 21, 36, 57};
  const double sp[] = {1, 1, 1, 2, 2, 2};
  for (std::size_t i = 0; i < 6; ++i) {
    CHECK(d.t[i] == doctest::Approx(t[i]).epsilon(1e-12));
    CHECK(d.pv[i] == doctest::Approx(pv[i]).epsilon(1e-12));
    CHECK(d.sp[i] == doctest::Approx(sp[i]).epsilon(1e-12));
  }
  CHECK(d.op[1] == doctest::Approx(0.75).epsilon(1e-12));
  // Without --resample a period that contradicts the stamps is refused.
  CsvOptions p;
  p.sample_period = 2;
  CHECK(std::string(parse_error("t,op,pv\n0,1,2\n1,2,3\n2,1,2\n", p).what()) ==
        "data.csv: column 't': the rows are 1 s apart, but --sample-period is 2 (leave it out, or "
        "add --resample to resample the data)");
  // ... and one that agrees is accepted as is.
  p.sample_period = 1;
  CHECK(parse("t,op,pv\n0,1,2\n1,2,3\n2,1,2\n", p).t == std::vector<double>{0, 1, 2});
}

TEST_CASE("resampling edge cases") {
  CsvOptions o;
  o.resample = true;
  // Found by fuzzing: the median grid (2 s) steps over the only row where OP moves.
  CHECK(std::string(parse_error("t,op,pv\n4,3,9\n6,3,9\n6.5,2,3\n", o).what()) ==
        "data.csv: column 'op': constant at 3 in all 2 resampled samples: nothing to identify (is "
        "--op the controller output?)");
  // b - a overflowed between huge values of opposite sign: such cells are refused by name now,
  // before any arithmetic.
  CHECK(std::string(parse_error("t,op,pv\n0,0,1\n1,1,-1.7e308\n3,2,1.7e308\n", o).what())
            .find("data.csv:3: column 'pv': '-1.7e308' is no measurement") == 0);
  const LoopData d = parse("t,op,pv\n0,0,1\n1,1,-1e12\n3,2,1e12\n", o);
  CHECK(d.t == std::vector<double>{0, 2});
  CHECK(d.op == std::vector<double>{0, 1.5});
  CHECK(d.pv == std::vector<double>{1, 0});
}

TEST_CASE("regular data is not touched by --resample") {
  CsvOptions o;
  o.resample = true;
  std::vector<std::string> notes;
  const LoopData d = parse("t,op,pv\n0,1,2\n10,2,3\n20,1,5\n", o, &notes);
  CHECK(d.t == std::vector<double>{0, 10, 20});
  CHECK(d.pv == std::vector<double>{2, 3, 5});
  CHECK(notes.size() == 1);
}

TEST_CASE("missing and empty files") {
  TempDir dir;
  const std::string missing = (dir.path / "nope.csv").string();
  try {
    read_loop_csv(missing, {});
    FAIL("no error");
  } catch (const DataError& e) {
    CHECK(e.file == missing);
    CHECK(e.line == 0);
    CHECK(std::string(e.what()) ==
          missing + ": cannot open the file: No such file or directory (check the path)");
  }
  const std::string empty = dir.write("empty.csv", "");
  CHECK_THROWS_WITH_AS(read_loop_csv(empty, {}), (empty + ": the file is empty (0 bytes)").c_str(),
                       DataError);
  CHECK_THROWS_WITH_AS(
      read_loop_csv(dir.path.string(), {}),
      (dir.path.string() + ": is a directory, not a data file (give the path of a CSV file)")
          .c_str(),
      DataError);
  const std::string ok = dir.write("ok.csv", "t,op,pv\n0,1,2\n1,2,3\n");
  const LoopData d = read_loop_csv(ok, {});
  CHECK(d.source == ok);
  CHECK(d.op == std::vector<double>{1, 2});
}

TEST_CASE("bad input: every message names file, line and column") {
  auto what = [](const std::string& text, const CsvOptions& o = {}) {
    return std::string(parse_error(text, o).what());
  };
  CHECK(what("\n# only a comment\n\n") ==
        "data.csv: the file has no header row, only blank or comment lines");
  CHECK(what("t,op,pv\n") == "data.csv: no data rows after the header row (line 1)");
  CHECK(what("t,op,pv\n0,1,2\n") ==
        "data.csv:2: only 1 data row: at least 2 samples are needed (is the file complete?)");

  const DataError missing = parse_error("time,OUT1,TEMP\n0,1,2\n1,2,3\n");
  CHECK(missing.line == 1);
  CHECK(missing.column == "t");
  CHECK(std::string(missing.what()) ==
        "data.csv:1: column 't': not found in the header row (columns: 'time', 'OUT1', 'TEMP'); "
        "choose the t column with --t NAME or --t NUMBER (1-based)");
  CsvOptions remap;
  remap.t_column = "time";
  remap.op_column = "OUT1";
  CHECK(what("time,OUT1,TEMP\n0,1,2\n1,2,3\n", remap) ==
        "data.csv:1: column 'pv': not found in the header row (columns: 'time', 'OUT1', 'TEMP'); "
        "choose the pv column with --pv NAME or --pv NUMBER (1-based)");
  CHECK(what("t;op;pv\n0;1;2\n1;2;3\n",
             [] {
               CsvOptions o;
               o.delimiter = ",";
               return o;
             }()) ==
        "data.csv:1: column 't': not found in the header row (columns: 't;op;pv'); "
        "choose the t column with --t NAME or --t NUMBER (1-based); only one column was "
        "found: check --delimiter");
  CHECK(what("0,1,2\n1,2,3\n2,3,4\n") ==
        "data.csv:1: column 't': not found in the header row (columns: '0', '1', '2'); choose the "
        "t column with --t NAME or --t NUMBER (1-based); the header row looks like data: check "
        "--skip-lines");

  const DataError nan = parse_error("t,op,pv\n0,1,2\n1,2,abc\n2,3,4\n");
  CHECK(nan.file == "data.csv");
  CHECK(nan.line == 3);
  CHECK(nan.column == "pv");
  CHECK(std::string(nan.what()) ==
        "data.csv:3: column 'pv': 'abc' is not a number (fix the cell or remove the row)");
  CsvOptions renamed;
  renamed.pv_column = "TEMP";
  CHECK(what("t,op,TEMP\n0,1,2\n1,2,abc\n", renamed) ==
        "data.csv:3: column 'TEMP' (pv): 'abc' is not a number (fix the cell or remove the row)");
  CHECK(what("t,op,pv\n0,1,2\n1,2,1,5\n") ==
        "data.csv:3: the row has 4 cells, but the header row names only 3 (cell 4 is '5'; a "
        "decimal comma or a delimiter inside an unquoted cell?)");
  CHECK(what("t;op;pv\n0;1;2\n1;2;1,5\n") ==
        "data.csv:3: column 'pv': '1,5' is not a number (fix the cell or remove the row; for "
        "decimal commas use --decimal ,)");
  CHECK(what("t,op,pv\n0,1,2\n1,NaN,3\n") ==
        "data.csv:3: column 'op': 'NaN' is NaN or infinite (remove the row or fill in a measured "
        "value)");
  CHECK(what("t,op,pv\n0,1,2\n1,2,-inf\n") ==
        "data.csv:3: column 'pv': '-inf' is NaN or infinite (remove the row or fill in a measured "
        "value)");
  CHECK(what("t,op,pv\n0,1,2\n1,2,1e999\n") ==
        "data.csv:3: column 'pv': '1e999' is out of the range of a double (fix the cell or remove "
        "the row)");
  // Finite but no measurement: a historian's bad-value marker (it hung the estimators).
  CHECK(what("t,op,pv\n0,1,2\n1,1e308,3\n") ==
        "data.csv:3: column 'op': '1e308' is no measurement (beyond +-1e12 in any unit: a "
        "historian's bad-value marker or a corrupt cell; remove the row or fill it in)");
  CHECK(what("t,op,pv\n0,1,2\n1,2,-3.4e38\n")
            .find("data.csv:3: column 'pv': '-3.4e38' is no "
                  "measurement") == 0);
  CHECK(parse("t,op,pv\n0,1,2\n1,2,9.9e11\n").pv.back() == 9.9e11);
  CHECK(what("t,op,pv\n0,1,2\n1,,3\n") ==
        "data.csv:3: column 'op': the cell is empty (fill the gap or remove the row)");
  CHECK(what("t,op,pv\n0,1,2\n1,2\n") ==
        "data.csv:3: column 'pv': the row has only 2 cells, but this is column 3 (truncated row: "
        "complete it or remove it)");
  CHECK(what("t,op,pv\n0,1,2\n1,\"2,3\n") ==
        "data.csv:3: a quoted cell has no closing quote (fix the row or remove it)");

  CHECK(what("t,op,pv\n0,1,2\n1,2,3\n1,3,4\n") ==
        "data.csv:4: column 't': time '1' is not after the previous row's '1' (line 3): duplicate "
        "time stamp (remove one of the rows; if the rows are evenly spaced and only the stamps are "
        "wrong, use --t none with --sample-period)");
  CHECK(what("t,op,pv\n0,1,2\n2,2,3\n1,3,4\n") ==
        "data.csv:4: column 't': time '1' is not after the previous row's '2' (line 3): time goes "
        "backwards (sort the rows by time; a clock change?)");
  CHECK(what("t,op,pv\n0,5,2\n1,5,3\n2,5,4\n") ==
        "data.csv: column 'op': constant at 5 in all 3 rows: nothing to identify (is --op the "
        "controller output?)");

  CsvOptions dt;
  dt.time_format = "%Y-%m-%d %H:%M:%S";
  CHECK(what("t,op,pv\n2024-01-01 00:00:00,1,2\n2024-01-01 00:00:10,2,3\n01/01/2024 "
             "00:00:20,3,4\n",
             dt) ==
        "data.csv:4: column 't': '01/01/2024 00:00:20' does not match --time-format '%Y-%m-%d "
        "%H:%M:%S' (expected %Y at character 1)");
  CHECK(what("t,op,pv\n2024-02-30 00:00:00,1,2\n", dt) ==
        "data.csv:2: column 't': '2024-02-30 00:00:00' does not match --time-format '%Y-%m-%d "
        "%H:%M:%S' (day 30 does not exist in month 2 of 2024)");
}

TEST_CASE("bad options and encodings") {
  auto what = [](const std::string& text, const CsvOptions& o = {}) {
    return std::string(parse_error(text, o).what());
  };
  const std::string good = "t,op,pv\n0,1,2\n1,2,3\n";
  CsvOptions o;
  o.delimiter = "xx";
  CHECK(what(good, o) ==
        "data.csv: --delimiter 'xx' is not usable (use ',', ';', 'tab', 'space', '|' or 'auto')");
  o = {};
  o.time_format = "yyyy-MM-dd HH:mm:ss";
  CHECK(what(good, o) ==
        "data.csv: --time-format 'yyyy-MM-dd HH:mm:ss': it has no % directive (use \"seconds\" "
        "for numeric time)");
  o = {};
  o.skip_lines = 10;
  CHECK(what(good, o) == "data.csv: the file has only 3 lines, but --skip-lines is 10");
  o = {};
  o.skip_after_header = 5;
  CHECK(what(good, o) ==
        "data.csv: the file ends before the 5 lines after the header row (check "
        "--skip-after-header)");
  o = {};
  o.op_column = "4";
  CHECK(what(good, o) ==
        "data.csv:1: column '4' (op): there is no column 4: the header row has 3 columns ('t', "
        "'op', 'pv')");
  o.op_column = "0";
  CHECK(what(good, o) == "data.csv:1: column '0' (op): column numbers start at 1");
  o = {};
  o.pv_column = "2";
  CHECK(what(good, o) ==
        "data.csv:1: column 'op': chosen for both op and pv (give --pv another column)");
  o = {};
  o.op_column = "*";
  CHECK(what(good, o) ==
        "data.csv:1: column '*' (op): matches 3 columns ('t', 'op', 'pv'); choose one with --op "
        "NAME or --op NUMBER");
  o = {};
  o.sample_period = -1;
  CHECK(what(good, o) == "data.csv: --sample-period must be a positive number of seconds, not -1");
  o = {};
  o.sample_period = 1e-12;
  o.resample = true;
  CHECK(what("t,op,pv\n0,1,2\n1,2,3\n3,1,2\n", o) ==
        "data.csv: column 't': resampling 3 s at 1e-12 s would give 3e+12 samples (choose a larger "
        "--sample-period)");
  CHECK(what(std::string("\xFF\xFEt\0,\0", 6)) ==
        "data.csv: the file is UTF-16 text; export or save it as UTF-8 (or ANSI)");
  CHECK(
      what(std::string("t\0,\0o\0p\0\n\0", 11)) ==
      "data.csv:1: the header row holds NUL bytes: the file is probably UTF-16; save it as UTF-8");
}

TEST_CASE("very long lines and cells do not blow up the messages") {
  const std::string junk(1 << 19, 'x');  // half the 1 MiB line limit
  const std::string msg = parse_error("t,op,pv\n0,1,2\n1,2," + junk + "\n").what();
  CHECK(msg ==
        "data.csv:3: column 'pv': 'xxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxx...' is not a number "
        "(fix the cell or remove the row)");
  // A huge ignored column is fine.
  const LoopData d = parse("t,op,pv,x\n0,1,2," + junk + "\n1,2,3," + junk + "\n");
  CHECK(d.pv == std::vector<double>{2, 3});
}

TEST_CASE("a million rows") {
  std::string text = "t,op,pv\n";
  text.reserve(40'000'000);
  char buf[64];
  const std::size_t n = 1'000'000;
  for (std::size_t i = 0; i < n; ++i) {
    const double t = 0.1 * static_cast<double>(i);
    const double op = 50 + 10 * std::sin(0.001 * static_cast<double>(i));
    for (double v : {t, op, op * 0.5 + 3}) {
      char* end = std::to_chars(buf, buf + sizeof buf, v).ptr;
      text.append(buf, end);
      text += ',';
    }
    text.back() = '\n';
  }
  const auto start = std::chrono::steady_clock::now();
  const LoopData d = parse(text);
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  REQUIRE(d.size() == n);
  CHECK(d.t[777'777] == 0.1 * 777'777.0);
  CHECK(d.op[123'456] == 50 + 10 * std::sin(0.001 * 123'456.0));
  CHECK(d.pv[999'999] == d.op[999'999] * 0.5 + 3);
  // Speed is reported, not asserted: a timed check flakes on a loaded machine.
  MESSAGE("parsed 10^6 rows in " << seconds << " s");
}

TEST_CASE("a file is read in chunks: the same rows as in memory, whatever the line ends") {
  TempDir dir;
  // Well over one 64 KiB chunk, so that rows straddle the chunk boundaries.
  for (const char* eol : {"\n", "\r\n", "\r"}) {
    std::string text = std::string("\xEF\xBB\xBF") + "t,op,pv" + eol;
    for (int k = 0; k < 20000; ++k)
      text += std::to_string(k) + "," + std::to_string(k % 7) + "," + std::to_string(k * 3) + eol;
    const std::string p = dir.write("big.csv", text);
    const LoopData f = read_loop_csv(p, {});
    const LoopData m = parse(text);
    REQUIRE(f.size() == 20000);
    CHECK(f.t == m.t);
    CHECK(f.op == m.op);
    CHECK(f.pv == m.pv);
    CHECK(f.t.back() == 19999);
    CHECK(f.pv.back() == 59997);
  }
}

TEST_CASE("more data rows than max_rows are refused at the first row beyond") {
  TempDir dir;
  std::string text = "t,op,pv\n# a comment is not a row\n";
  for (int k = 0; k < 101; ++k) text += std::to_string(k) + "," + std::to_string(k % 3) + ",1\n";
  const std::string p = dir.write("rows.csv", text);
  CsvOptions o;
  o.max_rows = 101;
  CHECK(read_loop_csv(p, o).size() == 101);
  o.max_rows = 100;
  // Row 101 is line 103: the header, the comment, then 100 rows.
  CHECK_THROWS_WITH_AS(read_loop_csv(p, o),
                       (p + ":103: more than 100 data rows, the --max-rows limit that keeps "
                            "memory bounded (about 50 bytes a row); give --max-rows with a larger "
                            "number to read it all, or cut the file into shorter records")
                           .c_str(),
                       DataError);
  o.max_rows = 1;
  CHECK_THROWS_WITH_AS(
      parse(text, o), "data.csv: --max-rows must be at least 2 (a fit needs 2 samples)", DataError);
  CHECK(CsvOptions{}.max_rows == 10'000'000);
}

TEST_CASE("a line longer than 1 MiB is an error at its line, in a file and in memory") {
  TempDir dir;
  const std::string text = "t,op,pv\n0,1,2\n" + std::string((1 << 20) + 1, '7') + "\n2,3,4\n";
  const std::string p = dir.write("long.csv", text);
  const std::string problem =
      ":3: the line is longer than 1 MiB (no line end within it): this is not a text data file "
      "(binary data, or a device such as /dev/zero?); give a CSV file";
  CHECK_THROWS_WITH_AS(read_loop_csv(p, {}), (p + problem).c_str(), DataError);
  CHECK_THROWS_WITH_AS(parse(text), ("data.csv" + problem).c_str(), DataError);
  // Exactly 1 MiB is still a line (a non-numeric cell, then).
  const std::string at_limit = "t,op,pv\n0,1,2\n" + std::string(1 << 20, '7') + "\n";
  CHECK_THROWS_WITH_AS(read_loop_csv(dir.write("limit.csv", at_limit), {}),
                       doctest::Contains("limit.csv:3: column 'op': the row has only 1 cells"),
                       DataError);
}

TEST_CASE("/dev/zero is refused quickly with bounded memory") {
  if (!fs::exists("/dev/zero")) return;
  // In a child process, so that a reader that never stops is killed instead of hanging the test,
  // and its peak memory is its own.
  int fds[2];
  REQUIRE(::pipe(fds) == 0);
  const pid_t pid = ::fork();
  REQUIRE(pid >= 0);
  if (pid == 0) {
    ::close(fds[0]);
    int code = 1;
    std::string what = "no error";
    try {
      read_loop_csv("/dev/zero", {});
    } catch (const DataError& e) {
      what = e.what();
      code = 3;
    }
    (void)!::write(fds[1], what.data(), what.size());
    ::_exit(code);
  }
  ::close(fds[1]);
  rusage before{};
  ::getrusage(RUSAGE_SELF, &before);
  const auto start = std::chrono::steady_clock::now();
  int status = 0;
  rusage child{};
  bool done = false;
  while (!done && std::chrono::steady_clock::now() - start < std::chrono::seconds(30)) {
    done = ::wait4(pid, &status, WNOHANG, &child) == pid;
    if (!done) std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  if (!done) {
    ::kill(pid, SIGKILL);
    ::wait4(pid, &status, 0, &child);
  }
  std::string what;
  char buf[512];
  for (ssize_t k; (k = ::read(fds[0], buf, sizeof buf)) > 0;)
    what.append(buf, static_cast<std::size_t>(k));
  ::close(fds[0]);
  REQUIRE(done);
  CHECK(WIFEXITED(status));
  CHECK(WEXITSTATUS(status) == 3);
  CHECK(what.rfind("/dev/zero:1: the line is longer than 1 MiB", 0) == 0);
  // ru_maxrss is in KiB. The child starts with this process's pages; it may add its 1 MiB
  // line buffer and change, not the gigabytes the whole-file read took.
  const long grown_kib = child.ru_maxrss - before.ru_maxrss;
  MESSAGE("/dev/zero: child peak RSS " << child.ru_maxrss << " KiB, this process "
                                       << before.ru_maxrss << " KiB");
  CHECK(grown_kib < 64 * 1024);
}
