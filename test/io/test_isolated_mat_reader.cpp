// MAT-files read in a child process (src/cli/isolated_mat_reader.hpp): the same loops and the
// same errors as the direct reader, and damaged files that crash or hang libmatio end as a
// DataError naming the file.
#include <doctest/doctest.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <system_error>
#include <vector>

#include "../../src/cli/isolated_mat_reader.hpp"
#include "mat_fixtures.hpp"
#include "valvediag/io/data_error.hpp"

namespace fs = std::filesystem;
using namespace valvediag;

namespace {

const std::string kDamaged = std::string(VALVEDIAG_TEST_DIR) + "/io/damaged-mat/";

// A scratch directory removed with its files when the test ends, passed or failed (the readers'
// child processes leave by _exit, so only this process removes it).
struct TempDir {
  fs::path path =
      fs::temp_directory_path() / ("valvediag_test_isomat_" + std::to_string(::getpid()));
  TempDir() { fs::create_directories(path); }
  ~TempDir() {
    std::error_code ec;
    fs::remove_all(path, ec);
  }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  std::string file(const std::string& name) const { return (path / name).string(); }
};

// Bit for bit: NaN and -0.0 must cross the process boundary unchanged.
bool same_bits(const std::vector<double>& a, const std::vector<double>& b) {
  return a.size() == b.size() &&
         (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(double)) == 0);
}

template <class F>
DataError data_error_of(F&& f) {
  try {
    f();
  } catch (const DataError& e) {
    return e;
  }
  FAIL("no DataError");
  return DataError("", 0, "", "");
}

}  // namespace

TEST_CASE("a .mat file read in a child process gives the same loops, notes and errors") {
  const TempDir tmp;
  for (const mat_ft version : {MAT_FT_MAT5, MAT_FT_MAT73}) {
    const std::string mat = tmp.file(version == MAT_FT_MAT5 ? "runs5.mat" : "runs73.mat");
    test::write_runs_file(mat, version);
    {
      // A loop whose OP holds a NaN and a negative zero: the reader must refuse or keep them
      // exactly as the direct read does.
      test::LoopSignals s = test::sticky_loop(300);
      s.op[0] = -0.0;
      test::mat_write(mat + ".x.mat",
                      {test::mat_struct("loop", {{{"OP", test::mat_column(s.op)},
                                                  {"PV", test::mat_column(s.pv)},
                                                  {"Ts", test::mat_scalar(1.0)}}})},
                      version);
    }
    INFO(mat);
    const MatFileInfo direct = list_mat_loops(mat);
    const MatFileInfo child = cli::list_mat_loops_isolated(mat);
    CHECK(child.format == direct.format);
    REQUIRE(child.loops.size() == direct.loops.size());
    for (std::size_t i = 0; i < direct.loops.size(); ++i) {
      const auto& a = direct.loops[i];
      const auto& b = child.loops[i];
      CHECK(b.path == a.path);
      CHECK(b.matrix == a.matrix);
      CHECK(b.samples == a.samples);
      CHECK(b.columns == a.columns);
      CHECK(b.ts == a.ts);
      CHECK(b.has_op == a.has_op);
      CHECK(b.has_pv == a.has_pv);
      CHECK(b.has_sp == a.has_sp);
      CHECK(b.has_mv == a.has_mv);
      CHECK(b.fields == a.fields);
    }
    for (const auto& [file, loop] :
         std::vector<std::pair<std::string, std::string>>{{mat, "runs(2)"}, {mat + ".x.mat", ""}}) {
      std::vector<std::string> notes_direct, notes_child{"kept"};
      const LoopData a = read_mat_loop(file, loop, {}, &notes_direct);
      const LoopData b = cli::read_mat_loop_isolated(file, loop, {}, &notes_child);
      CHECK(same_bits(b.t, a.t));
      CHECK(same_bits(b.op, a.op));
      CHECK(same_bits(b.pv, a.pv));
      CHECK(same_bits(b.sp, a.sp));
      CHECK(same_bits(b.mv, a.mv));
      CHECK(b.source == a.source);
      REQUIRE(notes_child.size() == notes_direct.size() + 1);
      CHECK(notes_child.front() == "kept");  // appended, as the direct reader does
      CHECK(std::vector<std::string>(notes_child.begin() + 1, notes_child.end()) == notes_direct);
    }
    // The reader's own errors cross unchanged: message, file, line and column.
    const DataError a = data_error_of([&] { (void)read_mat_loop(mat, "runs(9)"); });
    const DataError b = data_error_of([&] { (void)cli::read_mat_loop_isolated(mat, "runs(9)"); });
    CHECK(std::string(b.what()) == a.what());
    CHECK(b.file == a.file);
    CHECK(b.line == a.line);
    CHECK(b.column == a.column);
  }
  const std::string text = tmp.file("text.mat");
  std::ofstream(text) << std::string(300, 'x');
  const DataError e = data_error_of([&] { (void)cli::list_mat_loops_isolated(text); });
  CHECK(std::string(e.what()).find("not a MATLAB v5/v7/v7.3 MAT-file") != std::string::npos);
  CHECK(e.file == text);
}

TEST_CASE("a damaged .mat file that crashes or hangs libmatio is a DataError, in bounded time") {
  // Found by mutating files of test::write_runs_file; each crashes libmatio (signal 11) or keeps
  // it busy for minutes when read directly.
  for (const char* name : {"v5-segfault.mat", "v73-segfault.mat"}) {
    INFO(name);
    const std::string mat = kDamaged + name;
    for (int which = 0; which < 2; ++which) {
      const DataError e = data_error_of([&] {
        if (which == 0)
          (void)cli::list_mat_loops_isolated(mat);
        else
          (void)cli::read_mat_loop_isolated(mat, "runs(1)");
      });
      const std::string what = e.what();
      INFO(what);
      CHECK(e.file == mat);
      CHECK(what.find("the file is damaged") != std::string::npos);
      // Signal 11 here; under ASan an error its interceptors catch first ends the child with
      // SIGABRT (abort_on_error) or an exit status.
      CHECK((what.find("libmatio crashed reading it (signal ") != std::string::npos ||
             what.find("ended without a result") != std::string::npos));
    }
  }
  for (const char* name : {"v7-hang.mat", "v73-hang.mat"}) {
    INFO(name);
    const std::string mat = kDamaged + name;
    const auto t0 = std::chrono::steady_clock::now();
    const DataError e =
        data_error_of([&] { (void)cli::read_mat_loop_isolated(mat, "runs(1)", {}, nullptr, 2.0); });
    const double took =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    const std::string what = e.what();
    INFO(what);
    CHECK(what.find("did not finish within 2 s") != std::string::npos);
    CHECK(took < 10.0);
  }
}
