// Format "auto": the layout found from the first lines, the options given winning, the choices
// it refuses to guess; and the hints of format "plain" towards the option that fixes an error.
#include <doctest/doctest.h>

#include <string>
#include <vector>

#include "../common/text.hpp"
#include "csv_text.hpp"
#include "valvediag/io/csv_reader.hpp"
#include "valvediag/io/data_error.hpp"

using valvediag::CsvOptions;
using valvediag::DataError;
using valvediag::LoopData;

namespace {

CsvOptions auto_format() {
  CsvOptions o;
  o.format = std::string("auto");
  return o;
}

using valvediag::test::parse;

std::string error_of(const std::string& text, const CsvOptions& o) {
  try {
    valvediag::parse_loop_csv(text, o, "data.csv");
  } catch (const DataError& e) {
    return e.what();
  }
  FAIL("no DataError for: " << text.substr(0, 200));
  return "";
}

using valvediag::test::has;

// A historian-like export: title lines, tag header, a units row, then `rows` rows a minute
// apart from 10:00 (`stamp_format` takes the hour and the minute).
std::string historian(char delim, const std::string& stamp_format, int rows, bool decimal_comma) {
  std::string s = "Export of unit 2\n";
  s += std::string("tags") + delim + "2\n";  // narrower than the data: a title line
  s += std::string("Timestamp") + delim + "FIC7.OUT" + delim + "FIC7.PV" + delim + "FIC7.SP\n";
  s += std::string("") + delim + "%" + delim + "m3/h" + delim + "m3/h\n";
  for (int k = 0; k < rows; ++k) {
    char stamp[64];
    std::snprintf(stamp, sizeof stamp, stamp_format.c_str(), 10 + k / 60, k % 60);
    std::string op = std::to_string(40 + k % 7) + (decimal_comma ? ",5" : ".5");
    s += std::string(stamp) + delim + op + delim + std::to_string(k) + delim + "12\n";
  }
  return s;
}

}  // namespace

TEST_CASE("auto: a semicolon export with decimal commas and dd.mm.yyyy stamps") {
  const std::string text = historian(';', "13.03.2024 %02d:%02d:00", 120, true);
  std::vector<std::string> notes;
  const LoopData d = parse(text, auto_format(), &notes);
  CHECK(d.size() == 120);
  CHECK(d.sample_period() == 60.0);
  CHECK(d.op.front() == 40.5);
  CHECK(d.pv.back() == 119.0);
  CHECK(d.sp.front() == 12.0);
  REQUIRE(notes.size() == 3);
  CHECK(notes[0] ==
        "read as --skip-lines 2 --skip-after-header 1 --decimal , --time-format "
        "'%d.%m.%Y %H:%M:%S' --t 1 --op '*.OUT' --pv '*.PV' --sp '*.SP' (found by --format auto)");
  // The same with the options it printed, read plain.
  CsvOptions o;
  o.skip_lines = 2;
  o.skip_after_header = 1;
  o.decimal = ',';
  o.time_format = std::string("%d.%m.%Y %H:%M:%S");
  o.t_column = std::string("1");
  o.op_column = std::string("*.OUT");
  o.pv_column = std::string("*.PV");
  o.sp_column = std::string("*.SP");
  const LoopData p = valvediag::parse_loop_csv(text, o, "data.csv");
  CHECK(p.t == d.t);
  CHECK(p.op == d.op);
  CHECK(p.pv == d.pv);
  CHECK(p.sp == d.sp);
}

TEST_CASE("auto: a date column and a time-of-day column read as one stamp") {
  std::vector<std::string> notes;
  // A `Time` column of clock times after a `Date` column: the two, not Time alone.
  const LoopData d = parse(
      "Date;Time;FIC101.MV;FIC101.PV\n08.10.2024;23:59:58;50,0;41,0\n08.10.2024;23:59:59;50,5;"
      "41,2\n09.10.2024;00:00:00;51,0;41,5\n09.10.2024;00:00:01;51,5;41,9\n",
      auto_format(), &notes);
  CHECK(d.t == std::vector<double>{0, 1, 2, 3});
  CHECK(d.op == std::vector<double>{50.0, 50.5, 51.0, 51.5});
  REQUIRE(!notes.empty());
  CHECK(has(notes[0], "--time-format '%d.%m.%Y %H:%M:%S' --t Date+Time"));
  // Other names: the first neighbouring pair that reads as stamps.
  const LoopData e = parse(
      "Tag,Uhrzeit,op,pv\n2024-10-08,12:00:00,1,2\n2024-10-08,12:00:10,2,3\n2024-10-08,12:00:20,"
      "3,4\n",
      auto_format(), &notes);
  CHECK(e.t == std::vector<double>{0, 10, 20});
  // A numeric time column named time is still that column.
  CHECK(parse("date,time,op,pv\n1,0,1,2\n1,1,2,3\n", auto_format(), nullptr).t ==
        std::vector<double>{0, 1});
}

TEST_CASE("auto: day/month order is refused unless the data decide it") {
  // All on 01/02 or 02/01: both orders read, both increase.
  const std::string ambiguous = historian(',', "01/02/2024 %02d:%02d:00", 30, false);
  const std::string e = error_of(ambiguous, auto_format());
  CHECK(has(e,
            "data.csv:5: column 'Timestamp' (t): the time stamps ('01/02/2024 10:00:00' to "
            "'01/02/2024 10:29:00') read as day/month and as month/day alike; choose with "
            "--time-format '%m/%d/%Y %H:%M:%S' or '%d/%m/%Y %H:%M:%S'"));
  // Day 13 cannot be a month.
  std::vector<std::string> notes;
  const LoopData d =
      parse(historian(',', "13/02/2024 %02d:%02d:00", 30, false), auto_format(), &notes);
  CHECK(d.size() == 30);
  CHECK(has(notes[0], "--time-format '%d/%m/%Y %H:%M:%S'"));
  // Across midnight: 02/01 23:59 -> 03/01 00:00 is a minute as day/month, a month as
  // month/day: the regular sampling decides.
  const std::string midnight =
      "t,op,pv\n02/01/2024 23:58:00,1,2\n02/01/2024 23:59:00,2,3\n03/01/2024 00:00:00,3,4\n";
  notes.clear();
  CHECK(parse(midnight, auto_format(), &notes).t == std::vector<double>{0, 60, 120});
  CHECK(has(notes[0], "--time-format '%d/%m/%Y %H:%M:%S'"));
  // Given, it wins.
  CsvOptions o = auto_format();
  o.time_format = std::string("%m/%d/%Y %H:%M:%S");
  o.given.time_format = true;
  CHECK(parse(ambiguous, o, nullptr).size() == 30);
}

TEST_CASE("auto: ISO stamps with T and fractions of a second, tab separated") {
  std::string text = "time\top\tpv\n";
  for (int k = 0; k < 50; ++k)
    text += "2024-05-01T08:00:" + std::string(k < 20 ? "0" : "") + std::to_string(k / 2) +
            (k % 2 ? ".500" : ".000") + "\t" + std::to_string(k % 5) + "\t1\n";
  std::vector<std::string> notes;
  const LoopData d = parse(text, auto_format(), &notes);
  CHECK(d.size() == 50);
  CHECK(d.sample_period() == 0.5);
  CHECK(notes[0] == "read as --time-format '%Y-%m-%dT%H:%M:%S' --t time (found by --format auto)");
}

TEST_CASE("auto: a choice between tags is refused, naming the option") {
  const std::string text = "t,FIC101.PV,FIC102.PV,FIC101.MV\n0,1,2,3\n1,2,3,4\n2,3,4,5\n";
  CHECK(error_of(text, auto_format()) ==
        "data.csv:1: 2 columns end in .PV: 'FIC101.PV', 'FIC102.PV'; choose one with --pv NAME");
  CsvOptions o = auto_format();
  o.pv_column = std::string("FIC102.PV");
  o.given.pv = true;
  const LoopData d = parse(text, o, nullptr);
  CHECK(d.pv == std::vector<double>{2, 3, 4});
  CHECK(d.op == std::vector<double>{3, 4, 5});
}

TEST_CASE("auto: options given win over what is found") {
  const std::string text = historian('\t', "2024-03-13 %02d:%02d:00", 40, false);
  CsvOptions o = auto_format();
  o.pv_column = std::string("4");  // the set point column, on purpose
  o.given.pv = true;
  o.sp_column = std::string("none");
  o.given.sp = true;
  std::vector<std::string> notes;
  const LoopData d = parse(text, o, &notes);
  CHECK(d.pv.front() == 12.0);
  CHECK(d.sp.empty());
  CHECK(notes[0] ==
        "read as --skip-lines 2 --skip-after-header 1 --time-format "
        "'%Y-%m-%d %H:%M:%S' --t 1 --op '*.OUT' (found by --format auto)");
  // A wrong --skip-after-header given is kept, and the error says what fixes it.
  o.skip_after_header = 0;
  o.given.skip_after_header = true;
  CHECK(has(error_of(text, o),
            "data.csv:4: column 'Timestamp' (t): '' is not data: line 4 is "
            "text (units or descriptions under the header row?); skip the "
            "lines up to 4 with --skip-after-header 1"));
}

TEST_CASE("auto: files in today's plain layout read as before, with no extra note") {
  const std::string text = "# simulate\nt,op,pv,sp\n0,1,2,3\n0.5,2,3,3\n1,3,4,3\n";
  std::vector<std::string> a, p;
  const LoopData d = parse(text, auto_format(), &a);
  const LoopData e = parse(text, CsvOptions{}, &p);
  CHECK(d.t == e.t);
  CHECK(d.op == e.op);
  CHECK(d.sp == e.sp);
  CHECK(a == p);
  // Without a header the reader's own message stands.
  CHECK(has(error_of("0,1,2\n1,2,3\n", auto_format()), "the header row looks like data"));
}

TEST_CASE("plain: errors name the option that fixes them") {
  const std::string text = historian('\t', "2024-03-13 %02d:%02d:00", 10, false);
  CsvOptions o;
  o.skip_lines = 2;
  o.t_column = std::string("1");
  o.op_column = std::string("*.OUT");
  o.pv_column = std::string("*.PV");
  // The units row: 1 line to skip.
  CHECK(has(error_of(text, o),
            "data.csv:4: column 'Timestamp' (t): '' is not data: line 4 is "
            "text (units or descriptions under the header row?); skip the "
            "lines up to 4 with --skip-after-header 1"));
  o.skip_after_header = 1;
  CHECK(error_of(text, o) ==
        "data.csv:5: column 'Timestamp' (t): '2024-03-13 10:00:00' is a date and time, not "
        "seconds: give --time-format '%Y-%m-%d %H:%M:%S'");
  o.time_format = std::string("%Y-%m-%d %H:%M:%S");
  CHECK(parse(text, o, nullptr).size() == 10);
}

TEST_CASE("auto: a malformed row is named by the reader, never skipped as layout") {
  std::string rows;
  for (int k = 0; k < 40; ++k)
    rows += std::to_string(k) + "," + std::to_string(k % 3) + "," + std::to_string(k) + "\n";
  // A truncated second data row: still data, so the reader names it.
  std::string early = "t,op,pv\n0,1,2\n1,2\n" + rows.substr(rows.find("2,"));
  CHECK(error_of(early, auto_format()) ==
        "data.csv:3: column 'pv': the row has only 2 cells, but this is column 3 (truncated row: "
        "complete it or remove it)");
  // A truncated last row of a short file does not change the delimiter or the width.
  std::vector<std::string> notes;
  const std::string late = "t,op,pv\n" + rows + "40,1\n";
  CHECK(error_of(late, auto_format()) ==
        "data.csv:42: column 'pv': the row has only 2 cells, but this is column 3 (truncated row: "
        "complete it or remove it)");
  // A data row with one bad cell among good ones is data too.
  const std::string bad_cell = "t,op,pv\n0,x,2\n" + rows.substr(rows.find("1,"));
  CHECK(error_of(bad_cell, auto_format()) ==
        "data.csv:2: column 'op': 'x' is not a number (fix the cell or remove the row)");
}
