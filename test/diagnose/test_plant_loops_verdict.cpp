// The verdict on the 41 real plant loops of shared/data/plant-loops, labelled `stiction` /
// `no-stiction` by their provider. Prints every loop's verdict with what it rests on, the
// confusion table (label vs verdict), balanced accuracy and the false-sticky rate, and a
// leave-one-out and a split-half check of the two evidence thresholds (were they fitted to these
// files?). The file-name figure `Stick1=` is the provider's, never read here.
#include <doctest/doctest.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "valvediag/csv_reader.hpp"
#include "valvediag/data_error.hpp"
#include "valvediag/scenarios.hpp"
#include "valvediag/verdict.hpp"

namespace fs = std::filesystem;
using namespace valvediag;

namespace {

// The CLI equivalent: --delimiter tab --skip-lines 2 --skip-after-header 2
// --time-format '%Y-%m-%d %H:%M:%S' --t 1 --op '*.MV' --pv '*.PV' --sp '*.SV'
CsvOptions plant_options() {
  CsvOptions o;
  o.delimiter = "tab";
  o.skip_lines = 2;
  o.skip_after_header = 2;
  o.time_format = "%Y-%m-%d %H:%M:%S";
  o.t_column.assign(1, '1');  // column 1 (its header is "tagname")
  o.op_column = "*.MV";
  o.pv_column = "*.PV";
  o.sp_column = "*.SV";
  return o;
}

// The sample period the export states on its second line (columns, period, start, rows).
double stated_period(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::string line;
  std::getline(in, line);
  std::getline(in, line);
  std::stringstream ss(line);
  std::string cell;
  std::getline(ss, cell, '\t');
  std::getline(ss, cell, '\t');
  return std::strtod(cell.c_str(), nullptr);
}

// One export as LoopData. An export whose time stamps are broken (one repeats a stamp) is read
// by row number at its stated period: the verdict then judges the data itself.
LoopData read_plant(const fs::path& p, std::string* note) {
  try {
    return read_loop_csv(p.string(), plant_options());
  } catch (const DataError& e) {
    *note = "time stamps unusable, read by row at the stated period";
    CsvOptions o = plant_options();
    o.t_column = "none";
    o.sample_period = stated_period(p);
    return read_loop_csv(p.string(), o);
  }
}

struct Row {
  std::string file, loop, label;
  LoopVerdict v;
  double seconds = 0;
};

// Loop tag: the file name up to the date part, e.g. "2411FIC20102" (several files per loop).
std::string loop_tag(const std::string& file) {
  std::string s = file.substr(file.find('_') + 1);  // drop "stic_"
  if (s.rfind("2_", 0) == 0 || s.rfind("RHT.", 0) == 0) {
    const auto a = s.find('_', s.find('.'));
    return s.substr(0, a);
  }
  return s.substr(0, s.find('_'));
}

struct Score {
  int tp = 0, fn = 0, tn = 0, fp = 0;
  double recall() const { return tp + fn ? double(tp) / (tp + fn) : 0; }
  double specificity() const { return tn + fp ? double(tn) / (tn + fp) : 0; }
  double balanced() const { return 0.5 * (recall() + specificity()); }
  double false_sticky() const { return tn + fp ? double(fp) / (tn + fp) : 0; }
  void add(bool sticky_label, bool sticky_verdict) {
    if (sticky_label)
      (sticky_verdict ? tp : fn)++;
    else
      (sticky_verdict ? fp : tn)++;
  }
};

bool usable(const Row& r) {
  return r.v.verdict != "not-enough-data";
}

std::string redecide(const Row& r, const VerdictOptions& o) {
  return usable(r) ? decide_verdict(r.v.figures, o) : r.v.verdict;
}

// Balanced accuracy of the thresholds on a set of rows.
double balanced(const std::vector<const Row*>& rows, const VerdictOptions& o) {
  Score s;
  for (const Row* r : rows) s.add(r->label == "stiction", redecide(*r, o) == "stiction");
  return s.balanced() - 0.5 * s.false_sticky();  // prefer fewer false alarms among equals
}

// The thresholds that do best on `train` over a coarse grid (the defaults win ties).
VerdictOptions fit_thresholds(const std::vector<const Row*>& train) {
  VerdictOptions best;
  double best_score = balanced(train, best);
  for (double g : {2.5, 5.0, 7.5, 10.0, 12.5, 15.0, 20.0, 25.0})
    for (double rel : {0.05, 0.1, 0.15, 0.2, 0.25, 0.3, 0.35, 0.4, 0.5}) {
      VerdictOptions o;
      o.min_gain_points = g;
      o.min_relative_gain = rel;
      const double s = balanced(train, o);
      if (s > best_score + 1e-12) {
        best_score = s;
        best = o;
      }
    }
  return best;
}

#ifdef VALVEDIAG_SANITIZED
constexpr bool kSanitized = true;  // every 5th file: memory checks, not the accuracy figures
#else
constexpr bool kSanitized = false;
#endif

std::vector<Row> run_all() {
  std::vector<Row> rows;
  const fs::path root = fs::path(VALVEDIAG_DATA_DIR) / "plant-loops";
  for (const char* label : {"stiction", "no-stiction"}) {
    std::vector<fs::path> files;
    for (const auto& e : fs::directory_iterator(root / label))
      if (e.is_regular_file()) files.push_back(e.path());
    std::sort(files.begin(), files.end());
    if (kSanitized) {
      std::vector<fs::path> sample;
      for (std::size_t i = 0; i < files.size(); i += 5) sample.push_back(files[i]);
      files = sample;
    }
    for (const auto& p : files) {
      Row r;
      r.file = p.filename().string();
      r.loop = loop_tag(r.file);
      r.label = label;
      std::string note;
      const LoopData d = read_plant(p, &note);
      const auto t0 = std::chrono::steady_clock::now();
      r.v = loop_verdict(d);
      r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      if (!note.empty()) r.v.reason += " (" + note + ")";
      rows.push_back(std::move(r));
    }
  }
  return rows;
}

}  // namespace

TEST_CASE("the verdict on real plant loops against the provider's labels (confusion table)") {
  const auto t0 = std::chrono::steady_clock::now();
  const std::vector<Row> rows = run_all();
  const double total = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (kSanitized) {  // the sample ran through every path; the figures need all 41 files
    CHECK(rows.size() == 9);
    for (const Row& r : rows) CHECK(!r.v.verdict.empty());
    return;
  }
  REQUIRE(rows.size() == 41);

  std::printf("\n%-46s %-11s %-18s %6s %6s %6s %6s %5s\n", "file", "label", "verdict", "gain",
              "rel", "band%", "noise%", "s");
  for (const Row& r : rows) {
    const auto& f = r.v.figures;
    std::printf("%-46.46s %-11s %-18s %+6.1f %6.2f %6.2f %6.3f %5.2f\n", r.file.c_str(),
                r.label.c_str(), r.v.verdict.c_str(), f.hysteresis_gain, f.relative_gain, f.band,
                f.op_noise, r.seconds);
    std::printf("    %s\n", r.v.reason.c_str());
    if (std::getenv("VALVEDIAG_VERDICT_DUMP")) {
      std::printf("DUMP %s %s %.2f %.2f %.2f %.2f %.2f %.2f %.3f %.3f %.3f %.3f", r.label.c_str(),
                  r.loop.c_str(), f.linear_fitness, f.saturation_fitness, f.characteristic_fitness,
                  f.stiction_fitness, f.preisach_fitness, f.deadband_fitness, f.fs, f.fd,
                  f.op_noise, f.op_range);
      if (!r.v.diagnosis.steps.empty())
        for (const auto& x : r.v.diagnosis.last().findings)
          std::printf(" %s:%.1f:%.1f", x.effect.c_str(), x.estimation_gain_percent,
                      x.validation_gain_percent);
      std::printf("\n");
    }
  }

  const char* verdicts[] = {"stiction", "deadband", "other-nonlinearity", "no-valve-problem",
                            "not-enough-data"};
  std::map<std::string, std::map<std::string, int>> table;
  Score all, usable_only;
  for (const Row& r : rows) {
    table[r.label][r.v.verdict]++;
    all.add(r.label == "stiction", r.v.verdict == "stiction");
    if (usable(r)) usable_only.add(r.label == "stiction", r.v.verdict == "stiction");
  }
  std::printf(
      "\n| label \\ verdict | stiction | deadband | other-nonlinearity | no-valve-problem | "
      "not-enough-data |\n| --- | --- | --- | --- | --- | --- |\n");
  for (const char* label : {"stiction", "no-stiction"}) {
    std::printf("| %s (%d) |", label, label == std::string("stiction") ? 18 : 23);
    for (const char* v : verdicts) std::printf(" %d |", table[label][v]);
    std::printf("\n");
  }
  std::printf(
      "all 41: sticky loops found %d of %d, no-stiction loops called sticky %d of %d; "
      "balanced accuracy %.1f %%, false-sticky rate %.1f %%\n",
      all.tp, all.tp + all.fn, all.fp, all.fp + all.tn, 100 * all.balanced(),
      100 * all.false_sticky());
  std::printf("usable records only (%d): balanced accuracy %.1f %%, false-sticky rate %.1f %%\n",
              usable_only.tp + usable_only.fn + usable_only.tn + usable_only.fp,
              100 * usable_only.balanced(), 100 * usable_only.false_sticky());

  // Overfitting checks: choose the two evidence thresholds on the other files only.
  std::vector<const Row*> ptr;
  for (const Row& r : rows) ptr.push_back(&r);
  Score loo, loo_loop;
  for (std::size_t i = 0; i < rows.size(); ++i) {
    std::vector<const Row*> train, train_loop;
    for (std::size_t j = 0; j < rows.size(); ++j) {
      if (j != i) train.push_back(&rows[j]);
      if (rows[j].loop != rows[i].loop) train_loop.push_back(&rows[j]);
    }
    loo.add(rows[i].label == "stiction", redecide(rows[i], fit_thresholds(train)) == "stiction");
    loo_loop.add(rows[i].label == "stiction",
                 redecide(rows[i], fit_thresholds(train_loop)) == "stiction");
  }
  // Split-half by loop (all files of a loop on one side), both ways.
  std::vector<std::string> loops;
  for (const Row& r : rows)
    if (std::find(loops.begin(), loops.end(), r.loop) == loops.end()) loops.push_back(r.loop);
  std::vector<const Row*> half[2];
  for (const Row& r : rows) {
    const auto k = std::find(loops.begin(), loops.end(), r.loop) - loops.begin();
    half[k % 2].push_back(&r);
  }
  Score split;
  for (int h = 0; h < 2; ++h) {
    const VerdictOptions o = fit_thresholds(half[h]);
    std::printf(
        "split-half: thresholds from half %d (%zu files): gain >= %.1f points, relative "
        ">= %.2f\n",
        h, half[h].size(), o.min_gain_points, o.min_relative_gain);
    for (const Row* r : half[1 - h])
      split.add(r->label == "stiction", redecide(*r, o) == "stiction");
  }
  std::printf("leave-one-file-out: balanced accuracy %.1f %%, false-sticky %.1f %%\n",
              100 * loo.balanced(), 100 * loo.false_sticky());
  std::printf("leave-one-loop-out: balanced accuracy %.1f %%, false-sticky %.1f %%\n",
              100 * loo_loop.balanced(), 100 * loo_loop.false_sticky());
  std::printf("split-half by loop: balanced accuracy %.1f %%, false-sticky %.1f %%\n",
              100 * split.balanced(), 100 * split.false_sticky());
  std::printf("runtime: %.1f s for 41 files\n", total);

  // What is measured (issue 5 aims at >= 85 % and <= 10 %; not reached: 9 of 18 sticky loops
  // found, none of the 23 clean ones called sticky, 75 %). The thresholds are the defaults
  // (10 points, 25 %); the choice of them on the other files must do nearly as well.
  CHECK(all.tp >= 9);
  CHECK(all.fp == 0);
  CHECK(all.balanced() >= 0.74);
  CHECK(all.false_sticky() <= 0.0);
  CHECK(loo_loop.balanced() >= 0.70);
  CHECK(loo_loop.false_sticky() <= 0.1);
  CHECK(split.balanced() >= 0.74);
  // The dead-PV export and the 126-sample one are not usable.
  CHECK(table["stiction"]["not-enough-data"] == 1);
  CHECK(table["no-stiction"]["not-enough-data"] == 1);
}

TEST_CASE("a simulated sticky loop is stiction through loop_verdict, with He's fs") {
  const LoopData sticky = run_scenario(scenario_by_name("paper-ex1"), 1, 0);
  const LoopVerdict a = loop_verdict(sticky);
  INFO(a.reason);
  CHECK(a.verdict == "stiction");
  CHECK(a.figures.fs == doctest::Approx(8.4).epsilon(0.25));
}

// Open (see the issue note): on the whole record the Preisach fit gains about 50 points over
// linear on `linear-clean` (a load the linear model does not carry), so loop_verdict calls it
// stiction; verdict(Diagnosis), which the sweep uses, gives no-valve-problem there
// (test_diagnosis.cpp, test/sweep). No test here until loop_verdict is fixed.

TEST_CASE("unusable records give not-enough-data with the reason") {
  std::vector<double> u(600), y(600, 1.0);
  for (std::size_t t = 0; t < u.size(); ++t) u[t] = 50 + (t / 50 % 2 ? 5.0 : -5.0);
  CHECK(loop_verdict(u, y, 1.0).verdict == "not-enough-data");  // PV constant
  for (std::size_t t = 0; t < y.size(); ++t) y[t] = 0.01 * static_cast<double>(t % 7);
  const LoopVerdict few = loop_verdict(std::vector<double>(u.begin(), u.begin() + 100),
                                       std::vector<double>(y.begin(), y.begin() + 100), 1.0);
  CHECK(few.verdict == "not-enough-data");
  CHECK(few.reason.find("100 samples") != std::string::npos);
  std::vector<double> sat(600, 100.0);
  sat[10] = 99.0;
  CHECK(loop_verdict(sat, y, 1.0).verdict == "not-enough-data");  // saturated
  std::vector<double> ramp(600);
  for (std::size_t t = 0; t < ramp.size(); ++t) ramp[t] = 20 + 0.05 * static_cast<double>(t);
  const LoopVerdict r = loop_verdict(ramp, y, 1.0);  // one way only: no reversal
  CHECK(r.verdict == "not-enough-data");
  CHECK(r.reason.find("not identifiable") != std::string::npos);
}

// FIC20102 (13 Nov): after a set-point step at the start the valve sticks while OP ramps 2 % down
// and back up, then slips once, late in the record. The stiction trial learns from the first 70 %
// a band wider than the excursion at which the valve later slips, misses that slip and loses on
// the held-out tail; on the whole record it explains a third of what linear leaves, more than a
// load curve or any memoryless effect (whole_record_test.hpp). FIC10201, a clean loop with
// set-point steps, is where a memory model gains the most among the clean loops: under the bar.
TEST_CASE("a valve that slips once in the held-out tail is confirmed on the whole record") {
  const fs::path dir = fs::path(VALVEDIAG_DATA_DIR) / "plant-loops";
  std::string note;
  const LoopData sticky =
      read_plant(dir / "stiction" / "stic_2411FIC20102_1113_0005_Stick1=0.69853.txt", &note);
  const Diagnosis d = diagnose_auto(sticky.op, sticky.pv, sticky.sample_period(), ModelSpec{});
  INFO(d.conclusion);
  CHECK_FALSE(d.last().fit.spec.has("stiction"));  // the held-out trial fits do not confirm it
  for (const auto& f : d.steps.front().findings)
    if (f.effect == "stiction") CHECK(f.validation_gain_percent < 0);
  CHECK(d.whole_record.confirmed);
  CHECK(d.whole_record.relative_gain >= 0.3);
  CHECK(verdict(d) == "stiction");
  CHECK(d.conclusion.find("On the whole record `stiction") != std::string::npos);
  // Without the test the verdict rests on the held-out fits alone.
  DiagnoseOptions off;
  off.whole_record = false;
  const Diagnosis d0 =
      diagnose_auto(sticky.op, sticky.pv, sticky.sample_period(), ModelSpec{}, off);
  CHECK_FALSE(d0.whole_record.tested);
  CHECK(verdict(d0) == "no-valve-problem");

  const LoopData clean =
      read_plant(dir / "no-stiction" / "stic_2111FIC10201_1110_0002_Stick1=0.2548.txt", &note);
  const Diagnosis c = diagnose_auto(clean.op, clean.pv, clean.sample_period(), ModelSpec{});
  INFO(c.whole_record.summary);
  CHECK(c.whole_record.tested);
  CHECK_FALSE(c.whole_record.confirmed);
  CHECK(c.whole_record.relative_gain < 0.3);
  CHECK(verdict(c) == "no-valve-problem");
}
