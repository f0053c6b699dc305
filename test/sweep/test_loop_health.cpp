// Loop-health figures on signals whose answer is known: a sine's period, a triangle's reversals
// and travel, time pinned at a limit; and the reasons a record cannot carry a model.
#include <doctest/doctest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <random>

#include "../common/sanitized.hpp"
#include "valvediag/io/mat_reader.hpp"
#include "valvediag/sweep/loop_health.hpp"

using namespace valvediag;

namespace {

LoopData make(std::size_t n, double Ts) {
  LoopData d;
  for (std::size_t k = 0; k < n; ++k) d.t.push_back(static_cast<double>(k) * Ts);
  d.op.assign(n, 50.0);
  d.pv.assign(n, 0.0);
  d.sp.assign(n, 0.0);
  return d;
}

double triangle(double t, double period, double lo, double hi) {
  const double p = std::fmod(t, period) / period;
  return lo + (hi - lo) * (p < 0.5 ? 2 * p : 2 - 2 * p);
}

}  // namespace

TEST_CASE("an oscillating control error: period found, regular") {
  for (double period : {20.0, 60.0, 150.0}) {
    CAPTURE(period);
    std::mt19937_64 rng(7);
    std::normal_distribution<double> noise(0.0, 0.2);
    LoopData d = make(4000, 1.0);
    for (std::size_t k = 0; k < d.size(); ++k) {
      d.pv[k] = std::sin(2 * M_PI * d.t[k] / period) + noise(rng);
      d.op[k] = 50 + 5 * std::cos(2 * M_PI * d.t[k] / period);
    }
    const LoopHealth h = loop_health(d);
    CHECK(h.oscillating);
    CHECK(h.period_s == doctest::Approx(period).epsilon(0.03));
    CHECK(h.regularity > 1.0);
    CHECK(h.amplitude == doctest::Approx(1.0).epsilon(0.1));  // sqrt(1 + 2 * 0.04) ~ 1.04
    CHECK(h.signal == "sp-pv");
  }
}

TEST_CASE("white noise and a random walk are not called oscillating") {
  int called = 0;
  for (std::uint64_t seed = 1; seed <= 20; ++seed) {
    std::mt19937_64 rng(seed);
    std::normal_distribution<double> noise(0.0, 1.0);
    LoopData d = make(3000, 1.0);
    double walk = 0;
    for (std::size_t k = 0; k < d.size(); ++k) {
      walk += 0.1 * noise(rng);
      d.pv[k] = (seed % 2 ? noise(rng) : walk);
      d.op[k] = 50 + noise(rng);
    }
    called += loop_health(d).oscillating ? 1 : 0;
  }
  CHECK(called <= 1);  // regularity > 1 by chance is rare, not impossible
}

TEST_CASE("a triangle OP: reversals and travel per hour, noise does not add reversals") {
  std::mt19937_64 rng(3);
  std::normal_distribution<double> noise(0.0, 0.05);
  LoopData d = make(3600, 1.0);  // one hour
  for (std::size_t k = 0; k < d.size(); ++k) d.op[k] = triangle(d.t[k], 100.0, 40, 60) + noise(rng);
  for (std::size_t k = 0; k < d.size(); ++k) d.pv[k] = d.op[k];
  const LoopHealth h = loop_health(d);
  CHECK(h.op_reversals_per_hour == doctest::Approx(72).epsilon(0.03));  // two per 100 s period
  CHECK(h.op_travel_percent_per_hour == doctest::Approx(72 * 20).epsilon(0.03));
  CHECK(h.op_noise == doctest::Approx(0.05).epsilon(0.3));
  CHECK(h.time_at_limits_percent == 0.0);
  CHECK(h.op_span_percent == doctest::Approx(20).epsilon(0.05));
}

TEST_CASE("time at the OP limits counts samples within 0.5 % of either end of the range") {
  LoopData d = make(1000, 1.0);
  for (std::size_t k = 0; k < d.size(); ++k) {
    d.op[k] = k < 300 ? 100.0 : (k < 400 ? -0.2 : 50 + (k % 7));
    d.pv[k] = static_cast<double>(k % 13);
  }
  CHECK(loop_health(d).time_at_limits_percent == doctest::Approx(40.0));
  // A valve with a 20..80 % span: OP 100 and -0.2 are beyond it, also at a limit.
  CHECK(loop_health(d, OpRange{20, 80}).time_at_limits_percent == doctest::Approx(40.0));
}

TEST_CASE("unusable records are named with what is wrong") {
  std::mt19937_64 rng(5);
  std::normal_distribution<double> noise(0.0, 0.1);
  LoopData good = make(1200, 1.0);
  for (std::size_t k = 0; k < good.size(); ++k) {
    good.op[k] = triangle(good.t[k], 120.0, 30, 70) + noise(rng);
    good.pv[k] = good.op[k] + noise(rng);
  }
  CHECK(unusable_reason(good, loop_health(good)) == "");

  // One OP cell of 9e11, below the readers' 1e12 bound: named, not "does not excite the valve".
  LoopData spike = good;
  spike.op[300] = 9e11;
  const std::string sp = unusable_reason(spike, loop_health(spike));
  CHECK(sp.find("OP sample 301 (t = 300 s) is 9e+11, a million times its usual size") == 0);
  CHECK(sp.find("remove that row or fill it in") != std::string::npos);
  LoopData pv_spike = good;
  pv_spike.pv[7] = -5e8;  // 1e6 x its usual size, about 50
  CHECK(unusable_reason(pv_spike, loop_health(pv_spike)).find("PV sample 8 (t = 7 s) is -5e+08") ==
        0);
  // A valve resting shut for most of the record, then opening: no spike.
  LoopData rests = good;
  for (std::size_t k = 0; k < 1100; ++k) rests.op[k] = 0.0;
  CHECK(unusable_reason(rests, loop_health(rests)).find("sample") == std::string::npos);

  LoopData shortd = good;
  shortd.t.resize(150);
  shortd.op.resize(150);
  shortd.pv.resize(150);
  shortd.sp.resize(150);
  CHECK(unusable_reason(shortd, loop_health(shortd)).find("only 150 samples") == 0);

  LoopData idle = good;
  for (auto& u : idle.op) u = 42.0 + 0.01 * noise(rng);
  CHECK(unusable_reason(idle, loop_health(idle)).find("OP does not move") == 0);

  LoopData flat = good;
  for (auto& y : flat.pv) y = 3.0;
  CHECK(unusable_reason(flat, loop_health(flat)).find("PV does not change") == 0);

  LoopData ramp = good;  // one move up: no reversal
  for (std::size_t k = 0; k < ramp.size(); ++k) ramp.op[k] = 20 + 0.03 * static_cast<double>(k);
  CHECK(unusable_reason(ramp, loop_health(ramp)).find("OP reverses 0 times") == 0);
  // Up and down: one reversal, half a loop of the hysteresis. Up, down and up again closes it.
  LoopData tent = good, zigzag = good;
  const double n = static_cast<double>(good.size());
  for (std::size_t k = 0; k < good.size(); ++k) {
    const double x = static_cast<double>(k) / n;
    tent.op[k] = 20 + 40 * (1 - std::abs(2 * x - 1));
    zigzag.op[k] = 20 + 40 * std::abs(std::fmod(3 * x, 2.0) - 1);
  }
  CHECK(unusable_reason(tent, loop_health(tent))
            .find("OP reverses 1 times in the window; at least 2 "
                  "(up, down and up again)") == 0);
  CHECK(std::round(loop_health(zigzag).op_reversals_per_hour * loop_health(zigzag).duration_s /
                   3600.0) == 2);
  CHECK(unusable_reason(zigzag, loop_health(zigzag)).find("OP reverses") == std::string::npos);

  LoopData op_only = good;  // a .mat loop of OP alone (the stiction database's benchmark)
  op_only.pv.clear();
  op_only.sp.clear();
  CHECK(unusable_reason(op_only, loop_health(op_only)).find("no PV in the record") == 0);

  LoopData pinned = good;
  for (std::size_t k = 0; k < pinned.size(); ++k)
    pinned.op[k] = k % 100 < 2 ? 99.0 + (k % 2) : 100.0;
  CHECK(unusable_reason(pinned, loop_health(pinned)).find("OP sits at its limits") == 0);
}

TEST_CASE("an OP-only record: OP's own oscillation and figures, no PV needed") {
  LoopData d = make(2000, 1.0);
  d.pv.clear();
  d.sp.clear();
  for (std::size_t k = 0; k < d.size(); ++k)
    d.op[k] = 50 + 8 * std::sin(2 * M_PI * d.t[k] / 80.0);  // an 80 s cycle passed on to OP
  const LoopHealth h = loop_health(d);
  CHECK(h.signal == "op");
  CHECK(h.oscillating);
  CHECK(h.period_s == doctest::Approx(80.0).epsilon(0.05));
  CHECK(h.amplitude == doctest::Approx(8.0).epsilon(0.02));
  // 25 cycles, two reversals each; 4 x 8 % of travel per cycle.
  CHECK(h.op_reversals_per_hour * h.duration_s / 3600.0 == doctest::Approx(49).epsilon(0.05));
  CHECK(h.op_travel_percent_per_hour == doctest::Approx(32.0 * 3600.0 / 80.0).epsilon(0.05));
}

// The OP-only figures on real loops: the stiction database benchmark (shared/data/benchmark.mat,
// 93 industrial loops of OP alone) carries each loop's `oscillation` label from its curators.
// The detector (Thornhill's regularity of the ACF zero crossings, on OP about its mean) against
// those labels; the table is printed, the floor holds what was measured.
TEST_CASE("OP oscillation against the stiction database's oscillation labels" *
          valvediag::test::accuracy()) {
  const std::string path = std::string(VALVEDIAG_DATA_DIR) + "/benchmark.mat";
  REQUIRE(std::filesystem::exists(path));
  const MatFileInfo info = list_mat_loops(path);
  int table[2][2] = {{0, 0}, {0, 0}};  // [label][detected]
  int labelled = 0;
  MatOptions o;
  o.require_pv = false;
  for (const auto& l : info.loops) {
    double label = -1;
    for (const auto& [name, value] : l.scalars)
      if (name == "oscillation") label = value;
    if (label != 0 && label != 1) continue;
    const LoopData d = read_mat_loop(path, l.path, o);
    const LoopHealth h = loop_health(d);
    CHECK(h.signal == "op");
    ++table[label == 1][h.oscillating];
    ++labelled;
    if (label == 1 && h.oscillating) CHECK(h.period_s > 2 * d.sample_period());
  }
  std::printf(
      "benchmark.mat, OP oscillation vs label (%d loops)\n"
      "  label \\ detected   oscillating  not\n"
      "  oscillating        %11d  %3d\n"
      "  not                %11d  %3d\n",
      labelled, table[1][1], table[1][0], table[0][1], table[0][0]);
  CHECK(labelled == 92);  // chemicals.loop16 carries a `Type` field instead of the label
  // Measured: 35 of 66 labelled oscillating found, none of the 26 others called oscillating.
  // Thornhill's regularity test is strict by design (an irregular cycle is not called one).
  CHECK(table[0][1] <= 1);
  CHECK(table[1][1] >= 33);
}
