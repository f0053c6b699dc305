#include <doctest/doctest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <sstream>
#include <string>

#include "../common/text.hpp"
#include "valvediag/io/csv_reader.hpp"
#include "valvediag/io/csv_writer.hpp"
#include "valvediag/io/data_checks.hpp"
#include "valvediag/io/data_error.hpp"

namespace fs = std::filesystem;
using valvediag::DataError;
using valvediag::LoopData;

namespace {

fs::path scratch(const std::string& name) {
  const fs::path dir =
      fs::temp_directory_path() / ("valvediag_test_io_writer_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  return dir / name;
}

using valvediag::test::slurp;

LoopData sample_loop() {
  LoopData d;
  d.source = "sim";
  d.t = {0, 0.1, 0.2, 0.30000000000000004};
  d.op = {1.0 / 3.0, -2.5e-300, -9.87654321e11, 42};
  d.pv = {0.1, 0.2, 0.3, -0.0};
  d.sp = {5, 5, 5.5, 5.5};
  d.mv = {0.3333333333333333, 1e-310, 99.99999999999999, 7};
  return d;
}

}  // namespace

TEST_CASE("write_loop_csv round-trips exactly through read_loop_csv") {
  const LoopData d = sample_loop();
  const fs::path p = scratch("loop.csv");
  valvediag::write_loop_csv(p.string(), d);
  const std::string text = slurp(p);
  CHECK(text.substr(0, text.find('\n')) == "t,op,pv,sp,mv");
  CHECK(text.find("0.30000000000000004,42,-0,5.5,7\n") != std::string::npos);
  const LoopData r = valvediag::read_loop_csv(p.string(), {});
  CHECK(r.t == d.t);
  CHECK(r.op == d.op);
  CHECK(r.pv == d.pv);
  CHECK(r.sp == d.sp);
  CHECK(r.mv == d.mv);

  LoopData bare = d;
  bare.sp.clear();
  bare.mv.clear();
  valvediag::write_loop_csv(p.string(), bare);
  const std::string bare_text = slurp(p);
  CHECK(bare_text.substr(0, bare_text.find('\n')) == "t,op,pv");
  fs::remove_all(p.parent_path());
}

TEST_CASE("write_columns_csv quotes awkward names and refuses ragged series") {
  const fs::path p = scratch("series.csv");
  valvediag::write_columns_csv(p.string(), {"t", "op, %", "pv \"raw\""},
                               {{0, 1, 2}, {1, 2, 3}, {4, 5, 6}});
  CHECK(slurp(p) == "t,\"op, %\",\"pv \"\"raw\"\"\"\n0,1,4\n1,2,5\n2,3,6\n");
  valvediag::CsvOptions o;
  o.op_column = "op, %";
  o.pv_column = "pv \"raw\"";
  CHECK(valvediag::read_loop_csv(p.string(), o).pv == std::vector<double>{4, 5, 6});

  CHECK_THROWS_WITH_AS(
      valvediag::write_columns_csv(p.string(), {"a", "b"}, {{1, 2}, {1}}),
      ("cannot write " + p.string() + ": column 'b' has 1 values, column 'a' has 2").c_str(),
      std::runtime_error);
  CHECK_THROWS_WITH_AS(valvediag::write_columns_csv(p.string(), {"a"}, {{1}, {2}}),
                       ("cannot write " + p.string() + ": 1 names for 2 columns").c_str(),
                       std::runtime_error);
  const std::string bad = (p.parent_path() / "no-such-dir" / "x.csv").string();
  CHECK_THROWS_WITH_AS(
      valvediag::write_loop_csv(bad, sample_loop()),
      doctest::Contains(("cannot write " + bad + ": No such file or directory").c_str()),
      std::runtime_error);
  LoopData ragged = sample_loop();
  ragged.pv.pop_back();
  CHECK_THROWS_WITH_AS(
      valvediag::write_loop_csv(p.string(), ragged),
      ("cannot write " + p.string() + ": column 'pv' has 3 values, column 't' has 4").c_str(),
      std::runtime_error);
  fs::remove_all(p.parent_path());
}

TEST_CASE("check_loop_data") {
  LoopData d = sample_loop();
  CHECK_NOTHROW(valvediag::check_loop_data(d));
  d.sp.clear();
  d.mv.clear();
  CHECK_NOTHROW(valvediag::check_loop_data(d));

  LoopData short_pv = sample_loop();
  short_pv.pv.pop_back();
  CHECK_THROWS_WITH_AS(valvediag::check_loop_data(short_pv),
                       "sim: column 'pv': 3 samples, but t has 4 (the series must be aligned)",
                       DataError);
  LoopData nan = sample_loop();
  nan.mv[2] = std::numeric_limits<double>::quiet_NaN();
  CHECK_THROWS_WITH_AS(valvediag::check_loop_data(nan),
                       "sim: column 'mv': sample 3: nan is NaN or infinite (remove the row or fill "
                       "it in)",
                       DataError);
  LoopData marker = sample_loop();
  marker.pv[1] = 3.4e38;  // a historian's bad-value marker
  CHECK_THROWS_WITH_AS(valvediag::check_loop_data(marker),
                       "sim: column 'pv': sample 2: 3.4e+38 is no measurement (beyond +-1e12 in "
                       "any unit: a historian's bad-value marker or a corrupt cell; remove the row "
                       "or fill it in)",
                       DataError);
  LoopData back = sample_loop();
  back.t[2] = 0.1;
  CHECK_THROWS_WITH_AS(
      valvediag::check_loop_data(back),
      "sim: column 't': time does not increase at sample 3 (t = 0.1 s after 0.1 s)", DataError);
}

TEST_CASE("check_identifiable_data") {
  LoopData d = sample_loop();
  CHECK_NOTHROW(valvediag::check_identifiable_data(d, 4));
  CHECK_THROWS_WITH_AS(valvediag::check_identifiable_data(d, 200, "Hammerstein L=10"),
                       "sim: only 4 samples, but model Hammerstein L=10 needs at least 200 (use a "
                       "longer record or a model with fewer parameters)",
                       DataError);
  CHECK_THROWS_WITH_AS(
      valvediag::check_identifiable_data(d, 5),
      "sim: only 4 samples, but the requested model needs at least 5 (use a longer "
      "record or a model with fewer parameters)",
      DataError);
  LoopData flat = sample_loop();
  flat.op.assign(4, 30.0);
  CHECK_THROWS_WITH_AS(
      valvediag::check_identifiable_data(flat, 2),
      "sim: column 'op': constant at 30 in all 4 samples: nothing to identify (the "
      "controller output must move; is it the right column?)",
      DataError);
  LoopData inf = sample_loop();
  inf.op[0] = std::numeric_limits<double>::infinity();
  CHECK_THROWS_AS(valvediag::check_identifiable_data(inf, 2), DataError);
}
