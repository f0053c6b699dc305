// Files valvediag writes: whole or absent, never written through a planted link.
#include <doctest/doctest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <string>

#include "../common/text.hpp"
#include "valvediag/io/atomic_file.hpp"

namespace fs = std::filesystem;
using valvediag::AtomicFile;
using valvediag::write_file_atomically;

namespace {

fs::path folder(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() /
                       ("valvediag_test_atomic_" + name + "_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

using valvediag::test::slurp;

std::size_t entries(const fs::path& dir) {
  std::size_t n = 0;
  for ([[maybe_unused]] const auto& e : fs::directory_iterator(dir)) ++n;
  return n;
}

}  // namespace

TEST_CASE("a link planted at the target is replaced, its target untouched") {
  const fs::path dir = folder("link");
  std::ofstream(dir / "victim.txt") << "keep";
  fs::create_symlink(dir / "victim.txt", dir / "out.json");
  write_file_atomically((dir / "out.json").string(), "{}\n");
  CHECK(slurp(dir / "victim.txt") == "keep");
  CHECK_FALSE(fs::is_symlink(dir / "out.json"));
  CHECK(slurp(dir / "out.json") == "{}\n");
  CHECK(entries(dir) == 2);  // no temporary file left
  fs::remove_all(dir);
}

TEST_CASE("links planted at the old fixed temporary names are never written through") {
  // The history writer used DATA.history.json.tmp: a link there overwrote its target.
  const fs::path dir = folder("tmp");
  std::ofstream(dir / "victim.txt") << "keep";
  for (const char* planted : {"h.json.tmp", "h.json.partial"})
    fs::create_symlink(dir / "victim.txt", dir / planted);
  write_file_atomically((dir / "h.json").string(), "new");
  CHECK(slurp(dir / "victim.txt") == "keep");
  CHECK(slurp(dir / "h.json") == "new");
  fs::remove_all(dir);
}

TEST_CASE("not committed: the target keeps its old text and no temporary file stays") {
  const fs::path dir = folder("abort");
  std::ofstream(dir / "r.csv") << "old";
  {
    AtomicFile f((dir / "r.csv").string());
    f.write("half a fi");
    CHECK(fs::exists(f.temporary_path()));
  }
  CHECK(slurp(dir / "r.csv") == "old");
  CHECK(entries(dir) == 1);
  fs::remove_all(dir);
}

TEST_CASE("a folder that cannot be written is named, and nothing is left") {
  if (::geteuid() == 0) return;  // root writes anywhere: the refusal cannot be shown
  const fs::path dir = folder("ro");
  fs::permissions(dir, fs::perms::owner_read | fs::perms::owner_exec);
  try {
    write_file_atomically((dir / "x.json").string(), "{}");
    FAIL("wrote into a read-only folder");
  } catch (const std::runtime_error& e) {
    const std::string m = e.what();
    CHECK(m.find((dir / "x.json").string()) != std::string::npos);
    CHECK(m.find("writable") != std::string::npos);
  }
  fs::permissions(dir, fs::perms::owner_all);
  CHECK(entries(dir) == 0);
  fs::remove_all(dir);
}

TEST_CASE("a folder where the file should be is refused by name") {
  const fs::path dir = folder("dir");
  fs::create_directories(dir / "out.html");
  CHECK_THROWS_WITH_AS(write_file_atomically((dir / "out.html").string(), "x"),
                       doctest::Contains("out.html"), std::runtime_error);
  CHECK(entries(dir) == 1);
  fs::remove_all(dir);
}
