// The quiet lead-in rule (quiet_lead_in.hpp) on constructed OP series, and what it changes for a
// sticky valve whose loop rests for most of the record before two set-point steps.
#include <doctest/doctest.h>

#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include "../common/sanitized.hpp"
#include "valvediag/sim/scenarios.hpp"
#include "valvediag/sweep/loop_assessment.hpp"
#include "valvediag/sweep/loop_health.hpp"
#include "valvediag/sweep/quiet_lead_in.hpp"

using namespace valvediag;

namespace {

// OP at 50 with a small deterministic ripple until `move`, then a ramp down by 6 and back.
std::vector<double> op_moving_at(std::size_t n, std::size_t move) {
  std::vector<double> u(n);
  for (std::size_t k = 0; k < n; ++k) {
    const double ripple = 0.1 * std::sin(0.7 * static_cast<double>(k));
    const double s = k < move ? 0.0 : static_cast<double>(k - move) / static_cast<double>(n - move);
    u[k] = 50.0 + ripple - 6.0 * std::sin(M_PI * s);
  }
  return u;
}

}  // namespace

TEST_CASE(
    "quiet lead-in: a record at rest for most of its length is cut a little before OP moves") {
  const std::vector<double> u = op_moving_at(3000, 2400);
  const QuietLeadIn q = quiet_lead_in(u);
  REQUIRE(q.cut());
  // OP leaves 50 by a quarter of its 6.2 span once sin(pi s) > 0.25: s > 0.08, 49 samples in.
  CHECK(q.departure >= 2440);
  CHECK(q.departure <= 2460);
  CHECK(q.begin == q.departure - (3000 - q.departure) / 4);

  // A lead-in of half the record or less is kept: the first part still shows the valve.
  CHECK(!quiet_lead_in(op_moving_at(3000, 1200)).cut());
  CHECK(quiet_lead_in(op_moving_at(3000, 1200)).departure == doctest::Approx(1344).epsilon(0.01));
  // Too short to cut, a constant OP, and a record that moves from the start.
  CHECK(!quiet_lead_in(op_moving_at(390, 330)).cut());
  CHECK(!quiet_lead_in(std::vector<double>(3000, 42.0)).cut());
  CHECK(quiet_lead_in(std::vector<double>(3000, 42.0)).departure == 3000);
  CHECK(!quiet_lead_in(op_moving_at(3000, 0)).cut());

  // The analysed part never gets shorter than min_samples.
  const QuietLeadIn late = quiet_lead_in(op_moving_at(1000, 960));
  REQUIRE(late.cut());
  CHECK(late.begin == 800);
  QuietLeadInOptions o;
  o.min_samples = 100;
  CHECK(quiet_lead_in(op_moving_at(1000, 960), o).begin == 900);
  const QuietLeadIn mid = quiet_lead_in(op_moving_at(1000, 700), o);
  CHECK(mid.begin == mid.departure - (1000 - mid.departure) / 4);
}

TEST_CASE("quiet lead-in: drop_lead_in keeps every series aligned and says where it starts") {
  LoopData d;
  for (int k = 0; k < 10; ++k) {
    d.t.push_back(100.0 + 10.0 * k);
    d.op.push_back(k);
    d.pv.push_back(2.0 * k);
  }
  d.mv = d.op;
  d.source = "x.csv";
  const LoopData c = drop_lead_in(d, 4);
  CHECK(c.size() == 6);
  CHECK(c.t.front() == 140.0);  // time stamps keep their values
  CHECK(c.op.front() == 4.0);
  CHECK(c.pv.front() == 8.0);
  CHECK(c.mv.size() == 6);
  CHECK(c.sp.empty());  // absent series stay absent
  CHECK(c.source == "x.csv");

  QuietLeadIn q;
  q.begin = 4;
  q.departure = 6;
  CHECK(describe_lead_in(q, d.t, 100.0) ==
        "the analysis starts at t = 40 s (sample 5 of 10): before t = 60 s OP holds within a "
        "quarter of its span of where it started, which shows nothing of the valve");
  // On the data's own axis by default.
  CHECK(describe_lead_in(q, d.t).find("starts at t = 140 s") != std::string::npos);
  CHECK(describe_lead_in(QuietLeadIn{}, d.t).empty());
}

// A lead-in that holds OP within a quarter of its span but steps it back and forth: the
// reversals that make the record usable are all there. Cut, the part after it would fail the
// usability checks (one reversal), so lead_in_left_out() keeps the whole record; with the same
// lead-in and reversals after the departure too, it cuts as quiet_lead_in() does.
TEST_CASE("quiet lead-in: not left out when only the lead-in makes the record usable") {
  auto record = [](bool moves_after) {
    LoopData d;
    double y = 50.0;
    for (int k = 0; k < 1000; ++k) {
      double u = 0;
      if (k < 700)
        u = (k / 50) % 2 == 0 ? 52.0 : 48.0;  // +-2 steps: 13 reversals, all in the lead-in
      else if (k < 750)
        u = 48.0 + 22.0 * (k - 700) / 50.0;  // then up to 70
      else
        u = moves_after && (k / 40) % 2 == 1 ? 64.0 : 70.0;
      u += 0.02 * std::sin(1.3 * k);
      y += (u - y) / 10.0;  // first-order process, tau 10 samples
      d.t.push_back(k);
      d.op.push_back(u);
      d.pv.push_back(y + 0.05 * std::sin(2.1 * k));
    }
    return d;
  };
  const LoopData still = record(false);
  const QuietLeadIn q = quiet_lead_in(still.op);
  REQUIRE(q.cut());  // OP stays within 5.5 of 52 until sample 700 of 1000
  const LoopData part = drop_lead_in(still, q.begin);
  CAPTURE(q.begin);
  CHECK(unusable_reason(still, loop_health(still)).empty());
  CHECK(unusable_reason(part, loop_health(part)).find("OP reverses") == 0);
  CHECK(!lead_in_left_out(still, AssessOptions{}, true).cut());

  const LoopData moving = record(true);
  const QuietLeadIn m = lead_in_left_out(moving, AssessOptions{}, true);
  CHECK(m.cut());
  CHECK(m.begin == quiet_lead_in(moving.op).begin);
  AssessOptions keep;
  keep.keep_lead_in = true;
  CHECK(!lead_in_left_out(moving, keep, true).cut());
}

namespace {

// A flow loop with He's stiction (fs 3 %, fd 1 %) resting at its set point for 2400 s, then a
// set-point step down and one back up: as FIC20102 of 26 Dec 2024 in shared/data/plant-loops.
// The controller barely moves OP on the PV noise, so the first 80 % shows nothing of the valve.
Scenario resting_loop(bool sticky) {
  std::string toml =
      "name = \"quiet-lead-in\"\n"
      "sample_period = 1\n"
      "samples = 3000\n"
      "[controller]\nkc = 0.4\nti = 40\nop0 = 50\n"
      "[process]\ntype = \"first-order\"\ngain = 1.0\ntau = 10\ndead_time = 2\npv0 = 50\n"
      "[noise]\nmeasurement_std = 0.3\n"
      "[[setpoint]]\ntime = 2400\nvalue = 46\n"
      "[[setpoint]]\ntime = 2700\nvalue = 50\n";
  if (sticky) toml += "[[valve]]\neffect = \"stiction\"\nmodel = \"he\"\nfs = 3\nfd = 1\n";
  return parse_scenario_toml(toml, "quiet-lead-in");
}

constexpr std::uint64_t kSeeds = 3;

}  // namespace

TEST_CASE("assess_loop: a sticky valve after a quiet lead-in is judged on the part that moves" *
          valvediag::test::release_only()) {
  AssessOptions keep;
  keep.keep_lead_in = true;
  for (std::uint64_t seed = 1; seed <= kSeeds; ++seed) {
    CAPTURE(seed);
    const LoopData sticky = run_scenario(resting_loop(true), seed, 0);
    const LoopAssessment s = assess_loop(sticky, "FIC201");
    INFO(s.reason);
    CHECK(s.verdict == "stiction");
    CHECK(s.analysed_from_s == doctest::Approx(2250).epsilon(0.01));
    CHECK(s.reason.find("The analysis starts at t = 22") == 0);
    CHECK(s.health.samples == 3000);  // the loop-health figures cover the whole record
    // He's fs is 3 % of the 0-100 % travel: the band found is within 1 point of it.
    CHECK(std::abs(s.stiction_percent - 3.0) < 1.0);

    // The whole record: the 40 minutes of noise outweigh the slips, and the valve goes unseen.
    const LoopAssessment w = assess_loop(sticky, "FIC201", keep);
    INFO(w.reason);
    CHECK(w.analysed_from_s == 0.0);
    CHECK(w.verdict == "no-valve-problem");

    // The same loop with a linear valve, cut the same way, is not called sticky.
    const LoopAssessment c = assess_loop(run_scenario(resting_loop(false), seed, 0), "FIC202");
    INFO(c.reason);
    CHECK(c.analysed_from_s > 2000);
    CHECK(c.verdict == "no-valve-problem");
  }
}
