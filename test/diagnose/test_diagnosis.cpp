// Loops with one effect hidden from the starting model (`linear`), at least one for every effect
// of the vocabulary, over seeds and amplitudes, all with measurement noise and load disturbances:
// diagnose must name the hidden effect first (or second, where the two effects explain the data
// equally and diagnose says so), show intervals that overlap where the simulator exercised the
// effect, and the trial fit with it must raise validation fitness by a clear margin. Prints the
// case table, the confusion table (hidden effect vs first finding) and the mean gains.
#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <functional>
#include <map>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include "../common/sanitized.hpp"
#include "valvediag/core/autocorrelation.hpp"
#include "valvediag/diagnose/diagnosis.hpp"
#include "valvediag/diagnose/verdict.hpp"
#include "valvediag/sim/random_loop.hpp"
#include "valvediag/sim/scenarios.hpp"

using namespace valvediag;

namespace {

struct Case {
  std::string label;   // loop and amplitude
  std::string hidden;  // the effect the simulator exercised and the start model lacks
  std::uint64_t seed;
  std::function<Scenario()> scenario;
  std::string acted = "";  // the simulator's activity record to check ("" = hidden)
  // A confusion diagnose still makes on this loop, and why (printed; checked as a warning).
  std::string known = "";
  // Other effects that model the same physics, accepted first when their trial predicts
  // the held-out part better (asymmetric stiction is stiction; He's average band is its simpler
  // model, and a deadband, stiction without the jump, the simpler one still when the data do not
  // refute it: docs/diagnosis.md).
  std::vector<std::string> equivalent = {};
};

Scenario named(const char* name) {
  return scenario_by_name(name);
}

Scenario with_valve(const char* name, ValveEffect v) {
  Scenario s = scenario_by_name(name);
  s.loop.valve = {std::move(v)};
  return s;
}

std::vector<Case> cases() {
  return {
      {"paper-ex1 (He fs 8.4, fd 3.5)", "stiction", 1, [] { return named("paper-ex1"); }},
      {"paper-ex1 (He fs 8.4, fd 3.5)", "stiction", 2, [] { return named("paper-ex1"); }},
      {"kano (S 5, J 2)", "stiction", 1, [] { return named("kano"); }},
      {"kano (S 8, J 3)", "stiction", 2, [] { return with_valve("kano", KanoStiction(8, 3)); }},
      {"stenman (d 3)", "stiction", 1, [] { return named("stenman"); }},
      {"deadband (d 4)", "deadband", 1, [] { return named("deadband"); }},
      {"deadband (d 6)", "deadband", 2, [] { return with_valve("deadband", Deadband(6)); }},
      {"asymmetric stiction",
       "preisach",
       1,
       [] { return named("asymmetric-stiction"); },
       "stiction",
       "",
       {"stiction", "deadband"}},
      {"asymmetric stiction",
       "preisach",
       2,
       [] { return named("asymmetric-stiction"); },
       "stiction",
       "",
       {"stiction", "deadband"}},
      {"saturation (5-70 %)", "saturation", 1, [] { return named("saturation"); }},
      {"saturation (5-65 %)", "saturation", 2,
       [] { return with_valve("saturation", Saturation(5, 65)); }},
      {"characteristic (eq-% R 50)", "characteristic", 1, [] { return named("characteristic"); }},
      {"characteristic (eq-% R 20)", "characteristic", 2,
       [] {
         return with_valve("characteristic",
                           Characteristic(Characteristic::Kind::equal_percentage, 20));
       }},
      {"slow-actuator (tau 20 s)", "actuator-lag", 1, [] { return named("slow-actuator"); }},
      {"slow-actuator (tau 30 s)", "actuator-lag", 2,
       [] { return with_valve("slow-actuator", ActuatorLag(30, 1.0)); }},
      {"dead-time (26 s)", "delay", 1, [] { return named("dead-time"); }},
      {"dead-time (29 s)", "delay", 2,
       [] {
         Scenario s = named("dead-time");
         s.loop.process.dead_time = 29.0;
         return s;
       }},
      {"third-order (3rd lag 16 s)", "order", 1, [] { return named("third-order"); }},
      {"third-order (3rd lag 24 s)", "order", 2,
       [] {
         Scenario s = named("third-order");
         s.loop.process.tau3 = 24.0;
         return s;
       }},
      {"level (K 0.01 /s)", "integrator", 1, [] { return named("level"); }, "",
       "named first, but the level waves (a real load) hide most of the ramp in this record: the "
       "gain on estimation data stays under the 2-point threshold of a supported finding"},
      {"level (K 0.02 /s)", "integrator", 2,
       [] {
         Scenario s = named("level");
         s.loop.process.gain = 0.02;
         s.loop.controller.kc = 0.4;
         return s;
       }},
      {"load-changes", "disturbance", 1, [] { return named("load-changes"); }},
      {"load-changes (60 %)", "disturbance", 2,
       [] {
         Scenario s = named("load-changes");
         for (auto& st : s.loop.disturbances.steps) st.size *= 0.6;
         s.loop.disturbances.noises[0].std *= 0.6;
         return s;
       }},
  };
}

struct Outcome {
  Diagnosis diagnosis;
  ScenarioRun run;
};

// Diagnoses are shared between the test cases (each costs a second or so).
const Outcome& outcome(const std::string& key, const std::function<Scenario()>& make,
                       std::uint64_t seed) {
  static std::map<std::string, Outcome> cache;
  auto it = cache.find(key);
  if (it != cache.end()) return it->second;
  Outcome o;
  o.run = run_scenario_traced(make(), seed, 0);
  const LoopData& d = o.run.data;
  o.diagnosis = diagnose(d.op, d.pv, d.sample_period(), parse_model_spec("linear"));
  return cache.emplace(key, std::move(o)).first->second;
}

const Finding* find(const std::vector<Finding>& f, const std::string& effect) {
  for (const auto& x : f)
    if (x.effect == effect) return &x;
  return nullptr;
}

}  // namespace

TEST_CASE("hidden effects are named first, with a clear gain and overlapping intervals" *
          valvediag::test::accuracy()) {
  const auto all = cases();
  std::map<std::string, std::map<std::string, int>> confusion;
  std::vector<std::string> firsts;
  double sum_val = 0, sum_gain = 0;
  int hits = 0, flagged_second = 0, known = 0, equivalents = 0;
  std::printf("\n%-28s %-15s %4s %-15s %-15s %-5s %8s %8s %7s\n", "loop", "hidden effect", "seed",
              "first finding", "second", "flag", "val gain", "gain", "overlap");
  std::size_t runs = 0;
  for (std::size_t i = 0; i < all.size(); ++i, ++runs) {
    const auto& c = all[i];
    CAPTURE(c.label);
    CAPTURE(c.seed);
    const Outcome& o = outcome(c.label + "#" + std::to_string(c.seed), c.scenario, c.seed);
    const auto& f = o.diagnosis.last().findings;
    REQUIRE(f.size() >= 2);
    const Finding* hidden = find(f, c.hidden);
    REQUIRE(hidden != nullptr);
    const bool first = f[0].effect == c.hidden;
    // Second place counts only where diagnose says the first cannot be told from it.
    const bool second = f[1].effect == c.hidden && f[0].indistinguishable_from == c.hidden;
    // The equivalent effect first, when its trial predicts the held-out part better.
    const bool first_equivalent =
        std::find(c.equivalent.begin(), c.equivalent.end(), f[0].effect) != c.equivalent.end();
    const Finding* eq = first_equivalent ? &f[0] : nullptr;
    const bool equivalent = eq && eq->validation_gain_percent > hidden->validation_gain_percent;
    // The simulator's record of where the effect acted, against the intervals the finding shows.
    const EffectActivity* acted = o.run.find(c.acted.empty() ? c.hidden : c.acted);
    REQUIRE(acted != nullptr);
    bool overlap = false;
    for (const auto& iv : hidden->intervals) overlap = overlap || acted->overlaps(iv.begin, iv.end);
    std::printf("%-28s %-15s %4d %-15s %-15s %-5s %+8.2f %+8.2f %7s\n", c.label.c_str(),
                c.hidden.c_str(), static_cast<int>(c.seed), f[0].effect.c_str(),
                f[1].effect.c_str(), f[0].indistinguishable_from.empty() ? "" : "yes",
                hidden->validation_gain_percent, hidden->gain_percent, overlap ? "yes" : "no");
    if (c.known.empty()) {
      CHECK((first || second || equivalent));
      // Adding it raises fitness by a clear margin: on held-out data, and on both parts by the
      // product's own threshold for a supported finding (the equivalent effect's, when that one
      // is first).
      const Finding* named = equivalent && !first ? eq : hidden;
      CHECK(named->validation_gain_percent >= 2.0);
      CHECK(named->supported);
    } else {
      ++known;
      std::printf("  known confusion: %s\n", c.known.c_str());
      WARN((first || second));
      WARN(hidden->supported);
    }
    hits += first;
    flagged_second += second;
    equivalents += equivalent;
    confusion[c.hidden][f[0].effect] += 1;
    if (std::find(firsts.begin(), firsts.end(), f[0].effect) == firsts.end())
      firsts.push_back(f[0].effect);
    CHECK(overlap);
    sum_val += hidden->validation_gain_percent;
    sum_gain += hidden->gain_percent;
  }
  std::printf("\nconfusion (rows: hidden effect, columns: first finding)\n%-15s", "");
  for (const auto& e : firsts) std::printf(" %14s", e.c_str());
  std::printf("\n");
  for (const auto& [h, row] : confusion) {
    std::printf("%-15s", h.c_str());
    for (const auto& e : firsts) {
      const auto it = row.find(e);
      std::printf(" %14s", it == row.end() ? "." : std::to_string(it->second).c_str());
    }
    std::printf("\n");
  }
  const double n = static_cast<double>(runs);
  std::printf(
      "hidden effect first in %d of %zu loops, second behind an indistinguishable one in %d, "
      "an equivalent effect first in %d, known confusions %d; mean gain of adding it: %+.2f "
      "points validation fitness, %+.2f on both parts (the smaller of estimation and "
      "validation)\n",
      hits, all.size(), flagged_second, equivalents, known, sum_val / n, sum_gain / n);
  CHECK(known <= 1);
  CHECK(confusion.size() == 10);  // every effect is hidden at least once
}

TEST_CASE("an actuator lag alone is no valve finding: OP and PV cannot place it" *
          valvediag::test::release_only()) {
  // The same records as above (shared diagnoses): a third process lag behind an ideal valve and
  // a slow actuator before a second-order process are one linear model class.
  const std::pair<const char*, const char*> runs[] = {
      {"third-order (3rd lag 16 s)", "third-order"}, {"slow-actuator (tau 20 s)", "slow-actuator"}};
  for (const auto& [label, scenario] : runs) {
    CAPTURE(label);
    const char* name = scenario;
    const Outcome& o = outcome(
        std::string(label) + "#1", [name] { return named(name); }, 1);
    const Finding& top = o.diagnosis.last().findings.front();
    REQUIRE(top.supported);
    CHECK((top.effect == "actuator-lag" || top.effect == "order"));
    CHECK(verdict(o.diagnosis) == "no-valve-problem");
    const bool note = o.diagnosis.conclusion.find(
                          "cannot tell a slow actuator from one more "
                          "process lag") != std::string::npos;
    CHECK(note == (top.effect == "actuator-lag"));
  }
  // Beside a valve nonlinearity the lag no longer commutes with the process: that one counts.
  Diagnosis d;
  d.steps.emplace_back();
  const std::pair<const char*, const char*> models[] = {
      {"actuator-lag", "no-valve-problem"},
      {"actuator-lag+saturation", "other-nonlinearity"},
      {"actuator-lag+characteristic+order", "other-nonlinearity"},
      {"actuator-lag+deadband", "deadband"},
      {"actuator-lag+stiction:kano", "stiction"}};
  for (const auto& [model, expected] : models) {
    CAPTURE(model);
    d.steps.front().fit.spec = parse_model_spec(model);
    CHECK(verdict(d) == expected);
  }
}

TEST_CASE("paper Example 1: stiction parameters, and preisach fits about equally (Example 3)") {
  const Outcome& o = outcome(
      "paper-ex1 (He fs 8.4, fd 3.5)#1", [] { return named("paper-ex1"); }, 1);
  const Diagnosis& d = o.diagnosis;
  const auto& f = d.last().findings;
  const Finding* st = find(f, "stiction");
  const Finding* pr = find(f, "preisach");
  REQUIRE(st != nullptr);
  REQUIRE(pr != nullptr);
  double fs = 0, fd = 0;
  for (const auto& p : st->parameters) {
    if (p.name == "fs") fs = p.value;
    if (p.name == "fd") fd = p.value;
  }
  CHECK(fs == doctest::Approx(8.4).epsilon(0.2));
  CHECK(fd == doctest::Approx(3.5243).epsilon(0.2));
  CHECK(std::abs(st->gain_percent - pr->gain_percent) < 3.0);
  // `preisach` scores what it adds beyond the stiction trial it generalizes: on He's own valve,
  // too little to support it or to rank it ahead.
  CHECK_FALSE(pr->supported);
  CHECK(st - f.data() < pr - f.data());
  CHECK(verdict(d) == "stiction");
  CHECK(st->explanation.find("stiction") != std::string::npos);
}

// A trial whose band fits to nothing does not tell the user "OP must travel about 0.0 %": the
// workbench showed that for the deadband trial on paper Example 1 (1500 samples) from `stiction`.
TEST_CASE("a friction trial that fits no band says so instead of a band of 0.0 %") {
  const LoopData data = run_scenario(named("paper-ex1"), 1, 1500);
  const Diagnosis d =
      diagnose(data.op, data.pv, data.sample_period(), parse_model_spec("stiction"));
  const auto& f = d.last().findings;
  const Finding* db = find(f, "deadband");
  REQUIRE(db != nullptr);
  double band = -1.0;
  for (const auto& p : db->parameters)
    if (p.name == "d") band = p.value;
  REQUIRE(band >= 0.0);
  REQUIRE(band < 0.05);  // the case this test is about
  CHECK(db->explanation.find("fitted no play") != std::string::npos);
  for (const auto& x : f) {
    INFO(x.effect << ": " << x.explanation);
    CHECK(x.explanation.find("about 0.0 %") == std::string::npos);
  }
}

TEST_CASE("paper Example 1 over 50 minutes: `linear` has a stable fit, stiction is missing first" *
          valvediag::test::release_only()) {
  // 6000 samples of stick-slip cycles at a steady set point: least squares puts every linear
  // model's pole past the unit circle, so `linear` had no fit, no residual to analyse and no
  // baseline for the trials. The output-error fit from reflected poles gives one.
  const LoopData d = run_scenario(scenario_by_name("paper-ex1"), 3, 6000);
  const Diagnosis dg = diagnose(d.op, d.pv, d.sample_period(), parse_model_spec("linear"));
  const DiagnosisStep& s = dg.last();
  CHECK(s.fit.status != ModelFitStatus::NoStableModel);
  CHECK(s.fit.fitness_percent > 60.0);  // measured 73.6 (estimation), 73.3 (held out)
  CHECK(s.residual.rms > 0.0);
  REQUIRE(!s.findings.empty());
  CHECK(s.findings.front().effect == "stiction");
  CHECK(s.findings.front().gain_percent > 10.0);  // measured +25.1
  CHECK(verdict(dg) == "stiction");
}

TEST_CASE("a loop with no valve problem is not diagnosed with stiction" *
          valvediag::test::release_only()) {
  const std::uint64_t seeds[] = {1, 2};
  for (std::uint64_t seed : seeds) {
    CAPTURE(seed);
    const LoopData d = run_scenario(scenario_by_name("linear-clean"), seed, 0);
    const Diagnosis dg = diagnose(d.op, d.pv, d.sample_period(), parse_model_spec("linear"));
    const auto& f = dg.last().findings;
    REQUIRE(!f.empty());
    CHECK(f[0].effect != "stiction");
    CHECK(f[0].effect != "preisach");
    CHECK(verdict(dg) == "no-valve-problem");
    CHECK(dg.last().judge.horizon == 0);  // a self-regulating model: its simulated output judges
  }
}

// A level behind a valve with play (development seed 49 of the benchmark): the true model's
// simulated output drifts with any rate error (the deadband trial, its band right, scored -412
// points held out so), so an integrating model's step is judged k steps ahead from the measured
// PV, every trial alike.
TEST_CASE("an integrating model is judged k steps ahead: the true deadband gains on both parts") {
  const RandomLoop r = draw_random_loop(49, "deadband");
  REQUIRE(r.start_model == "integrator");
  const LoopData d = simulate_random_loop(r);
  // Every candidate, as `diagnose` runs: a load gains about as much as the band here (+46.7 /
  // +44.8 against +44.6 / +80.9), and which of the two a narrower contest puts first is the
  // ranking's business (a valve with memory and a load imitate each other), not the judge's.
  const Diagnosis dg = diagnose(d.op, d.pv, d.sample_period(), parse_model_spec("integrator"));
  const DiagnosisStep& s = dg.last();
  REQUIRE(s.fit.integrating);
  CHECK(s.judge.horizon > 0);
  CHECK(s.judge.horizon <= (s.fit.estimation_end - s.fit.first_sample) / 8);
  CHECK(std::isfinite(s.judge.model_fitness_percent));
  CHECK(judge_note(s).find("-step-ahead prediction") != std::string::npos);
  REQUIRE(!s.findings.empty());
  const Finding& f = s.findings.front();
  CHECK(f.effect == "deadband");
  CHECK(f.supported);
  CHECK(f.estimation_gain_percent >= 2.0);
  CHECK(f.validation_gain_percent >= 2.0);
  // The simulated-output figures stay reported beside the judge's.
  CHECK(std::isfinite(f.trial_validation_fitness_percent));
  CHECK(f.trial_validation_fitness_percent - s.fit.validation_fitness_percent !=
        doctest::Approx(f.validation_gain_percent).epsilon(0.01));
}

// The conclusion names its worst interval on the data's time axis: a record cut after a quiet
// lead-in (quiet_lead_in.hpp) starts late, and its sample 0 is not t = 0.
TEST_CASE("the conclusion's interval times count from time_origin_s") {
  const LoopData d = run_scenario(scenario_by_name("deadband"), 1, 0);
  DiagnoseOptions o;
  o.candidates = {"deadband"};  // one trial: only the conclusion is under test
  auto interval_start = [](const std::string& c) {
    const auto at = c.find("the largest unexplained interval is t ");
    REQUIRE(at != std::string::npos);  // linear leaves the backlash unexplained
    return std::stod(c.substr(at + 38));
  };
  const Diagnosis from0 = diagnose(d.op, d.pv, d.sample_period(), parse_model_spec("linear"), o);
  o.time_origin_s = 5000.0;
  const Diagnosis late = diagnose(d.op, d.pv, d.sample_period(), parse_model_spec("linear"), o);
  INFO(from0.conclusion);
  INFO(late.conclusion);
  const double t0 = interval_start(from0.conclusion);
  CHECK(t0 >= 0.0);
  CHECK(t0 < d.t.back());
  CHECK(interval_start(late.conclusion) == doctest::Approx(t0 + 5000.0));
}

TEST_CASE("--auto climbs to the hidden effect and stops" * valvediag::test::release_only()) {
  const LoopData data = run_scenario(scenario_by_name("paper-ex1"), 1, 0);
  std::vector<std::pair<double, std::string>> progress;  // one call at a time (the options say)
  DiagnoseOptions o;
  o.progress = [&progress](double f, const std::string& phase) { progress.emplace_back(f, phase); };
  const Diagnosis d =
      diagnose_auto(data.op, data.pv, data.sample_period(), parse_model_spec("linear"), o);
  REQUIRE(d.steps.size() >= 2);
  CHECK(to_string(d.steps[1].fit.spec) == "stiction");
  // The progress rises from the first step's model fit to the final tests, and counts each
  // step's trial fits.
  REQUIRE(progress.size() >= 4);
  CHECK(progress.front().first == doctest::Approx(0.0));
  CHECK(progress.front().second == "step 1 (linear): fitting linear");
  CHECK(progress.back().second == "limit-cycle and whole-record tests");
  for (std::size_t i = 1; i < progress.size(); ++i) {
    INFO(progress[i].second);
    CHECK(progress[i].first >= progress[i - 1].first);
    CHECK(progress[i].first <= 1.0);
  }
  for (std::size_t k = 0; k < d.steps.size(); ++k) {
    const std::string step = "step " + std::to_string(k + 1) + " (" +
                             to_string(d.steps[k].fit.spec) + "): trial models: ";
    const auto trials = std::count_if(progress.begin(), progress.end(), [&](const auto& p) {
      return p.second.rfind(step, 0) == 0 && p.second.find(" fitted") != std::string::npos;
    });
    INFO(step);
    CHECK(trials >= static_cast<long>(d.steps[k].findings.size()) + 1);  // 0 of N, then each
  }
  CHECK(d.steps.size() <= 3);
  CHECK(d.steps.back().fit.validation_fitness_percent > 85.0);
  CHECK(d.conclusion.find("What is left") != std::string::npos);
  // Each step improved validation fitness.
  for (std::size_t i = 1; i < d.steps.size(); ++i)
    CHECK(d.steps[i].fit.validation_fitness_percent >
          d.steps[i - 1].fit.validation_fitness_percent);
}

TEST_CASE("a load the controller compensates is not ranked behind a valve with memory" *
          valvediag::test::release_only()) {
  // A level loop (integrating process) with a drifting outflow and an inflow step: a stuck valve
  // and the load both explain OP winding while the level holds. With the load ahead on both
  // parts of the record, the two-parameter friction must not win on its parameter count
  // (measured before the fix: He's stiction ranked first on seeds 5-7 and the verdict was
  // `stiction`).
  const std::uint64_t seeds[] = {5, 6};
  for (std::uint64_t seed : seeds) {
    CAPTURE(seed);
    const LoopData d = run_scenario(scenario_by_name("integrating"), seed, 0);
    const Diagnosis dg = diagnose(d.op, d.pv, d.sample_period(), parse_model_spec("linear"));
    const auto& f = dg.last().findings;
    REQUIRE(!f.empty());
    const Finding* load = find(f, "disturbance");
    const Finding* stiction = find(f, "stiction");
    REQUIRE(load);
    REQUIRE(stiction);
    // The premise: the load gains at least as much on both parts and scores higher.
    CHECK(load->validation_gain_percent > stiction->validation_gain_percent);
    CHECK(load->score > stiction->score);
    CHECK(f[0].effect == "disturbance");
    CHECK(verdict(dg) != "stiction");
    CHECK(verdict(dg) != "deadband");
  }
}

TEST_CASE("held valve: how much of a memory trial's held-out gain its predicted slips give") {
  // Load changes with a linear valve: He's stiction with a wide band imitates the compensated
  // loads by holding the valve (no slip after the estimation part) and gains +27 held out over
  // linear, which follows OP's compensating moves. Held still, the model scores the same: the
  // slips give nothing, and the report says so.
  const LoopData d = run_scenario(scenario_by_name("load-changes"), 3, 0);
  const Diagnosis dg = diagnose(d.op, d.pv, d.sample_period(), parse_model_spec("linear"));
  const Finding* stiction = find(dg.last().findings, "stiction");
  REQUIRE(stiction);
  CHECK(stiction->validation_gain_percent > 10.0);  // the premise
  REQUIRE(std::isfinite(stiction->held_valve_validation_fitness_percent));
  CHECK(stiction->held_valve_validation_fitness_percent ==
        doctest::Approx(stiction->trial_validation_fitness_percent).epsilon(0.01));
  const std::string note = held_valve_note(*stiction);
  CHECK(note.find("the slips it predicts there give +0.0") != std::string::npos);
  // Reported, not scored: the gain that ranks the finding is unchanged.
  CHECK(stiction->gain_percent == doctest::Approx(std::min(stiction->validation_gain_percent,
                                                           stiction->estimation_gain_percent)));
  // Memoryless effects have no held valve.
  const Finding* load = find(dg.last().findings, "disturbance");
  REQUIRE(load);
  CHECK(std::isnan(load->held_valve_validation_fitness_percent));
  CHECK(held_valve_note(*load).empty());
  // A stick-slip cycle: the held-out slips are what the trial gains. (Paper Example 1, seed 1:
  // the diagnosis shared with the cases above, of the same record.)
  const Outcome& ex1 = outcome(
      "paper-ex1 (He fs 8.4, fd 3.5)#1", [] { return named("paper-ex1"); }, 1);
  const Finding* he = find(ex1.diagnosis.last().findings, "stiction");
  REQUIRE(he);
  CHECK(he->held_valve_validation_fitness_percent < he->trial_validation_fitness_percent - 50.0);
  CHECK(held_valve_note(*he).empty());
}

TEST_CASE("--auto adds a valve with memory and a load step together when neither alone fits" *
          valvediag::test::release_only()) {
  // Choudhury's stiction (S 5 %, J 2 %) with a 3 % load step at the valve, noise-free: fitted
  // without the load the friction band is biased and misses the held-out slips, and a load curve
  // alone cannot follow the slips; each loses on one part of the record.
  const LoopData d = run_scenario(scenario_by_name("choudhury"), 1, 0);
  const Diagnosis dg = diagnose_auto(d.op, d.pv, d.sample_period(), parse_model_spec("linear"));
  const auto& f0 = dg.steps.front().findings;
  const Finding* load = find(f0, "disturbance");
  const Finding* stiction = find(f0, "stiction");
  REQUIRE(load);
  REQUIRE(stiction);
  // The premise: neither alone gains the margin on both parts.
  CHECK(load->gain_percent < 2.0);
  CHECK(stiction->gain_percent < 2.0);
  REQUIRE(dg.steps.size() >= 3);
  CHECK(to_string(dg.steps[1].fit.spec) == "disturbance");
  CHECK(dg.steps[2].fit.spec.has("stiction"));
  CHECK(dg.steps[2].fit.spec.has("disturbance"));
  // Together: both parts far better than the linear model.
  CHECK(dg.steps[2].fit.fitness_percent - dg.steps[0].fit.fitness_percent > 30.0);
  CHECK(dg.steps[2].fit.validation_fitness_percent - dg.steps[0].fit.validation_fitness_percent >
        30.0);
  CHECK(dg.conclusion.find("were added together") != std::string::npos);
  CHECK(verdict(dg) == "stiction");
}

// Development seed 114 of the benchmark: a dead time of about 24 s hidden from a linear model.
// On simulated output a delay, an extra lag and a slow actuator gain alike (2-3.6 points each),
// and the lag ranked first; predicted one step ahead (prediction_error.hpp) only the dead time
// predicts PV much better than the model, and it ranks first.
TEST_CASE("between valve and process-lag effects the one-step prediction ranks: a dead time") {
  const RandomLoop r = draw_random_loop(114, "delay");
  REQUIRE(r.start_model == "linear");
  const LoopData d = simulate_random_loop(r);
  DiagnoseOptions o;
  o.candidates = {"delay", "order", "actuator-lag"};
  const Diagnosis dg = diagnose(d.op, d.pv, d.sample_period(), parse_model_spec("linear"), o);
  const auto& f = dg.last().findings;
  REQUIRE(f.size() == 3);
  CHECK(f[0].effect == "delay");
  for (const auto& x : f) {
    INFO(x.effect);
    CHECK(std::isfinite(x.prediction_bic_change));
    CHECK(std::isfinite(x.prediction_estimation_gain_percent));
    CHECK(x.gain_percent > 1.0);  // each gains on simulated output
  }
  CHECK(f[0].prediction_bic_change < f[1].prediction_bic_change - 50.0);
  CHECK(f[0].prediction_bic_change < f[2].prediction_bic_change - 50.0);
  CHECK(f[0].prediction_estimation_gain_percent > 0.0);
  CHECK(f[0].prediction_validation_gain_percent > 0.0);
}

// `integrator` judged on the one-step prediction as the restriction A(1) = 0 of the model's
// predictor (one coefficient fewer): on development seeds 44 and 56 (a level hidden from a
// linear model, which fitted a pole at 1 already, so the trial gains nothing on simulated output)
// the restriction lowers the BIC by nearly ln n and holds held out, and the finding ranks above
// the unsupported friction and extra lag the rules ranked first before; the drifting-load form
// of the predictor (B(1) = 0 besides) is refuted by far. On a control that settles (seed 10) the
// restriction is refuted. Under a wandering load (seed 45, a random walk at the valve) it holds,
// but the drifting-load form fits better: the unit root is the load's, and the load, not the
// integrator, is named.
TEST_CASE("an integrating process is named by the restriction its prediction passes" *
          valvediag::test::release_only()) {
  enum Kind { integrates, settles, wanders };
  struct Case {
    std::uint64_t seed;
    const char* category;
    Kind kind;
  };
  for (const Case& c : {Case{44, "integrator", integrates}, Case{56, "integrator", integrates},
                        Case{10, "none", settles}, Case{45, "disturbance", wanders}}) {
    CAPTURE(c.seed);
    const RandomLoop r = draw_random_loop(c.seed, c.category);
    const LoopData d = simulate_random_loop(r);
    DiagnoseOptions o;
    o.validation_fraction = r.validation_fraction;
    const Diagnosis dg =
        diagnose(d.op, d.pv, d.sample_period(), parse_model_spec(r.start_model), o);
    const auto& f = dg.last().findings;
    REQUIRE(!f.empty());
    const auto it =
        std::find_if(f.begin(), f.end(), [](const Finding& x) { return x.effect == "integrator"; });
    REQUIRE(it != f.end());
    const double ln_n = std::log(static_cast<double>(d.pv.size()));
    if (c.kind == integrates) {
      CHECK(f[0].effect == "integrator");
      CHECK(it->prediction_bic_change <= -2.0);
      CHECK(it->prediction_bic_change >= -ln_n);  // it saves one coefficient, no more
      CHECK(it->prediction_validation_deviance_change < 6.63);
      CHECK(it->prediction_drift_bic_change > 100.0);
    } else if (c.kind == settles) {
      CHECK(it->prediction_bic_change > 20.0);
      CHECK(f[0].effect != "integrator");
    } else {
      CHECK(it->prediction_bic_change <= -2.0);
      CHECK(it->prediction_drift_bic_change < 0.0);
      CHECK(f[0].effect == "disturbance");
    }
  }
}

// The ranking's invariant on the path from OP to PV: of two findings there that the one-step
// prediction shows evidence for (BIC change <= -2), the lower BIC change ranks first, except two
// valves with memory (their nested test orders them) and an actuator lag that commutes with a
// process lag (no valve nonlinearity in the model: the process lag is named). Development seeds
// where the rules alone put them the other way: 17 (actuator lag behind a deadband, ranked below
// an extra lag), 59 (a deadband and a load, the deadband below an extra lag) and 67 (an extra lag
// below a dead time).
TEST_CASE("findings on the path with prediction evidence rank by their prediction BIC" *
          valvediag::test::release_only()) {
  const std::vector<std::string> path = {"stiction",       "deadband",     "preisach", "saturation",
                                         "characteristic", "actuator-lag", "delay",    "order"};
  const auto on_path = [&path](const std::string& e) {
    return std::find(path.begin(), path.end(), e) != path.end();
  };
  const auto memory = [](const std::string& e) {
    return e == "stiction" || e == "deadband" || e == "preisach";
  };
  struct Case {
    std::uint64_t seed;
    const char* category;
    const char* first;  // the hidden effect, now named first
  };
  int pairs = 0;  // pairs the invariant was checked on, over the three records
  for (const Case& c : {Case{17, "actuator-lag", "actuator-lag"}, Case{59, "pair", "deadband"},
                        Case{67, "order", "order"}}) {
    CAPTURE(c.seed);
    const RandomLoop r = draw_random_loop(c.seed, c.category);
    const LoopData d = simulate_random_loop(r);
    DiagnoseOptions o;
    o.validation_fraction = r.validation_fraction;
    const ModelSpec start = parse_model_spec(r.start_model);
    const Diagnosis dg = diagnose(d.op, d.pv, d.sample_period(), start, o);
    const auto& f = dg.last().findings;
    REQUIRE(!f.empty());
    CHECK(f[0].effect == c.first);
    const bool commute = !start.has("stiction") && !start.has("deadband") &&
                         !start.has("preisach") && !start.has("saturation") &&
                         !start.has("characteristic");
    for (std::size_t i = 0; i < f.size(); ++i)
      for (std::size_t j = i + 1; j < f.size(); ++j) {
        const Finding &a = f[i], &b = f[j];
        if (!on_path(a.effect) || !on_path(b.effect) || !(a.prediction_bic_change <= -2.0) ||
            !(b.prediction_bic_change <= -2.0) || (memory(a.effect) && memory(b.effect)))
          continue;
        const bool lags = (a.effect == "order" && b.effect == "actuator-lag") ||
                          (a.effect == "actuator-lag" && b.effect == "order");
        if (commute && lags) continue;
        INFO(a.effect << " above " << b.effect);
        CHECK(a.prediction_bic_change <= b.prediction_bic_change);
        ++pairs;
      }
  }
  CHECK(pairs >= 2);
}

// Each finding's gains restated as likelihoods on the judge's errors (Finding::output_bic_change,
// validation_deviance_change): development seed 12, a He stiction hidden from a linear model,
// which gains about 10 points on the estimation part and 60 held out. Its statistics are clearly
// negative; a trial that gains nothing pays its parameters; and the figure is the formula over
// the model's own effective residual samples (the simulated output judges a self-regulating
// model, and the stiction and saturation trials start where the model does).
TEST_CASE("each finding's gains as a change of BIC and of held-out deviance") {
  const RandomLoop r = draw_random_loop(12, "stiction");
  REQUIRE(r.start_model == "linear");
  const LoopData d = simulate_random_loop(r);
  DiagnoseOptions o;
  o.candidates = {"stiction", "delay", "saturation"};
  o.validation_fraction = r.validation_fraction;
  const Diagnosis dg = diagnose(d.op, d.pv, d.sample_period(), parse_model_spec("linear"), o);
  const DiagnosisStep& s = dg.last();
  REQUIRE(s.judge.horizon == 0);
  REQUIRE(s.findings.size() == 3);
  const ModelFit& m = s.fit;
  const double n_e = effective_sample_size(d.pv, m.y_sim, m.first_sample, m.estimation_end);
  const double n_v = effective_sample_size(d.pv, m.y_sim, m.estimation_end, d.pv.size());
  REQUIRE(n_e >= 1.0);
  REQUIRE(n_v >= 1.0);
  for (const auto& f : s.findings) {
    INFO(f.effect);
    REQUIRE(std::isfinite(f.output_bic_change));
    REQUIRE(std::isfinite(f.validation_deviance_change));
    CHECK(f.parameter_count >= 1.0);
    if (f.effect == "stiction") {
      CHECK(f.estimation_gain_percent > 5.0);
      CHECK(f.output_bic_change < -10.0);
      CHECK(f.validation_deviance_change < -10.0);
    }
    if (f.estimation_gain_percent <= 0.0)
      CHECK(f.output_bic_change >= f.parameter_count * std::log(n_e) - 1e-9);
    if (f.validation_gain_percent <= 0.0) CHECK(f.validation_deviance_change >= 0.0);
    const double left_e = 100.0 - m.fitness_percent, left_v = 100.0 - m.validation_fitness_percent;
    // (A delay trial starts later: it is measured over its own samples.)
    if (f.effect != "delay" && f.trial_fitness_percent < 100.0 &&
        f.trial_validation_fitness_percent < 100.0) {
      CHECK(f.output_bic_change ==
            doctest::Approx(2.0 * n_e * std::log((left_e - f.estimation_gain_percent) / left_e) +
                            f.parameter_count * std::log(n_e))
                .epsilon(1e-6));
      CHECK(f.validation_deviance_change ==
            doctest::Approx(2.0 * n_v * std::log((left_v - f.validation_gain_percent) / left_v))
                .epsilon(1e-6));
    }
  }
}

// Development seed 48 of the benchmark: Kano stiction (S 1.97, J 0.48) in a regulatory loop.
// Fitted to simulated output from OP the friction collapses (a band of 0.003, gaining what a
// deadband of 0.006 gains: OP's noise filtered), and an actuator lag gained most; refitted to
// the one-step prediction of PV (prediction_refit.hpp) the friction comes back near S 1.97,
// predicts PV far better than its two parameters cost, and ranks first, above the lag and above
// the deadband it nests (the likelihood-ratio test on the prediction errors).
TEST_CASE("a friction the simulated output misses ranks first on its refitted prediction") {
  const RandomLoop r = draw_random_loop(48, "stiction");
  REQUIRE(r.start_model == "linear");
  const LoopData d = simulate_random_loop(r);
  const Diagnosis dg = diagnose(d.op, d.pv, d.sample_period(), parse_model_spec("linear"));
  const auto& f = dg.last().findings;
  REQUIRE(!f.empty());
  CHECK(f[0].effect == "stiction");
  CHECK(f[0].supported);
  CHECK(f[0].prediction_bic_change < -20.0);
  CHECK(f[0].prediction_validation_gain_percent > 0.0);
  double S = std::nan("");
  for (const auto& p : f[0].prediction_parameters)
    if (p.name == "S") S = p.value;
  CHECK(S == doctest::Approx(1.97).epsilon(0.25));
  for (std::size_t i = 1; i < f.size(); ++i) {
    INFO(f[i].effect);
    if (f[i].effect == "deadband" || f[i].effect == "actuator-lag")
      CHECK(f[i].prediction_bic_change > f[0].prediction_bic_change + 20.0);
  }
}

// An open loop of 3000 samples at 1 s: OP random steps (levels 30-70 held 20-80 samples), PV
// their first-order response (pole 0.95, dead time 2 samples) plus what `measured` makes of the
// sample index and a measurement noise of 0.2.
std::pair<std::vector<double>, std::vector<double>> open_loop_record(
    unsigned seed, const std::function<double(std::size_t, double)>& measured) {
  const std::size_t N = 3000;
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> level(30.0, 70.0);
  std::uniform_int_distribution<int> hold(20, 80);
  std::normal_distribution<double> noise(0.0, 0.2);
  std::vector<double> op(N), pv(N, 50.0);
  for (std::size_t t = 0; t < N;) {
    const double v = level(rng);
    for (int k = hold(rng); k > 0 && t < N; --k) op[t++] = v;
  }
  double x = 50.0;
  for (std::size_t t = 3; t < N; ++t) {
    x = 0.95 * x + 0.05 * op[t - 3];
    pv[t] = x + measured(t, noise(rng));
  }
  return {op, pv};
}

// The one step of a diagnosis of a linear model with `delay` its only candidate (Ts 1 s).
DiagnosisStep delay_only_step(const std::vector<double>& op, const std::vector<double>& pv) {
  DiagnoseOptions o;
  o.candidates = {"delay"};
  const Diagnosis dg = diagnose(op, pv, 1.0, parse_model_spec("linear"), o);
  REQUIRE(dg.last().findings.size() == 1);
  return dg.last();
}

// A trial whose structure reaches further back (a `delay`, searched up to an eighth of the
// estimation part) starts its simulation later than the model. Its estimation gain is measured
// over the samples both simulate: a start the model fails on (here a burst of measurement noise
// in PV's first 200 samples) is no gain of the dead time's.
TEST_CASE("a trial that starts later gains only over the samples both fits simulate") {
  // Open loop: PV a first-order response to OP's random steps (dead time 2 samples), with
  // measurement noise, and a burst of larger noise over samples 20-220.
  const auto [op, pv] = open_loop_record(
      5, [](std::size_t t, double n) { return n * (t >= 20 && t < 220 ? 20.0 : 1.0); });
  const DiagnosisStep s = delay_only_step(op, pv);
  const Finding& f = s.findings[0];
  // The setup: each fitness over its own samples would credit the trial with the burst.
  CHECK(f.trial_fitness_percent - s.fit.fitness_percent > 5.0);
  CHECK(std::abs(f.estimation_gain_percent) < 1.0);
  CHECK(std::abs(f.validation_gain_percent) < 1.0);
  CHECK_FALSE(f.supported);
}

// The same trial also *fits* on fewer samples: a load the model cannot carry, in the samples the
// trial skips, bends the model's fit and not the trial's, and the trial would gain held out what
// the model lost. The model is refitted from the trial's first sample, and the trial measured
// against that fit.
TEST_CASE("a trial that starts later is measured against the model fitted on its samples") {
  // Open loop as above, measurement noise only, and a load that lifts PV by 15 over samples
  // 40-240, inside the eighth of the record a dead-time trial skips.
  const auto [op, pv] = open_loop_record(
      7, [](std::size_t t, double n) { return n + (t >= 40 && t < 240 ? 15.0 : 0.0); });
  const DiagnosisStep s = delay_only_step(op, pv);
  const Finding& f = s.findings[0];
  // The setup: the model fitted over the load loses held out what the trial keeps.
  CHECK(f.trial_validation_fitness_percent - s.fit.validation_fitness_percent > 5.0);
  CHECK(std::abs(f.estimation_gain_percent) < 1.0);
  CHECK(std::abs(f.validation_gain_percent) < 1.0);
  CHECK_FALSE(f.supported);
}

// Development seed 96 of the benchmark: He stiction behind a linear start model. On simulated
// output the stiction trial loses held out (-14.9 points), while an extra lag and a flow
// characteristic gain on both parts; their one-step predictions of PV are not worth their
// parameters, the stiction's is by far (BIC -124) and holds held out. On the path from OP to PV
// the prediction judges: stiction ranks first, and the findings it refutes are not supported
// whatever they gain on the simulated output.
TEST_CASE("a prediction that refutes a valve or lag finding's gains: unsupported, evidence first" *
          valvediag::test::release_only()) {
  const RandomLoop r = draw_random_loop(96, "stiction");
  REQUIRE(r.start_model == "linear");
  const LoopData d = simulate_random_loop(r);
  const Diagnosis dg = diagnose(d.op, d.pv, d.sample_period(), parse_model_spec("linear"));
  const auto& f = dg.last().findings;
  REQUIRE(f.size() >= 2);
  CHECK(f[0].effect == "stiction");
  CHECK_FALSE(f[0].supported);
  CHECK(f[0].prediction_bic_change < -50.0);
  CHECK(f[0].prediction_validation_gain_percent > 0.0);
  int refuted = 0;
  for (std::size_t i = 1; i < f.size(); ++i)
    if (f[i].gain_percent >= 2.0 && (f[i].effect == "order" || f[i].effect == "characteristic")) {
      INFO(f[i].effect);
      CHECK(f[i].prediction_bic_change > 0.0);
      CHECK_FALSE(f[i].supported);
      ++refuted;
    }
  CHECK(refuted >= 1);
}
