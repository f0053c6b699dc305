// --format auto (the default) and plain as a user meets them: a historian export read with no
// layout options, the chosen options shown, options given winning, bad values refused.
#include <doctest/doctest.h>

#include <filesystem>
#include <string>
#include <vector>

#include "../common/run_cli.hpp"
#include "../common/text.hpp"

namespace fs = std::filesystem;
using valvediag::test::CliResult;

namespace {

const std::string kExport = std::string(VALVEDIAG_DATA_DIR) +
                            "/plant-loops/stiction/stic_2111FIC46005_0902_0003_Stick1=0.txt";

CliResult run_auto(const std::vector<std::string>& args) {
  return valvediag::test::run_cli(VALVEDIAG_BIN, args, VALVEDIAG_TMP, 120.0);
}

using valvediag::test::has;

const std::vector<std::string> kSmall = {"--na-max", "1", "--nb-max",    "1", "--nk-max", "2",
                                         "--L-max",  "8", "--no-history"};

std::vector<std::string> fit(std::vector<std::string> args) {
  args.insert(args.begin(), {"fit", kExport});
  args.insert(args.end(), kSmall.begin(), kSmall.end());
  return args;
}

}  // namespace

TEST_CASE("fit reads a historian export with no layout options and shows what it chose") {
  const CliResult r = run_auto(fit({}));
  CHECK(r.status == 0);
  CHECK(has(r.out,
            "note: read as --skip-lines 2 --skip-after-header 2 --time-format '%Y-%m-%d "
            "%H:%M:%S' --t 1 --op '*.MV' --pv '*.PV' --sp '*.SV' (found by --format auto)\n"));
  CHECK(has(r.out, "(751 samples, Ts 10.000 s"));
  // Options given win, and are not repeated in the note.
  const CliResult g = run_auto(fit({"--pv", "3", "--sp", "none"}));
  CHECK(g.status == 0);
  CHECK(has(g.out,
            "note: columns: t = 'tagname' (1), op = '2111FIC46005.MV' (2), pv = "
            "'2111FIC46005.PV' (3)\n"));
  CHECK(has(g.out,
            "note: read as --skip-lines 2 --skip-after-header 2 --time-format "
            "'%Y-%m-%d %H:%M:%S' --t 1 --op '*.MV' (found by --format auto)\n"));
}

TEST_CASE("--format plain reads with the options alone; other values are refused") {
  const CliResult p = run_auto(
      fit({"--format", "plain", "--skip-lines", "2", "--t", "1", "--op", "*.MV", "--pv", "*.PV"}));
  CHECK(p.status == 2);
  CHECK(has(p.out,
            ":4: column 'tagname' (t): 'desc' is not data: line 4 is text (units or "
            "descriptions under the header row?); skip the lines up to 5 with "
            "--skip-after-header 2"));
  CHECK_FALSE(has(p.out, "read as"));
  const CliResult bad = run_auto(fit({"--format", "excel"}));
  CHECK(bad.status == 2);
  CHECK(has(bad.out, "--format"));
}
