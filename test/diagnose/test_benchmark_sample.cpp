// A fixed sample of the randomized benchmark (scripts/accuracy.sh runs the full one): the first
// development seeds, one case of each category per 12 seeds. The floors are the sample's measured
// figures less one case, so a change that loses more than one case here fails; the
// generator's properties (fair cases, disjoint streams, reproducible draws) are checked exactly.
#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <set>

#include "valvediag/core/parallel_for.hpp"
#include "valvediag/diagnose/diagnosis_benchmark.hpp"
#include "valvediag/model/model_spec.hpp"

using namespace valvediag;

namespace {
// Measured on this sample (22 hidden effects, 2 controls): 17 named first, 16 gaining 2 points
// or more, 1 control with a supported finding. A floor one case below each.
constexpr int kFirstFloor = 16;
constexpr int kGainFloor = 15;
constexpr int kAlarmCeiling = 1;
}  // namespace

TEST_CASE("random loops: every category draws a fair case, reproducibly, from its seed") {
  for (std::uint64_t seed = 0; seed < 12; ++seed) {
    const std::string cat = benchmark_categories(seed, 1).front();
    const RandomLoop a = draw_random_loop(seed, cat);
    const RandomLoop b = draw_random_loop(seed, cat);
    INFO(a.scenario.description);
    CHECK(a.scenario.description == b.scenario.description);
    CHECK(a.noise_seed == b.noise_seed);
    const LoopData da = simulate_random_loop(a), db = simulate_random_loop(b);
    REQUIRE(da.size() == a.samples);
    CHECK(da.pv == db.pv);
    // The hidden effects act in both parts (fair_case on the very run the benchmark diagnoses).
    const ScenarioRun run = run_scenario_traced(a.scenario, a.noise_seed, a.samples);
    CHECK(fair_case(a, run).empty());
    CHECK(run.data.pv == da.pv);
    if (cat == "none") CHECK(a.hidden.empty());
    if (cat != "none" && cat != "pair") CHECK(a.hidden == std::vector<std::string>{cat});
    if (cat == "pair") CHECK(a.hidden.size() == 2);
    CHECK(a.truth.empty() == (cat == "none"));
  }
  // Another seed draws another loop; the two ranges of scripts/accuracy.sh share no seed.
  CHECK(draw_random_loop(1, "deadband").scenario.description !=
        draw_random_loop(13, "deadband").scenario.description);
  CHECK_THROWS_AS(draw_random_loop(1, "no-such-effect"), std::invalid_argument);
}

// The start model is the true model less the hidden effects, a friction's variant included: a
// lagged Kano valve starts from Kano's stiction, not He's, which cannot fit it (development seed
// 461: He's fit to the truly lagged OP 92.2 % of the estimation part, Kano's 95.5 %, as the true
// valve position).
TEST_CASE("random loops: the start model keeps the friction's variant") {
  const RandomLoop kano = draw_random_loop(461, "actuator-lag");
  CHECK(kano.start_model == "stiction:kano");
  CHECK(kano.true_model == "actuator-lag+stiction:kano");
  CHECK(draw_random_loop(197, "actuator-lag").start_model == "stiction:stenman");
  CHECK(draw_random_loop(89, "actuator-lag").start_model == "stiction");
  std::set<std::string> starts;
  for (std::uint64_t seed = 0; seed < 120; ++seed)
    for (const char* cat : {"actuator-lag", "none"}) {
      const RandomLoop r = draw_random_loop(seed, cat);
      CAPTURE(r.start_model);
      CHECK_NOTHROW(parse_model_spec(r.start_model));
      CHECK_NOTHROW(parse_model_spec(r.true_model));
      starts.insert(r.start_model.substr(0, r.start_model.find('+')));
    }
  CHECK(starts.count("stiction:kano") == 1);
  CHECK(starts.count("stiction:stenman") == 1);
  CHECK(starts.count("deadband") == 1);
}

TEST_CASE("random loops: a travel limit the loop reaches but is not pinned at") {
  for (std::uint64_t seed : {3, 15, 27}) {
    const RandomLoop r = draw_random_loop(seed, "saturation");
    const LoopData d = simulate_random_loop(r);
    std::size_t clamped = 0;
    for (std::size_t t = 0; t < d.size(); ++t) clamped += std::abs(d.op[t] - d.mv[t]) > 1e-9;
    INFO(r.scenario.description);
    CHECK(clamped > d.size() / 50);
    CHECK(clamped < d.size() * 7 / 10);
  }
}

TEST_CASE("benchmark sample: hidden effects named first, gains, and quiet controls") {
#ifdef VALVEDIAG_SANITIZED
  const std::uint64_t count = 2;  // memory and UB on two cases; the figures in Release
#else
  const std::uint64_t count = 24;
#endif
  const auto cats = benchmark_categories(0, count);
  std::vector<BenchmarkOutcome> out(count);
  DiagnoseOptions opt;
  opt.fit.threads = 1;
  parallel_for(count, worker_count(0, count), [&](unsigned, std::size_t i) {
    out[i] = run_benchmark_case(draw_random_loop(i, cats[i]), opt);
  });
  std::printf("%s", format_benchmark(out, "benchmark sample (development seeds 0..23)").c_str());
  int first = 0, gains = 0, hidden = 0, alarms = 0;
  for (const auto& o : out) {
    INFO(o.loop.scenario.description);
    CHECK(o.error.empty());
    if (o.loop.hidden.empty()) {
      alarms += o.false_alarm;
    } else {
      ++hidden;
      first += o.named_first;
      gains += o.gains;
      // The true model's gain is measured except against a hidden load (the true model would
      // carry it) or a k-step judge (an integrating start model).
      const bool load = std::count(o.loop.hidden.begin(), o.loop.hidden.end(), "disturbance") > 0;
      CHECK(std::isfinite(o.true_model_gain) == (!load && o.judge.horizon == 0));
      // The valve search is measured against the true valve position for one hidden valve
      // effect under the simulated-output judge.
      CHECK(std::isfinite(o.valve_search_shortfall) ==
            (o.loop.hidden.size() == 1 && is_valve_effect(o.loop.hidden.front()) &&
             o.judge.horizon == 0));
    }
  }
#ifndef VALVEDIAG_SANITIZED
  // Seed 15: a travel limit the linear start model cannot follow; the true model, driven by the
  // recorded valve position, explains 41.8 points more of PV on both parts.
  CHECK(out[15].loop.category == "saturation");
  CHECK(out[15].true_model_gain > 20.0);
  // Where the search finds its valve (a characteristic, stiction, a deadband, a travel limit, an
  // actuator lag behind a deadband: seeds 4, 12, 13, 15, 17), the true valve position fits the
  // estimation part no better (measured: -0.08 to 0.00 points).
  for (const std::size_t i : {4, 12, 13, 15, 17}) {
    INFO("seed " << i << ": " << out[i].loop.scenario.description);
    CHECK(std::abs(out[i].valve_search_shortfall) < 0.5);
  }
  CHECK(hidden == 22);
  CHECK(first >= kFirstFloor);
  CHECK(gains >= kGainFloor);
  CHECK(alarms <= kAlarmCeiling);
#endif
}

TEST_CASE(
    "nested friction trials: the wider stiction ranks first only when the data refute the "
    "deadband") {
  // Development seed 13: a deadband of 3.1 %; the stiction trial fits it as Kano's S 3.08 with a
  // small jump, 0.5 points better on the estimation part and 1.4 worse held out.
  const BenchmarkOutcome db = run_benchmark_case(draw_random_loop(13, "deadband"));
  INFO(db.loop.scenario.description);
  REQUIRE(db.ranked.size() >= 2);
  CHECK(db.ranked[0] == "deadband");
  CHECK(db.ranked[1] == "stiction");
#ifndef VALVEDIAG_SANITIZED
  // Development seed 72: Kano's stiction, S 5.55 %, J 1.87 %: the jump is in the data.
  const BenchmarkOutcome st = run_benchmark_case(draw_random_loop(72, "stiction"));
  INFO(st.loop.scenario.description);
  REQUIRE(!st.ranked.empty());
  CHECK(st.ranked[0] == "stiction");
  const auto deadband = std::find(st.ranked.begin(), st.ranked.end(), "deadband");
  CHECK(deadband != st.ranked.end());
#endif
}

TEST_CASE("a load its own BIC refutes ranks below an effect the prediction shows evidence for") {
#ifndef VALVEDIAG_SANITIZED
  // Development seed 132: He's stiction on a loop whose model fits 94.5 %. The load's spline
  // gains 3.7 points on both parts, supported, but its 17 parameters cost more than that
  // explains on the model's few effective samples; the stiction trial loses 0.2 points of
  // simulated output held out and lowers the one-step prediction's BIC by hundreds.
  const BenchmarkOutcome o = run_benchmark_case(draw_random_loop(132, "stiction"));
  INFO(o.detail);
  REQUIRE(o.findings.size() >= 2);
  const auto find = [&o](const std::string& e) {
    return std::find_if(o.findings.begin(), o.findings.end(),
                        [&e](const Finding& f) { return f.effect == e; });
  };
  const auto load = find("disturbance"), stiction = find("stiction");
  REQUIRE(load != o.findings.end());
  REQUIRE(stiction != o.findings.end());
  CHECK(load->supported);
  CHECK(load->output_bic_change > 0.0);
  CHECK(stiction->prediction_bic_change < -100.0);
  CHECK(stiction->prediction_validation_gain_percent > 0.0);
  CHECK(o.first == "stiction");
  CHECK(stiction < load);
#endif
}
