// The whole-record test for a valve with memory (whole_record_test.hpp): simulated sticky valves
// are confirmed; a compensated load, a static valve curve and a linear loop are not, each for
// its own reason; on real plant loops, a valve that slips once is confirmed and a clean loop
// with set-point steps is not.
#include <doctest/doctest.h>

#include <cstdio>
#include <filesystem>
#include <string>

#include "../common/plant_csv.hpp"
#include "../common/sanitized.hpp"
#include "valvediag/diagnose/diagnosis.hpp"
#include "valvediag/diagnose/verdict.hpp"
#include "valvediag/diagnose/whole_record_test.hpp"
#include "valvediag/io/csv_reader.hpp"
#include "valvediag/sim/scenarios.hpp"

namespace fs = std::filesystem;
using namespace valvediag;

namespace {

LoopData read_plant(const fs::path& p) {
  return read_loop_csv(p.string(), test::plant_csv_options());
}

WholeRecordTest test_on(const char* scenario, unsigned seed) {
  const LoopData d = run_scenario(scenario_by_name(scenario), seed, 3000);
  const WholeRecordTest w =
      whole_record_test(d.op, d.pv, d.sample_period(), parse_model_spec("linear"), {});
  std::printf("%-16s seed %u: %s\n", scenario, seed, w.summary.c_str());
  return w;
}

}  // namespace

TEST_CASE("a sticky valve is confirmed on the whole record, ahead of a load and static curves") {
#ifdef VALVEDIAG_SANITIZED
  const char* const cases[] = {"paper-ex1"};
#else
  const char* const cases[] = {"paper-ex1", "kano", "stenman"};
#endif
  for (const char* s : cases) {
    CAPTURE(s);
    const WholeRecordTest w = test_on(s, 1);
    CHECK(w.tested);
    CHECK(w.confirmed);
    CHECK(w.memory_model.rfind("stiction", 0) == 0);
    CHECK(w.relative_gain >= 0.3);
    CHECK(w.load_bic_margin > 0);
    CHECK(w.memory_fitness > w.rival_fitness);
    CHECK(w.rival_bic_margin > 0);  // ahead of every memoryless effect with parameters counted
    CHECK(w.preferred.empty());
    CHECK(w.memory_fitness > w.start_fitness);
    REQUIRE(!w.memory_effects.empty());
    CHECK(w.memory_effects.front().name == "stiction");
  }
}

TEST_CASE("a compensated load step imitates a stuck valve, and the charged load explains it") {
  // linear-clean: a linear valve, filtered load noise and a 5 % load step. The memory model
  // explains half of what linear leaves (OP moved, PV stayed), so only the load decides.
#ifdef VALVEDIAG_SANITIZED
  const unsigned seeds[] = {1};
#else
  const unsigned seeds[] = {1, 2, 3};
#endif
  for (unsigned seed : seeds) {
    CAPTURE(seed);
    const WholeRecordTest w = test_on("linear-clean", seed);
    CHECK(w.tested);
    CHECK_FALSE(w.confirmed);
    CHECK(w.relative_gain >= 0.3);
    CHECK(w.load_bic_margin < 0);
    CHECK(w.load_fitness > w.memory_fitness);
    CHECK(w.preferred == "disturbance");
    CHECK(w.summary.find("slow load fits it better") != std::string::npos);
  }
}

TEST_CASE("static curves and linear loops are not confirmed" * valvediag::test::release_only()) {
  const char* const cases[] = {"paper-ex1-linear", "characteristic", "saturation", "second-order",
                               "third-order"};
  for (const char* s : cases)
    for (unsigned seed : {1u, 2u}) {
      CAPTURE(s);
      CAPTURE(seed);
      const WholeRecordTest w = test_on(s, seed);
      CHECK(w.tested);
      CHECK_FALSE(w.confirmed);
    }
  // A start model with memory is not tested; an unknown effect is refused by the spec parser.
  const LoopData d = run_scenario(scenario_by_name("paper-ex1"), 1, 400);
  CHECK_FALSE(
      whole_record_test(d.op, d.pv, d.sample_period(), parse_model_spec("stiction"), {}).tested);
}

// FIC20102 (13 Nov): after a set-point step at the start the valve sticks while OP ramps 2 % down
// and back up, then slips once, late in the record. The stiction trial learns from the first 70 %
// a band wider than the excursion at which the valve later slips, misses that slip and loses on
// the held-out tail; on the whole record it explains a third of what linear leaves, more than a
// load curve or any memoryless effect (whole_record_test.hpp). FIC10201, a clean loop with
// set-point steps, is where a memory model gains the most among the clean loops: under the bar.
TEST_CASE("a valve that slips once in the held-out tail is confirmed on the whole record" *
          valvediag::test::release_only()) {
  const fs::path dir = fs::path(VALVEDIAG_DATA_DIR) / "plant-loops";
  const LoopData sticky =
      read_plant(dir / "stiction" / "stic_2411FIC20102_1113_0005_Stick1=0.69853.txt");
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
      read_plant(dir / "no-stiction" / "stic_2111FIC10201_1110_0002_Stick1=0.2548.txt");
  const Diagnosis c = diagnose_auto(clean.op, clean.pv, clean.sample_period(), ModelSpec{});
  INFO(c.whole_record.summary);
  CHECK(c.whole_record.tested);
  CHECK_FALSE(c.whole_record.confirmed);
  CHECK(c.whole_record.relative_gain < 0.3);
  CHECK(verdict(c) == "no-valve-problem");
}
