// The MAT-file reader: the International Stiction Database benchmark, the Tennessee Eastman runs
// and files written here (every layout, numeric class and format), and files that are not
// MAT-files at all.
#include <doctest/doctest.h>
#include <unistd.h>

#include <algorithm>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <random>
#include <string>
#include <vector>

#include "../common/text.hpp"
#include "mat_fixtures.hpp"
#include "valvediag/io/data_error.hpp"
#include "valvediag/io/mat_reader.hpp"

namespace fs = std::filesystem;
using namespace valvediag;
using namespace valvediag::test;

namespace {

const std::string kBenchmark = std::string(VALVEDIAG_DATA_DIR) + "/benchmark.mat";
const std::string kTe14 = std::string(VALVEDIAG_DATA_DIR) + "/tennessee-eastman/m1d14.mat";

struct TmpDir {
  fs::path path = fs::temp_directory_path() / ("valvediag_test_mat_" + std::to_string(::getpid()));
  TmpDir() { fs::create_directories(path); }
  ~TmpDir() {
    std::error_code ec;
    fs::remove_all(path, ec);
  }
  std::string operator()(const std::string& name) const { return (path / name).string(); }
};

// The message of the DataError `f` throws ("" when it does not throw one).
template <class F>
std::string error_of(F&& f) {
  try {
    f();
  } catch (const DataError& e) {
    return e.what();
  }
  return "";
}

using valvediag::test::has;

void write_bytes(const std::string& path, const std::string& bytes) {
  std::ofstream(path, std::ios::binary) << bytes;
}

std::string read_bytes(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>()};
}

}  // namespace

TEST_CASE("benchmark.mat: the stiction database's loops are listed by group") {
  const MatFileInfo info = list_mat_loops(kBenchmark);
  CHECK(info.loops.size() == 93);
  std::map<std::string, int> groups;
  for (const auto& l : info.loops) {
    CHECK(l.has_op);
    CHECK_FALSE(l.has_pv);  // OP and Ts only
    CHECK_FALSE(l.matrix);
    CHECK(l.ts.has_value());
    const auto a = l.path.find('.'), b = l.path.rfind('.');
    REQUIRE(a != b);
    CHECK(l.path.substr(0, a) == "benchmark");
    ++groups[l.path.substr(a + 1, b - a - 1)];
  }
  CHECK(groups == std::map<std::string, int>{{"buildings", 8},
                                             {"chemicals", 63},
                                             {"pulpPapers", 13},
                                             {"power", 5},
                                             {"mining", 1},
                                             {"metals", 3}});
  const auto it = std::find_if(info.loops.begin(), info.loops.end(), [](const auto& l) {
    return l.path == "benchmark.chemicals.loop23";
  });
  REQUIRE(it != info.loops.end());
  CHECK(it->samples == 1500);
  CHECK(*it->ts == 10.0);
  CHECK(it->fields == std::vector<std::string>{"oscillation", "Ts", "OP"});
}

TEST_CASE("benchmark.mat: a loop without PV gets a message naming what is missing") {
  const std::string e = error_of([] { read_mat_loop(kBenchmark, "chemicals.loop23"); });
  CHECK(has(e, kBenchmark));
  CHECK(has(e, "benchmark.chemicals.loop23"));
  CHECK(has(e, "no PV field"));
  CHECK(has(e, "fields present: oscillation, Ts, OP"));

  SUBCASE("OP only when PV is not required") {
    MatOptions o;
    o.require_pv = false;
    std::vector<std::string> notes;
    const LoopData d = read_mat_loop(kBenchmark, "chemicals.loop23", o, &notes);
    CHECK(d.size() == 1500);
    CHECK(d.pv.empty());
    CHECK(d.t[1] == 10.0);
    CHECK(d.t.back() == 14990.0);
    CHECK(d.source == kBenchmark + ":benchmark.chemicals.loop23");
    REQUIRE(notes.size() == 1);
    CHECK(has(notes[0], "no PV"));
  }
  SUBCASE("the full path, a unique tail, an ambiguous tail, no such loop, no loop at all") {
    MatOptions o;
    o.require_pv = false;
    CHECK(read_mat_loop(kBenchmark, "benchmark.chemicals.loop23", o).size() == 1500);
    CHECK(read_mat_loop(kBenchmark, "loop23", o).size() == 1500);  // only chemicals has 23
    const std::string amb = error_of([&] { read_mat_loop(kBenchmark, "loop1", o); });
    CHECK(has(amb, "ambiguous"));
    CHECK(has(amb, "benchmark.buildings.loop1"));
    CHECK(has(amb, "benchmark.chemicals.loop1"));
    const std::string none = error_of([&] { read_mat_loop(kBenchmark, "chemicals.loop99", o); });
    CHECK(has(none, "no loop 'chemicals.loop99'"));
    const std::string many = error_of([&] { read_mat_loop(kBenchmark, "", o); });
    CHECK(has(many, "93 loops"));
    CHECK(has(many, "--loop"));
    CHECK(has(many, "benchmark.buildings.loop1"));
  }
}

TEST_CASE("Tennessee Eastman m1d14: a plain matrix read by column numbers") {
  const MatFileInfo info = list_mat_loops(kTe14);
  REQUIRE(info.loops.size() == 1);
  CHECK(info.loops[0].matrix);
  CHECK(info.loops[0].path == "m1d14");
  CHECK(info.loops[0].samples == 7201);
  CHECK(info.loops[0].columns == 81);

  MatOptions o;
  CHECK(has(error_of([&] { read_mat_loop(kTe14, "", o); }), "--op N"));
  o.op = "51";  // XMV(10), reactor cooling water flow
  o.pv = "21";  // XMEAS(21), reactor cooling water outlet temperature
  CHECK(has(error_of([&] { read_mat_loop(kTe14, "m1d14", o); }), "--sample-period"));
  o.sample_period = 36.0;
  const LoopData d = read_mat_loop(kTe14, "m1d14", o);
  CHECK(d.size() == 7201);
  CHECK(d.sample_period() == 36.0);
  CHECK(d.t.back() == 7200.0 * 36.0);  // 72 h
  CHECK(d.op[0] == doctest::Approx(35.865).epsilon(1e-4));
  CHECK(d.pv[0] == doctest::Approx(102.48).epsilon(1e-4));
  o.op = "82";
  CHECK(has(error_of([&] { read_mat_loop(kTe14, "m1d14", o); }), "outside 1..81"));
  o.op = "51";
  o.sample_period = 30.0;
  // Not a time column: XMEAS(1) does not increase. (Assigned from a char, not "1": g++ 12 -O2
  // reports a false -Wrestrict on that literal assignment here.)
  o.t = std::string(1, '1');
  CHECK(has(error_of([&] { read_mat_loop(kTe14, "m1d14", o); }), "time column 1"));
}

TEST_CASE("files written here: struct arrays, cells, top-level loops, every format") {
  TmpDir tmp;
  const LoopSignals s = sticky_loop(400, 1);
  struct Case {
    const char* name;
    mat_ft version;
    matio_compression compression;
  };
  for (const Case c : {Case{"v5", MAT_FT_MAT5, MAT_COMPRESSION_NONE},
                       Case{"v7", MAT_FT_MAT5, MAT_COMPRESSION_ZLIB},
                       Case{"v73", MAT_FT_MAT73, MAT_COMPRESSION_NONE}}) {
    CAPTURE(c.name);
    const std::string path = tmp(std::string("runs-") + c.name + ".mat");
    write_runs_file(path, c.version, c.compression);
    const MatFileInfo info = list_mat_loops(path);
    REQUIRE(info.loops.size() == 2);
    CHECK(info.loops[0].path == "runs(1)");
    CHECK(info.loops[1].path == "runs(2)");
    CHECK(info.loops[1].has_pv);
    CHECK(info.loops[1].has_sp);
    CHECK_FALSE(info.loops[1].has_mv);
    CHECK(info.loops[1].samples == 400);
    CHECK(*info.loops[1].ts == 0.5);
    CHECK(info.format == (c.version == MAT_FT_MAT73 ? "MATLAB v7.3 (HDF5)" : "MATLAB v5/v7"));
    const LoopData d = read_mat_loop(path, "runs(2)");
    CHECK(d.op == s.op);  // column vector
    CHECK(d.pv == s.pv);  // row vector
    CHECK(d.sp == s.sp);
    CHECK(d.t[399] == 199.5);
    CHECK(has(error_of([&] { read_mat_loop(path, ""); }), "2 loops"));
  }

  SUBCASE("single, int16 and uint8 data; lower-case field names") {
    const std::string path = tmp("classes.mat");
    std::vector<double> op(300), pv(300), sp(300, 7);
    for (std::size_t i = 0; i < op.size(); ++i) {
      op[i] = static_cast<double>(i % 50);
      pv[i] = static_cast<double>(i % 30) * 0.25;
    }
    mat_write(path,
              {mat_struct("loop", {{{"op", mat_column(op, MAT_C_INT16)},
                                    {"pv", mat_row(pv, MAT_C_SINGLE)},
                                    {"sp", mat_column(sp, MAT_C_UINT8)},
                                    {"ts", mat_scalar(2)}}})},
              MAT_FT_MAT5, MAT_COMPRESSION_ZLIB);
    const LoopData d = read_mat_loop(path, "");
    CHECK(d.op == op);
    CHECK(d.pv == pv);  // quarter steps are exact in single precision
    CHECK(d.sp == sp);
    CHECK(d.sample_period() == 2.0);
  }
  SUBCASE("a loop in a cell inside a struct, and one saved as top-level variables") {
    const std::string nested = tmp("nested.mat");
    mat_write(
        nested,
        {mat_struct("site",
                    {{{"name", mat_scalar(1)},
                      {"loops", mat_cell(nullptr, {mat_struct(nullptr, {{
                                                                           {"OP", mat_column(s.op)},
                                                                           {"PV", mat_column(s.pv)},
                                                                           {"Ts", mat_scalar(1)},
                                                                       }})})}}})});
    const MatFileInfo info = list_mat_loops(nested);
    REQUIRE(info.loops.size() == 1);
    CHECK(info.loops[0].path == "site.loops{1}");
    CHECK(read_mat_loop(nested, "loops{1}").pv == s.pv);

    const std::string top = tmp("top.mat");
    std::vector<matvar_t*> vars{mat_column(s.op), mat_column(s.pv), mat_scalar(0.1)};
    const char* names[] = {"OP", "PV", "Ts"};
    for (int i = 0; i < 3; ++i) vars[i]->name = strdup(names[i]);
    mat_write(top, vars);
    CHECK(list_mat_loops(top).loops.at(0).path == ".");
    const LoopData d = read_mat_loop(top, "");
    CHECK(d.op == s.op);
    CHECK(d.sample_period() == doctest::Approx(0.1));
  }
  SUBCASE("what is wrong with a loop is named") {
    const std::string path = tmp("bad.mat");
    std::vector<double> nan_op = s.op;
    nan_op[7] = std::nan("");
    std::vector<double> short_pv(s.pv.begin(), s.pv.begin() + 100);
    mat_write(
        path,
        {mat_struct(
            "bad", {{{"OP", mat_column(nan_op)}, {"PV", mat_column(s.pv)}, {"Ts", mat_scalar(1)}},
                    {{"OP", mat_column(s.op)}, {"PV", mat_column(short_pv)}, {"Ts", mat_scalar(1)}},
                    {{"OP", mat_column(s.op)},
                     {"PV", mat_column(s.pv)},
                     {"Ts", mat_numeric({1, 2}, 1, 2)}},
                    {{"OP", mat_column(s.op)}, {"PV", mat_column(s.pv)}, {"Ts", nullptr}}})});
    CHECK(has(error_of([&] { read_mat_loop(path, "bad(1)"); }),
              "op sample 8: nan is NaN or infinite"));
    CHECK(
        has(error_of([&] { read_mat_loop(path, "bad(2)"); }), "pv has 100 samples but op has 400"));
    CHECK(has(error_of([&] { read_mat_loop(path, "bad(3)"); }), "field Ts must be one positive"));
    const std::string no_ts = error_of([&] { read_mat_loop(path, "bad(4)"); });
    CHECK(has(no_ts, "bad(4)"));
    CHECK(has(no_ts, "Ts"));
    CHECK(has(no_ts, "--sample-period"));
    MatOptions o;
    o.sample_period = 2.0;
    CHECK(read_mat_loop(path, "bad(4)", o).sample_period() == 2.0);
    CHECK(has(error_of([&] { read_mat_loop(path, "bad(2)", o); }), "disagrees with Ts"));
    o.sample_period.reset();
    o.pv = "flow";
    CHECK(has(error_of([&] { read_mat_loop(path, "bad(2)", o); }),
              "no FLOW field (fields present: OP, PV, Ts)"));
    o.pv = "3";
    CHECK(has(error_of([&] { read_mat_loop(path, "bad(2)", o); }), "columns of a matrix"));
  }
}

TEST_CASE("garbage, truncated and foreign files: a DataError, never a crash") {
  TmpDir tmp;
  const std::string runs = tmp("runs.mat"), zruns = tmp("zruns.mat");
  write_runs_file(runs);
  write_runs_file(zruns, MAT_FT_MAT5, MAT_COMPRESSION_ZLIB);
  auto refused = [&](const std::string& path, const std::string& part) {
    CAPTURE(path);
    const std::string e = error_of([&] { list_mat_loops(path); });
    CHECK(has(e, path));
    CHECK(has(e, part));
    CHECK(has(error_of([&] { read_mat_loop(path, "runs(1)"); }), path));
  };
  refused(tmp("missing.mat"), "cannot open");
  write_bytes(tmp("empty.mat"), "");
  refused(tmp("empty.mat"), "too short");
  write_bytes(tmp("text.mat"), "t,op,pv\n0,1,2\n1,2,3\n" + std::string(200, '#'));
  refused(tmp("text.mat"), "not a MATLAB v5/v7/v7.3 MAT-file");

  std::mt19937 rng(5);
  std::string noise(4096, '\0');
  for (char& c : noise) c = static_cast<char>(rng());
  write_bytes(tmp("noise.mat"), noise);
  refused(tmp("noise.mat"), "not a MATLAB");
  const std::string header = read_bytes(runs).substr(0, 128);
  write_bytes(tmp("header-noise.mat"), header + noise);
  refused(tmp("header-noise.mat"), "malformed");

  for (const std::string& full : {read_bytes(runs), read_bytes(zruns), read_bytes(kBenchmark)})
    for (const std::size_t cut :
         {std::size_t{130}, std::size_t{136}, std::size_t{600}, full.size() / 2, full.size() - 1}) {
      CAPTURE(cut);
      write_bytes(tmp("cut.mat"), full.substr(0, cut));
      refused(tmp("cut.mat"), "the file ends inside");
    }

  // Damaged bytes inside the data: a DataError or a loop read from the damaged data, but no
  // crash (the sanitizer build runs this too).
  for (const std::string& src : {runs, zruns}) {
    const std::string full = read_bytes(src);
    std::uniform_int_distribution<std::size_t> at(128, full.size() - 1);
    for (int k = 0; k < 60; ++k) {
      std::string b = full;
      for (int j = 0; j < 4; ++j) b[at(rng)] = static_cast<char>(rng());
      write_bytes(tmp("damaged.mat"), b);
      try {
        (void)list_mat_loops(tmp("damaged.mat"));
        (void)read_mat_loop(tmp("damaged.mat"), "runs(1)");
      } catch (const DataError&) {
      }
    }
  }
}
