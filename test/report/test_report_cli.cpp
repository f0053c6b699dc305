// valvediag report and the demo's report, as a user runs them: the file, each plot in it, the
// user errors and a missing gnuplot.
#include <doctest/doctest.h>
#include <sys/wait.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include "../common/sanitized.hpp"
#include "../common/text.hpp"
#include "page_checks.hpp"

using report_test::check_self_contained;
using report_test::count;
using report_test::figure;
using report_test::has_plot;

namespace {

struct Run {
  int status = -1;
  std::string out;  // stdout and stderr together
};

// `env` goes before the program (VAR=value ...), so a test can change PATH or VALVEDIAG_GNUPLOT.
Run run(const std::string& args, const std::string& env = "") {
  Run r;
  const std::string cmd = env + " " + std::string(VALVEDIAG_BIN) + " " + args + " 2>&1";
  FILE* p = popen(cmd.c_str(), "r");
  REQUIRE(p != nullptr);
  char buf[4096];
  while (std::fgets(buf, sizeof buf, p)) r.out += buf;
  const int st = pclose(p);
  r.status = WIFEXITED(st) ? WEXITSTATUS(st) : -1;
  return r;
}

std::string tmp(const std::string& name) {
  return std::string(VALVEDIAG_TMP) + "/" + name;
}

using valvediag::test::slurp;

// A sticky loop (the paper's Example 1, 1500 samples) with no model history yet in the file that
// --history CSV.history.json names.
std::string sticky_loop(const std::string& name) {
  const std::string csv = tmp(name);
  const Run s = run("simulate --scenario paper-ex1 --seed 1 --samples 1500 --out " + csv);
  REQUIRE(s.status == 0);
  std::filesystem::remove(csv + ".history.json");
  return csv;
}

}  // namespace

TEST_CASE("report on a simulated sticky loop: one self-contained page with every plot" *
          valvediag::test::release_only()) {
  const std::string csv = sticky_loop("sticky.csv"), out = tmp("sticky.html");
  std::filesystem::remove(out);
  const std::string hist = " --history " + csv + ".history.json";
  const Run r = run("report " + csv + hist + " --model preisach:general --out " + out);
  INFO(r.out);
  REQUIRE(r.status == 0);
  CHECK(r.out.find("wrote " + out) != std::string::npos);
  CHECK(r.out.find("10 plots") != std::string::npos);
  CHECK(r.out.find("verdict:") != std::string::npos);
  const std::string h = slurp(out);
  check_self_contained(h);
  for (const char* id :
       {"plot-trends", "plot-fit", "plot-residual", "plot-resid", "plot-pv-op", "plot-signature",
        "plot-preisach", "plot-bode", "plot-step", "plot-ladder"})
    CHECK_MESSAGE(has_plot(h, id), id);
  CHECK(count(figure(h, "plot-fit"), "rgb(244, 182, 182)") >= 1);  // failing intervals shaded
  CHECK(figure(h, "plot-trends").find("SP") != std::string::npos);
  CHECK(figure(h, "plot-preisach").find("nonzero weights") != std::string::npos);
  CHECK(h.find("id=\"where-intervals\"") != std::string::npos);
  CHECK(h.find("id=\"findings\"") != std::string::npos);  // the diagnosis ran
  CHECK(h.find("id=\"ladder-table\"") != std::string::npos);
  CHECK(h.find("<code>preisach:general</code>") != std::string::npos);
  CHECK(h.find("% on validation data") != std::string::npos);
  // The fit entered the model history; the next report takes the ladder's last model.
  CHECK(std::filesystem::exists(csv + ".history.json"));
  const Run again = run("report " + csv + hist + " --no-diagnose --out " + tmp("again.html"));
  INFO(again.out);
  CHECK(again.status == 0);
  CHECK(again.out.find("model preisach:general (the last model of this data's ladder)") !=
        std::string::npos);
  const std::string h2 = slurp(tmp("again.html"));
  CHECK(h2.find("Not diagnosed") != std::string::npos);
  CHECK(has_plot(h2, "plot-preisach"));
}

// With no --model the page explains its verdict: it shows the model the verdict rests on (the end
// of diagnose --auto's climb), not the ladder's last model or a bare Preisach plane.
TEST_CASE("report without --model shows the model its verdict rests on" *
          valvediag::test::release_only()) {
  const std::string csv = sticky_loop("verdict-model.csv"), out = tmp("verdict-model.html");
  const Run r = run("report " + csv + " --no-plots --no-history --out " + out);
  INFO(r.out);
  REQUIRE(r.status == 0);
  CHECK(r.out.find("note: model stiction (the model the verdict rests on") != std::string::npos);
  CHECK(r.out.find("verdict:   stiction") != std::string::npos);
  const std::string h = slurp(out);
  CHECK(h.find("<tr><th>model</th><td><code>stiction") != std::string::npos);
}

TEST_CASE("report: user errors exit 2 with a clear message and leave no file") {
  const std::string csv = sticky_loop("errors.csv");
  SUBCASE("bad --model names the vocabulary") {
    const Run r = run("report " + csv + " --model stiction+wobble --out " + tmp("bad.html"));
    CHECK(r.status == 2);
    CHECK(r.out.find("wobble") != std::string::npos);
    CHECK(r.out.find("deadband") != std::string::npos);
    CHECK(!std::filesystem::exists(tmp("bad.html")));
  }
  SUBCASE("unwritable --out") {
    const Run r = run("report " + csv + " --out /nonexistent-dir/report.html");
    CHECK(r.status == 2);
    CHECK(r.out.find("cannot write the report to /nonexistent-dir/report.html") !=
          std::string::npos);
    const Run d = run("report " + csv + " --out " + std::string(VALVEDIAG_TMP));
    CHECK(d.status == 2);
  }
  SUBCASE("no --out: no page beside the data, nor anywhere") {
    const Run r = run("report " + csv + " --no-plots --no-diagnose");
    CHECK(r.status == 2);
    CHECK(r.out.find("--out FILE: give the HTML file to write") != std::string::npos);
    CHECK(!std::filesystem::exists(csv + ".report.html"));
  }
  SUBCASE("no data, or a missing file") {
    CHECK(run("report --out " + tmp("x.html")).status == 2);
    CHECK(run("report " + tmp("no-such.csv") + " --out " + tmp("x.html")).status == 2);
  }
}

TEST_CASE("report without gnuplot: says which package to install, or writes notes (--no-plots)") {
  const std::string csv = tmp("clean.csv"), out = tmp("nognuplot.html");
  REQUIRE(run("simulate --scenario linear-clean --seed 1 --samples 1500 --out " + csv).status == 0);
  std::filesystem::remove(out);
  for (const std::string& env :
       {std::string("VALVEDIAG_GNUPLOT=/nonexistent/gnuplot"), std::string("PATH=/nonexistent")}) {
    const Run r = run("report " + csv + " --model linear --out " + out, env);
    INFO(env, r.out);
    CHECK(r.status == 1);
    CHECK(r.out.find("gnuplot-nox") != std::string::npos);
    CHECK(r.out.find("--no-plots") != std::string::npos);
    CHECK(!std::filesystem::exists(out));
  }
  const Run n = run("report " + csv + " --model linear --no-diagnose --no-plots --out " + out,
                    "VALVEDIAG_GNUPLOT=/nonexistent/gnuplot");
  INFO(n.out);
  CHECK(n.status == 0);
  const std::string h = slurp(out);
  check_self_contained(h);
  CHECK(h.find("<svg") == std::string::npos);
  CHECK(h.find("Plots left out (--no-plots)") != std::string::npos);
  CHECK(h.find("id=\"where-intervals\"") != std::string::npos);
}

TEST_CASE("demo --offline diagnoses and writes the report, and says where it is" *
          valvediag::test::release_only()) {
  const std::string dir = tmp("demo-out");
  std::filesystem::remove_all(dir);
  const Run r = run("demo --offline --out-dir " + dir);
  INFO(r.out);
  REQUIRE(r.status == 0);
  const std::string report = dir + "/report.html";
  CHECK(r.out.find("verdict:") != std::string::npos);
  CHECK(r.out.find("report (HTML)   " + report) != std::string::npos);
  CHECK(r.out.find("model history   " + dir + "/fic101.csv.history.json   (valvediag ladder " +
                   dir + "/fic101.csv --history " + dir + "/fic101.csv.history.json)") !=
        std::string::npos);
  const std::string h = slurp(report);
  check_self_contained(h);
  for (const char* id : {"plot-fit", "plot-preisach", "plot-ladder"})
    CHECK_MESSAGE(has_plot(h, id), id);
  CHECK(h.find("id=\"findings\"") != std::string::npos);
  // The ladder: linear (diagnosed) and the full-grid Preisach fit.
  const Run l = run("ladder " + dir + "/fic101.csv --history " + dir + "/fic101.csv.history.json");
  CHECK(l.status == 0);
  CHECK(l.out.find("linear") != std::string::npos);
  CHECK(l.out.find("preisach") != std::string::npos);
}
