#include <doctest/doctest.h>

#include <cmath>
#include <map>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "../common/sanitized.hpp"
#include "valvediag/core/hammerstein.hpp"
#include "valvediag/model/model_fit.hpp"
#include "valvediag/sim/random_loop.hpp"
#include "valvediag/sim/scenarios.hpp"

using namespace valvediag;

namespace {

LoopData scenario_data(const std::string& name, std::uint64_t seed) {
  return run_scenario(scenario_by_name(name), seed, 0);
}

double param(const ModelFit& f, const std::string& effect, const std::string& name) {
  for (const auto& e : f.effects)
    if (e.name == effect)
      for (const auto& p : e.parameters)
        if (p.name == name) return p.value;
  return std::nan("");
}

ModelFit fit(const LoopData& d, const std::string& spec, ModelFitOptions opt = {}) {
  return fit_model(d.op, d.pv, d.sample_period(), parse_model_spec(spec), opt);
}

ModelFitOptions split(double fraction = 0.3) {
  ModelFitOptions o;
  o.validation_fraction = fraction;
  return o;
}

// A scenario's own record fitted with split(): several cases read the same fit, so it is made
// once (a fit takes seconds, ten times that under the sanitizers).
const ModelFit& shared_fit(const std::string& scenario, std::uint64_t seed,
                           const std::string& spec) {
  static std::map<std::string, ModelFit> fits;
  const std::string key = scenario + "#" + std::to_string(seed) + " " + spec;
  auto it = fits.find(key);
  if (it == fits.end())
    it = fits.emplace(key, fit(scenario_data(scenario, seed), spec, split())).first;
  return it->second;
}

// The reference loop of the valve scenarios with a given valve and noise.
LoopData custom_loop(std::vector<ValveEffect> valve, double noise, bool load_noise,
                     std::uint64_t seed, double dead_time = 4.0) {
  Scenario s = scenario_by_name("linear-clean");
  s.loop.valve = std::move(valve);
  s.loop.measurement_noise_std = noise;
  s.loop.disturbances.steps.clear();
  if (!load_noise) s.loop.disturbances.noises.clear();
  s.loop.process.dead_time = dead_time;
  return run_scenario(s, seed, 3000);
}

void show(const ModelFit& f) {
  std::string p;
  for (const auto& e : f.effects)
    for (const auto& v : e.parameters)
      p += " " + e.name + "." + v.name + "=" + std::to_string(v.value);
  MESSAGE(to_string(f.spec) << " (" << f.structure.na << "," << f.structure.nb << ","
                            << f.structure.nk << ") est " << f.fitness_percent << " val "
                            << f.validation_fitness_percent << ", " << f.evaluations << " evals, "
                            << f.elapsed_s << " s," << p);
}

// `linear` with a held-out part, by least squares alone and with the output-error refinement.
std::pair<ModelFit, ModelFit> least_squares_and_output_error(const LoopData& d) {
  ModelFitOptions ls = split();
  ls.output_error_iterations = 0;
  std::pair<ModelFit, ModelFit> r{fit(d, "linear", ls), fit(d, "linear", split())};
  show(r.first);
  show(r.second);
  return r;
}

}  // namespace

TEST_CASE("linear model: x = u, ARX by least squares, fitness as the core defines it") {
  const LoopData d = scenario_data("paper-ex1-linear", 1);
  const ModelFit f = fit(d, "linear", split());
  show(f);
  CHECK(f.status == ModelFitStatus::Converged);
  CHECK(f.effects.empty());
  CHECK(f.x_hat == d.op);
  CHECK(f.estimation_end == 2100);
  CHECK(f.fitness_percent > 90.0);
  CHECK(f.validation_fitness_percent > 80.0);
  CHECK(is_stable(f.a));
  CHECK(f.fitness_percent ==
        doctest::Approx(fitness_percent(d.pv, f.y_sim, f.first_sample, f.estimation_end)));
  // The same model driven again reproduces its own simulation.
  const auto again = simulate_model(f, d.op, d.pv);
  for (std::size_t t = 0; t < d.size(); t += 97) CHECK(again[t] == doctest::Approx(f.y_sim[t]));
}

TEST_CASE("impossible problems throw; options are checked") {
  const LoopData d = scenario_data("paper-ex1", 1);
  const ModelSpec st = parse_model_spec("stiction");
  std::vector<double> shorter(d.op.begin(), d.op.end() - 1);
  CHECK_THROWS_AS(fit_model(shorter, d.pv, 0.5, st), std::invalid_argument);
  CHECK_THROWS_AS(fit_model(std::vector<double>(d.size(), 50.0), d.pv, 0.5, st),
                  std::invalid_argument);
  CHECK_THROWS_AS(fit_model(d.op, d.pv, 0.0, st), std::invalid_argument);
  std::vector<double> few(d.op.begin(), d.op.begin() + 40), fewy(d.pv.begin(), d.pv.begin() + 40);
  CHECK_THROWS_AS(fit_model(few, fewy, 0.5, st), std::invalid_argument);
  ModelFitOptions bad;
  bad.validation_fraction = 0.95;
  CHECK_THROWS_AS(fit_model(d.op, d.pv, 0.5, st, bad), std::invalid_argument);
  std::vector<double> nan_pv = d.pv;
  nan_pv[10] = std::nan("");
  CHECK_THROWS_AS(fit_model(d.op, nan_pv, 0.5, st), std::invalid_argument);
}

TEST_CASE("He stiction: fs, fd recovered by separable least squares (paper Example 1)") {
  const LoopData d = scenario_data("paper-ex1", 1);
  const ModelFit& f = shared_fit("paper-ex1", 1, "stiction");
  show(f);
  CHECK(f.effects[0].variant == "he");
  CHECK(param(f, "stiction", "fs") == doctest::Approx(8.4).epsilon(0.2));
  CHECK(param(f, "stiction", "fd") == doctest::Approx(3.5243).epsilon(0.2));
  CHECK(f.fitness_percent > 95.0);
  const ModelFit& lin = shared_fit("paper-ex1", 1, "linear");
  show(lin);
  CHECK(f.validation_fitness_percent > lin.validation_fitness_percent + 20.0);
  REQUIRE(f.valve.size() == 1);
  CHECK(std::holds_alternative<HeStiction>(f.valve[0]));
  const auto again = simulate_model(f, d.op, d.pv);
  for (std::size_t t = 0; t < d.size(); t += 97) CHECK(again[t] == doctest::Approx(f.y_sim[t]));
}

TEST_CASE("He stiction on other loops, bands and noise") {
  struct Case {
    double fs, fd, noise;
    bool load_noise;
    std::uint64_t seed;
  };
  for (const Case c : {Case{5.0, 2.0, 0.1, false, 7}, Case{3.0, 1.0, 0.3, true, 8}}) {
    CAPTURE(c.fs);
    CAPTURE(c.fd);
    const LoopData d = custom_loop({HeStiction(c.fs, c.fd)}, c.noise, c.load_noise, c.seed);
    const ModelFit f = fit(d, "stiction", split());
    show(f);
    const double fs = param(f, "stiction", "fs"), fd = param(f, "stiction", "fd");
    CHECK(std::abs(fs - c.fs) <= std::max(0.2 * c.fs, 0.5));
    CHECK(std::abs(fd - c.fd) <= std::max(0.2 * c.fd, 0.5));
  }
}

TEST_CASE("Kano, Stenman and deadband bands; the true effect raises validation fitness") {
  {
    const LoopData d = scenario_data("kano", 1);
    const ModelFit& f = shared_fit("kano", 1, "stiction:kano");
    const ModelFit lin = fit(d, "linear", split());
    show(f);
    show(lin);
    CHECK(f.effects[0].variant == "kano");
    CHECK(param(f, "stiction", "S") == doctest::Approx(5.0).epsilon(0.1));
    // J (true 2) is weakly determined by this limit cycle: only its ordering is asserted.
    CHECK(param(f, "stiction", "J") < param(f, "stiction", "S"));
    CHECK(f.validation_fitness_percent > lin.validation_fitness_percent + 20.0);
  }
  {
    const LoopData d = scenario_data("stenman", 1);
    const ModelFit& f = shared_fit("stenman", 1, "stiction:stenman");
    const ModelFit lin = fit(d, "linear", split());
    show(f);
    CHECK(param(f, "stiction", "d") == doctest::Approx(3.0).epsilon(0.1));
    CHECK(f.validation_fitness_percent > lin.validation_fitness_percent + 15.0);
  }
  {
    const LoopData d = scenario_data("deadband", 1);
    const ModelFit& f = shared_fit("deadband", 1, "deadband");
    const ModelFit lin = fit(d, "linear", split());
    show(f);
    CHECK(param(f, "deadband", "d") == doctest::Approx(4.0).epsilon(0.15));
    CHECK(f.validation_fitness_percent > lin.validation_fitness_percent + 20.0);
  }
}

TEST_CASE("saturation limit and characteristic rangeability") {
  {
    const LoopData d = scenario_data("saturation", 1);
    const ModelFit f = fit(d, "saturation", split());
    const ModelFit lin = fit(d, "linear", split());
    show(f);
    show(lin);
    CHECK(param(f, "saturation", "upper") == doctest::Approx(70.0).epsilon(0.02));
    // OP never goes near the true lower limit (5 %): the fit must not invent one inside the data.
    const double op_min = *std::min_element(d.op.begin(), d.op.begin() + 2100);
    CHECK(param(f, "saturation", "lower") <= op_min + 1.0);
    CHECK(f.validation_fitness_percent > lin.validation_fitness_percent + 15.0);
  }
  {
    const LoopData d = scenario_data("characteristic", 1);
    const ModelFit f = fit(d, "characteristic", split());
    const ModelFit lin = fit(d, "linear", split());
    show(f);
    CHECK(f.effects[0].variant == "equal-percentage");
    CHECK(param(f, "characteristic", "R") == doctest::Approx(50.0).epsilon(0.25));
    CHECK(f.validation_fitness_percent > lin.validation_fitness_percent + 20.0);
  }
}

TEST_CASE("a travel limit the estimation part never reaches is left at the record's edge") {
  // The true lower limit is 5 %; OP stays above 49 % in the estimation part of seed 3 and falls to
  // 38 % in the held-out part. The estimation fit is flat in any lower limit under 49 %: where the
  // search stopped decided the held-out fitness (36 % or 83 %, from rounding alone). On seed 1 a
  // limit at 49.5 % clipped a few estimation samples for 0.014 points of fitness and the held-out
  // part to 16 % fitness. On seeds 2, 5 and 6 a limit at 50 % clipped OP's wander while the loop
  // regulated at 50 %, 0.12-0.29 points above the parsimony window but no more than a slow load's
  // residual gives by chance (widen_unsupported_limits): 14-17 % held out.
  for (const std::uint64_t seed : {1u, 2u, 3u, 5u, 6u}) {
    CAPTURE(seed);
    const LoopData d = scenario_data("saturation", seed);
    const ModelFit f = fit(d, "saturation", split());
    show(f);
    const double op_min = *std::min_element(d.op.begin(), d.op.end());
    CHECK(param(f, "saturation", "lower") == doctest::Approx(op_min).epsilon(1e-9));
    CHECK(param(f, "saturation", "upper") == doctest::Approx(70.0).epsilon(0.02));
    CHECK(f.validation_fitness_percent > 80.0);
  }
}

TEST_CASE("actuator lag: tau and the process lag as a pair") {
  // A lag before a linear process is a second pole the ARX part could carry as well: with a
  // first-order ARX the two time constants are recovered, but which is which is not identifiable.
  const LoopData d = scenario_data("actuator-lag", 1);
  ModelFitOptions o = split();
  o.structure.na_max = 1;
  o.structure.nb_max = 1;
  const ModelFit f = fit(d, "actuator-lag", o);
  const ModelFit lin = fit(d, "linear", o);
  show(f);
  const double tau = param(f, "actuator-lag", "tau");
  const double tau_p = -d.sample_period() / std::log(-f.a[0]);
  CHECK(std::min(tau, tau_p) == doctest::Approx(15.0).epsilon(0.2));
  CHECK(std::max(tau, tau_p) == doctest::Approx(40.0).epsilon(0.2));
  CHECK(f.fitness_percent > lin.fitness_percent + 1.5);
}

TEST_CASE("an actuator lag behind a sticky valve is profiled, not left to the friction's delay") {
  // Benchmark development seed 101: He's friction fs 1.34, fd 0.36 % behind a lag of 13.0 s.
  // Searched effect by effect, the lag fitted with the friction at rest took part of its delay
  // and kept it: 9.3 s, 42.6 % of the held-out part. Profiled: 12.0 s, 62.8 %.
  const RandomLoop r = draw_random_loop(101, "actuator-lag");
  const LoopData d = simulate_random_loop(r);
  double tau_true = 0.0;
  for (const auto& t : r.truth)
    if (t.effect == "actuator-lag") tau_true = t.value;
  REQUIRE(tau_true == doctest::Approx(12.99).epsilon(0.01));
  const ModelFit f = fit(d, "stiction+actuator-lag", split());
  show(f);
  CHECK(param(f, "actuator-lag", "tau") == doctest::Approx(tau_true).epsilon(0.15));
  CHECK(f.validation_fitness_percent > 55.0);
}

TEST_CASE("stiction + saturation are fitted jointly" * valvediag::test::release_only()) {
  const LoopData d = custom_loop({HeStiction(5.0, 2.0), Saturation(0.0, 52.0)}, 0.1, false, 10);
  const ModelFit f = fit(d, "stiction+saturation", split());
  show(f);
  CHECK(param(f, "saturation", "upper") == doctest::Approx(52.0).epsilon(0.03));
  CHECK(std::abs(param(f, "stiction", "fd") - 2.0) <= 1.0);
  // fs (true 5) comes out near 3 here: with the valve pinned at its limit for long stretches the
  // stick-slip is excited less; the joint model must still beat stiction alone.
  const ModelFit st = fit(d, "stiction", split());
  show(st);
  CHECK(f.fitness_percent > st.fitness_percent + 2.0);
  REQUIRE(f.valve.size() == 2);
  CHECK(std::holds_alternative<Saturation>(f.valve[1]));
}

TEST_CASE("process effects: delay and order widen the structure grid") {
  // Measurement noise only: the dead time (20 s, nk 19-20) is recovered and the held-out part
  // confirms it. (The output-error fit of the linear start, nk <= 10 with two poles, carries
  // most of a dead time behind a smooth OP, so the gain is about a point, not the five points
  // the biased least-squares start used to leave.)
  const LoopData d = custom_loop({}, 0.1, false, 11, 20.0);
  const ModelFit lin = fit(d, "linear", split());
  const ModelFit del = fit(d, "delay", split());
  show(lin);
  show(del);
  CHECK(lin.structure.nk <= 10);
  CHECK(param(del, "delay", "nk") == doctest::Approx(19.5).epsilon(0.05));
  CHECK(param(del, "delay", "dead_time") == doctest::Approx(param(del, "delay", "nk") * 1.0));
  CHECK(del.validation_fitness_percent > lin.validation_fitness_percent + 0.3);
  CHECK(del.fitness_percent > lin.fitness_percent + 1.0);
  const ModelFit ord = fit(d, "order", split());
  CHECK(ord.fitness_percent >= lin.fitness_percent - 0.2);  // a wider grid never fits worse
  // With heavy filtered load noise as well, the output-error fit of the linear start carries
  // much of the dead time with its two poles: delay still finds it, the held-out gain is small.
  const LoopData n = custom_loop({}, 0.1, true, 11, 20.0);
  const ModelFit nlin = fit(n, "linear", split());
  const ModelFit ndel = fit(n, "delay", split());
  show(nlin);
  show(ndel);
  CHECK(param(ndel, "delay", "nk") == doctest::Approx(19.5).epsilon(0.15));
  CHECK(ndel.fitness_percent > nlin.fitness_percent);
  CHECK(ndel.validation_fitness_percent > nlin.validation_fitness_percent);
}

TEST_CASE("order: an extra lag and wider orders carry a third lag; the linear start cannot") {
  const LoopData d = scenario_data("third-order", 1);
  const ModelFit lin = fit(d, "linear", split());
  const ModelFit ord = fit(d, "order", split());
  show(lin);
  show(ord);
  CHECK(param(ord, "order", "extra_lag") > 5.0);
  CHECK(ord.validation_fitness_percent > lin.validation_fitness_percent + 1.0);
  CHECK(ord.fitness_percent > lin.fitness_percent + 2.0);
}

TEST_CASE("output-error refinement: never worse than least squares, better under load noise") {
  const LoopData d = scenario_data("third-order", 2);
  const auto [a, b] = least_squares_and_output_error(d);
  CHECK(b.fitness_percent >= a.fitness_percent - 1e-9);
  CHECK(b.fitness_percent > a.fitness_percent + 2.0);
}

TEST_CASE(
    "a model extending a fitted one never fits its estimation part worse "
    "(ModelFitOptions::extends)") {
  // Paper Example 1: He's friction alone is searched finely; a chain of two effects on coarser
  // grids (by passes over each effect, or an actuator lag profiled), which here missed the
  // friction's basin (an actuator lag added to it fitted 94.3 % of the estimation part against
  // 98.6 % without). The fit it extends starts a second polish and is a candidate of the final
  // choice.
  const LoopData d = run_scenario(scenario_by_name("paper-ex1"), 1, 4000);
  const ModelFit st = fit(d, "stiction", split());
  show(st);
  for (const char* spec :
       {"stiction+actuator-lag", "stiction+saturation", "stiction+disturbance"}) {
    CAPTURE(spec);
    ModelFitOptions o = split();
    o.extends = &st;
    const ModelFit wide = fit(d, spec, o);
    show(wide);
    CHECK(wide.fitness_percent >= st.fitness_percent - 0.05);
    // The friction the wider model keeps is the one fitted before or a better one nearby.
    CHECK(param(wide, "stiction", "fs") ==
          doctest::Approx(param(st, "stiction", "fs")).epsilon(0.2));
  }
  // Process effects alone added (no valve search): the extended model's linear part, its
  // constant as a flat load, starts an output-error refinement. Least squares alone gave the
  // third-order loop's load model no stable A.
  for (const char* scenario : {"load-changes", "third-order"}) {
    CAPTURE(scenario);
    const LoopData dl = scenario_data(scenario, 2);
    const ModelFit lin = fit(dl, "linear", split());
    ModelFitOptions o = split();
    o.extends = &lin;
    const ModelFit load = fit(dl, "disturbance", o);
    show(load);
    REQUIRE(std::isfinite(load.fitness_percent));
    CHECK(load.fitness_percent >= lin.fitness_percent - 1e-6);
  }
}

TEST_CASE(
    "a long sticky record: least squares finds no stable A, output error from reflected poles "
    "does") {
  // Paper Example 1 over 6000 samples (50 min of stick-slip cycles at a steady set point): every
  // least-squares A of the range lies past the unit circle. The output-error refinement starts
  // from A with those roots reflected inside and finds the stable linear model the ladder starts
  // from.
  const LoopData d = run_scenario(scenario_by_name("paper-ex1"), 3, 6000);
  const auto [a, b] = least_squares_and_output_error(d);
  CHECK(a.status == ModelFitStatus::NoStableModel);
  REQUIRE(b.status != ModelFitStatus::NoStableModel);
  CHECK(is_stable(b.a));
  CHECK(b.fitness_percent > 60.0);             // measured 73.6
  CHECK(b.validation_fitness_percent > 60.0);  // measured 73.3
  // A forced-stable fit is kept only when it beats the record's mean: a level (integrating)
  // over 12000 samples still has no stable linear part, so the ladder goes on from `integrator`.
  const LoopData level = run_scenario(scenario_by_name("integrating"), 1, 12000);
  const ModelFit c = fit(level, "linear", split());
  show(c);
  CHECK(c.status == ModelFitStatus::NoStableModel);
}

TEST_CASE("integrator and disturbance forms") {
  const LoopData d = scenario_data("integrating", 1);
  const ModelFit lin = fit(d, "linear");
  CHECK(lin.status == ModelFitStatus::NoStableModel);  // drift makes every ARX fit unstable
  CHECK(std::isnan(lin.fitness_percent));
  const ModelFit dist = fit(d, "disturbance");
  const ModelFit both = fit(d, "integrator+disturbance");
  show(lin);
  show(dist);
  show(both);
  CHECK(both.integrating);
  // The level loop: K = 0.01 PV/s per % of valve.
  CHECK(param(both, "integrator", "rate_gain") == doctest::Approx(0.01).epsilon(0.15));
  CHECK(both.fitness_percent > 90.0);
  CHECK(both.disturbance.size() == d.size());
}

TEST_CASE("an integrating loop's valve is fitted on short predictions, not a drifting simulation" *
          valvediag::test::release_only()) {
  // Randomized level loops (the benchmark's development seeds) with load noise at the valve: a
  // random walk in PV. Fitted on the simulated output of the whole record, the drift chose the
  // band (measured: 27 % of OP for a 2.8 % Kano band, 24 % for a 2.5 % deadband); with the level
  // restarted from measured PV every few samples the band comes back.
  struct Case {
    std::uint64_t seed;
    const char* category;
    const char* spec;
    const char* parameter;
  };
  for (const Case c : {Case{1, "deadband", "deadband+integrator", "d"},
                       Case{97, "deadband", "deadband+integrator", "d"},
                       Case{120, "stiction", "stiction:kano+integrator", "S"}}) {
    CAPTURE(c.seed);
    const RandomLoop loop = draw_random_loop(c.seed, c.category);
    REQUIRE(loop.start_model == "integrator");
    REQUIRE(loop.truth.size() == 1);
    const LoopData d = simulate_random_loop(loop);
    const ModelFit f = fit(d, c.spec, split());
    show(f);
    const double band = param(f, c.category, c.parameter), truth = loop.truth[0].value;
    MESSAGE(std::string(c.spec) << " seed " << c.seed << ": " << band << " against " << truth
                                << " % of OP");
    CHECK(band == doctest::Approx(truth).epsilon(0.1));
  }
}

TEST_CASE("a disturbance model's held-out load is predicted from the past, not fitted there") {
  // load-changes: real slow loads; the held-out part is scored with the load predicted one knot
  // interval ahead (the mean equation error of the interval before).
  LoopData d = scenario_data("load-changes", 1);
  const ModelFit lin = fit(d, "linear", split());
  const ModelFit dist = fit(d, "disturbance", split());
  show(lin);
  show(dist);
  const std::size_t N = d.size(), e0 = dist.estimation_end;
  const double h_s = param(dist, "disturbance", "knot_spacing");
  REQUIRE(h_s > 0);
  const auto h = static_cast<std::size_t>(std::llround(h_s / d.sample_period()));
  REQUIRE(dist.disturbance.size() == N);
  // Constant over each knot interval of the held-out part.
  for (std::size_t t = e0; t < N; ++t)
    if ((t - e0) % h != 0) REQUIRE(dist.disturbance[t] == dist.disturbance[t - 1]);
  // A real slow load is predictable: the model with it is better on the held-out part.
  CHECK(dist.validation_fitness_percent > lin.validation_fitness_percent + 20.0);
  // Causal: a jump of PV late in the held-out part changes nothing before it (a load fitted to
  // the held-out samples would bend towards it), and earns the model nothing there.
  const std::size_t m = N - h - h / 2;
  for (std::size_t t = m; t < N; ++t) d.pv[t] += 50.0;
  const ModelFit moved = fit(d, "disturbance", split());
  REQUIRE(moved.disturbance.size() == N);
  REQUIRE(moved.estimation_end == e0);
  for (std::size_t t = 0; t < m; ++t) {
    INFO(t);
    REQUIRE(moved.disturbance[t] == doctest::Approx(dist.disturbance[t]).epsilon(1e-9));
    REQUIRE(moved.y_sim[t] == doctest::Approx(dist.y_sim[t]).epsilon(1e-9));
  }
  // The interval holding the jump still predicts the load from before it.
  const std::size_t interval_end = std::min(N, e0 + ((m - e0) / h + 1) * h);
  for (std::size_t t = m; t < interval_end; ++t)
    CHECK(moved.disturbance[t] == doctest::Approx(dist.disturbance[t]).epsilon(1e-9));
}

TEST_CASE("held valve: the held-out fitness with the valve held where estimation left it") {
  // Exact: it is the model driven by an OP held from the first held-out sample on, for a linear
  // valve (x = u) on a self-regulating and on an integrating process.
  for (const char* c : {"linear-clean/linear", "level/integrator"}) {
    const std::string name(c);
    CAPTURE(name);
    const std::size_t slash = name.find('/');
    const LoopData d = scenario_data(name.substr(0, slash), 1);
    const ModelFit f = fit(d, name.substr(slash + 1), split());
    REQUIRE(std::isfinite(f.validation_fitness_percent));
    const std::size_t e0 = f.estimation_end, N = d.size();
    // The premise: simulate_model reproduces the fit's own simulated output.
    const std::vector<double> again = simulate_model(f, d.op, d.pv);
    CHECK(fitness_percent(d.pv, again, e0, N) ==
          doctest::Approx(f.validation_fitness_percent).epsilon(1e-9));
    std::vector<double> held_op(d.op);
    for (std::size_t t = e0; t < N; ++t) held_op[t] = d.op[e0 - 1];
    const double held = held_valve_validation_fitness(f, d.pv);
    CHECK(held == doctest::Approx(fitness_percent(d.pv, simulate_model(f, held_op, d.pv), e0, N))
                      .epsilon(1e-9));
    MESSAGE(name << ": validation " << f.validation_fitness_percent << " %, held " << held << " %");
    if (name == "level/integrator") {
      // The controller moves the valve there and the level answers: holding it predicts worse.
      CHECK(held < f.validation_fitness_percent - 10.0);
    } else {
      // Loads the controller compensates: OP moves and PV holds, so a valve held still predicts
      // PV better than the true linear valve does. Why a held-out gain a held valve also earns
      // is no evidence of memory.
      CHECK(held > f.validation_fitness_percent + 10.0);
    }
  }
  // A valve that does not move in the held-out part: holding it changes nothing.
  LoopData d = scenario_data("linear-clean", 2);
  const std::size_t e0 = d.size() - static_cast<std::size_t>(0.3 * static_cast<double>(d.size()));
  for (std::size_t t = e0 - 20; t < d.size(); ++t) d.op[t] = d.op[e0 - 21];
  const ModelFit still = fit(d, "linear", split());
  REQUIRE(std::isfinite(still.validation_fitness_percent));
  CHECK(held_valve_validation_fitness(still, d.pv) ==
        doctest::Approx(still.validation_fitness_percent).epsilon(1e-9));
  // He's stiction in a stick-slip cycle: the held-out slips are the fit.
  const ModelFit& he = shared_fit("paper-ex1", 1, "stiction");
  CHECK(he.validation_fitness_percent > 80.0);
  CHECK(held_valve_validation_fitness(he, scenario_data("paper-ex1", 1).pv) <
        he.validation_fitness_percent - 50.0);
  // No held-out part: NaN.
  CHECK(std::isnan(held_valve_validation_fitness(fit(d, "linear"), d.pv)));
}

TEST_CASE("paper comparison: Preisach vs He vs Kano on simulated loops" *
          valvediag::test::release_only()) {
  // Asymmetric (position-dependent) stiction, as the paper's Examples 2 and 4: validation on a
  // separate record of the same loop (another noise seed), as in Example 4.
  double pre = 0, he = 0, kano = 0;
  const std::vector<std::uint64_t> seeds{1, 2, 3};
  for (std::uint64_t seed : seeds) {
    const LoopData d = scenario_data("asymmetric-stiction", seed);
    const LoopData v = scenario_data("asymmetric-stiction", seed + 100);
    ModelFitOptions o;
    o.preisach_L_min = 10;
    o.preisach_L_max = 24;
    auto val = [&](const ModelFit& f) {
      return fitness_percent(v.pv, simulate_model(f, v.op, v.pv), f.first_sample, v.size());
    };
    const ModelFit p = fit(d, "preisach:general", o), h = fit(d, "stiction", o),
                   k = fit(d, "stiction:kano", o);
    MESSAGE("seed " << seed << ": preisach " << p.fitness_percent << " / " << val(p) << ", he "
                    << h.fitness_percent << " / " << val(h) << ", kano " << k.fitness_percent
                    << " / " << val(k) << " (estimation / validation)");
    CHECK(p.fitness_percent > h.fitness_percent);
    CHECK(p.fitness_percent > k.fitness_percent);
    pre += val(p) / 3;
    he += val(h) / 3;
    kano += val(k) / 3;
  }
  if (seeds.size() == 3) {
    CHECK(pre > he + 1.5);
    CHECK(pre > kano + 1.5);
  }
  // Plain He stiction (Example 3's finding): both fit about equally.
  const LoopData d = scenario_data("paper-ex1", 1);
  ModelFitOptions o;
  o.preisach_L_min = 10;
  o.preisach_L_max = 24;
  const ModelFit p = fit(d, "preisach:general", o), h = fit(d, "stiction", o);
  show(p);
  show(h);
  CHECK(std::abs(p.fitness_percent - h.fitness_percent) < 3.0);
}

// Position-dependent friction (preisach:position-dependent) on the paper's asymmetric valve
// (fs 8, fd 3 up to 20 % of travel, fs 1.5, fd 0.5 from 40 %): it nests He's model, so it never
// fits the estimation part worse; it finds which side sticks most and predicts the held-out
// part better. `preisach` alone (auto) keeps it over 40-odd Preisach weights by BIC.
TEST_CASE("preisach: position-dependent friction on the asymmetric valve" *
          valvediag::test::release_only()) {
  const LoopData d = scenario_data("asymmetric-stiction", 1);
  const ModelFit p = fit(d, "preisach:position-dependent", split()),
                 h = fit(d, "stiction", split());
  show(p);
  REQUIRE(p.effects.size() == 1);
  CHECK(p.effects[0].variant == "position-dependent");
  CHECK(p.valve_coordinates.size() == 7);
  CHECK(p.fitness_percent >= h.fitness_percent - 0.1);
  CHECK(param(p, "preisach", "severe_above") == 0.0);  // the severe side is the closed one
  CHECK(param(p, "preisach", "fs") == doctest::Approx(8.0).epsilon(0.3));
  CHECK(param(p, "preisach", "fs_mild") < 0.6 * param(p, "preisach", "fs"));
  CHECK(param(p, "preisach", "position") > 15.0);
  CHECK(param(p, "preisach", "position") < 50.0);
  CHECK(effect_parameter_count("preisach", p, d.sample_period()) == 6.0);
  // As a trial on the stiction model it takes He's place: it adds its six less He's two.
  CHECK(effect_parameter_count("stiction", h, d.sample_period()) == 2.0);
  CHECK(added_parameter_count("preisach", p, h, d.sample_period()) == 4.0);
  CHECK(added_parameter_count("stiction", h, fit(d, "linear", split()), d.sample_period()) == 2.0);
  const ModelFit a = fit(d, "preisach", split());
  CHECK(to_string(a.spec) == "preisach");
  CHECK(a.effects[0].variant == "position-dependent");
  CHECK(a.validation_fitness_percent == doctest::Approx(p.validation_fitness_percent));
  // Another record of the same loop (the paper's Example 4; simulate_model drives the fitted
  // blocks): it predicts that better than He's model.
  const LoopData v = scenario_data("asymmetric-stiction", 101);
  const double pv = fitness_percent(v.pv, simulate_model(p, v.op, v.pv), p.first_sample, v.size());
  const double hv = fitness_percent(v.pv, simulate_model(h, v.op, v.pv), h.first_sample, v.size());
  MESSAGE("another record: position-dependent " << pv << " %, He " << hv << " %");
  CHECK(pv > hv + 1.0);
}

TEST_CASE("a fit reports its valve search's progress, rising to the end, and the same fit") {
  const LoopData d = run_scenario(scenario_by_name("paper-ex1"), 1, 2000);
  for (const char* spec : {"stiction", "stiction+actuator-lag"}) {
    CAPTURE(spec);
    std::vector<std::pair<double, std::string>> calls;
    ModelFitOptions o = split();
    o.progress = [&calls](double share, const std::string& stage) {
      calls.emplace_back(share, stage);
    };
    const ModelFit with = fit(d, spec, o);
    const ModelFit without = fit(d, spec, split());
    CHECK(with.fitness_percent == without.fitness_percent);  // reporting changes nothing
    REQUIRE(calls.size() >= 10);
    bool rising = true, grid = false, polish = false;
    for (std::size_t k = 0; k < calls.size(); ++k) {
      rising = rising && (k == 0 || calls[k].first > calls[k - 1].first);
      grid = grid || calls[k].second.find("a grid of") != std::string::npos;
      polish = polish || calls[k].second.find("polish") != std::string::npos;
    }
    CHECK(rising);
    CHECK(grid);
    CHECK(polish);
    CHECK(calls.front().first < 0.2);
    CHECK(calls.back().first > 0.6);  // polishes that converge early end short of 1
    CHECK(calls.back().first <= 1.0);
  }
}

TEST_CASE("a Preisach fit reports its weights' progress, rising to 1; auto fills half with each") {
  const LoopData d = run_scenario(scenario_by_name("paper-ex1"), 1, 2000);
  ModelFitOptions small = split();
  small.preisach_L_max = 6;
  for (const char* spec : {"preisach:general", "preisach"}) {
    CAPTURE(spec);
    std::vector<std::pair<double, std::string>> calls;
    ModelFitOptions o = small;
    o.progress = [&calls](double share, const std::string& stage) {
      calls.emplace_back(share, stage);
    };
    const ModelFit with = fit(d, spec, o);
    const ModelFit without = fit(d, spec, small);
    CHECK(with.fitness_percent == without.fitness_percent);  // reporting changes nothing
    REQUIRE(calls.size() >= 5);
    bool rising = true;
    int weights_before_half = 0, after_half = 0;
    for (std::size_t k = 0; k < calls.size(); ++k) {
      rising = rising && (k == 0 || calls[k].first >= calls[k - 1].first);
      const bool weights = calls[k].second.find("Preisach weights") != std::string::npos;
      weights_before_half += weights && calls[k].first <= 0.5;
      after_half += calls[k].first > 0.5;
      CHECK(calls[k].first >= 0.0);
      CHECK(calls[k].first <= 1.0);
    }
    CHECK(rising);
    if (std::string(spec) == "preisach:general") {
      CHECK(calls.back().first == 1.0);  // every configuration fitted
      CHECK(calls.back().second.find("Preisach weights") != std::string::npos);
    } else {
      // auto: the weights fill the first half, the position-dependent friction's search the rest.
      CHECK(weights_before_half >= 3);
      CHECK(after_half >= 3);
    }
  }
}

TEST_CASE("fit_models runs independent fits in parallel with the same results") {
  const LoopData d = scenario_data("stenman", 2);
  const std::vector<ModelSpec> specs = {parse_model_spec("linear"), parse_model_spec("deadband"),
                                        parse_model_spec("stiction:stenman")};
  const auto many = fit_models(d.op, d.pv, 1.0, specs, split());
  REQUIRE(many.size() == 3);
  for (std::size_t k = 0; k < specs.size(); ++k) {
    const ModelFit one = fit(d, to_string(specs[k]), split());
    CHECK(many[k].spec == specs[k]);
    CHECK(many[k].fitness_percent == doctest::Approx(one.fitness_percent).epsilon(1e-6));
  }
}

// The band's profile-likelihood interval (band_interval): it holds the fitted band, it holds the
// true one where the fit found the true valley, and a flat cost (more measurement noise) widens
// it. It is local: it walks out from the fitted band, so it cannot undo a fit that took another
// valley (He 5/2 at noise 0.5 and 1 fits fs 10.8 and 9.7, whose intervals exclude 5).
TEST_CASE("a friction effect's band interval") {
  struct Case {
    std::string spec, effect, param;
    std::string scenario;  // a scenario's own record (seed 1), or "" for a custom loop
    LoopData data;
    double truth;
    bool truth_inside;  // measured; the fit found the true valley
  };
  std::vector<Case> cases;
  cases.push_back(
      {"stiction", "stiction", "fs", "paper-ex1", scenario_data("paper-ex1", 1), 8.4, true});
  cases.push_back({"stiction:kano", "stiction", "S", "kano", scenario_data("kano", 1), 5.0, true});
  cases.push_back(
      {"stiction:stenman", "stiction", "d", "stenman", scenario_data("stenman", 1), 3.0, true});
  cases.push_back(
      {"deadband", "deadband", "d", "deadband", scenario_data("deadband", 1), 4.0, true});
  for (double noise : {0.1, 0.5, 1.0, 2.0})
    cases.push_back({"stiction", "stiction", "fs", "",
                     custom_loop({HeStiction(5.0, 2.0)}, noise, false, 7), 5.0, noise < 0.2});
  std::printf("\nband interval: spec, truth, fitted band, 95 %% interval, N_eff, evaluations\n");
  std::vector<double> widths;
  for (const Case& c : cases) {
    CAPTURE(c.spec);
    const ModelFitOptions o = split();
    // A scenario's record: the fit the cases above made.
    const ModelFit f =
        c.scenario.empty() ? fit(c.data, c.spec, o) : shared_fit(c.scenario, 1, c.spec);
    const double band = param(f, c.effect, c.param);
    const BandInterval iv =
        band_interval(c.data.op, c.data.pv, c.data.sample_period(), f, c.effect, o);
    REQUIRE(iv.valid);
    std::printf("%-18s %5.2f %6.3f  %6.3f-%-6.3f %6.0f %4d%s%s\n", c.spec.c_str(), c.truth, band,
                iv.lo, iv.hi, iv.effective_samples, iv.evaluations, iv.capped ? " capped" : "",
                iv.open_above ? " open above" : "");
    CHECK(iv.lo <= band);
    CHECK(band <= iv.hi);
    if (c.truth_inside) {
      CHECK(iv.lo <= c.truth);
      CHECK(c.truth <= iv.hi);
      CHECK_FALSE(iv.open_above);  // the slips bound the band: far below the OP span
    }
    widths.push_back(iv.hi - iv.lo);
  }
  // Measured: 0.48 wide at noise 0.1, 16 at noise 2 (the fit there says fs 0: the walk finds
  // bands up to 16 that fit as well or better).
  CHECK(widths.back() > 10 * widths[4]);
  // No friction effect, or not the one asked for: no interval.
  const LoopData& d = cases.front().data;
  const ModelFit& lin = shared_fit("paper-ex1", 1, "linear");
  CHECK_FALSE(band_interval(d.op, d.pv, d.sample_period(), lin, "stiction", split()).valid);
  const ModelFit& he = shared_fit("paper-ex1", 1, "stiction");
  CHECK_FALSE(band_interval(d.op, d.pv, d.sample_period(), he, "deadband", split()).valid);
}

namespace {
// A fit by hand: y(t) = -a y(t-1) + b x(t-1-nk) + c (differenced when integrating), its valve
// position x and simulated output over n samples.
ModelFit hand_fit(bool integrating, double a, double b, double c, std::size_t n) {
  ModelFit f;
  f.structure = ArxStructure{1, 1, 1};
  f.integrating = integrating;
  f.a = {a};
  f.b = {b};
  f.c = c;
  f.first_sample = 3;
  f.estimation_end = n;
  f.x_hat.resize(n);
  for (std::size_t t = 0; t < n; ++t)
    f.x_hat[t] = std::sin(0.05 * static_cast<double>(t)) + static_cast<double>((t / 37) % 2);
  std::vector<double> v(n, 0.0);  // the (differenced) output
  f.y_sim.assign(n, 0.0);
  for (std::size_t t = 2; t < n; ++t) {
    v[t] = -a * v[t - 1] + b * f.x_hat[t - 2] + c;
    f.y_sim[t] = integrating ? f.y_sim[t - 1] + v[t] : v[t];
  }
  return f;
}
}  // namespace

TEST_CASE("k_step_output: the measured output k samples back, carried through the fit") {
  constexpr std::size_t n = 400, jump = 200, k = 10;
  SUBCASE("a stable fit on its own output predicts it exactly at any horizon") {
    const ModelFit f = hand_fit(false, -0.9, 0.5, 0.1, n);
    for (std::size_t h : {std::size_t{1}, k, std::size_t{150}}) {
      const auto p = k_step_output(f, f.y_sim, h);
      REQUIRE(p.size() == n);
      double worst = 0;
      for (std::size_t t = f.first_sample + h; t < n; ++t)
        worst = std::max(worst, std::abs(p[t] - f.y_sim[t]));
      CHECK(worst < 1e-9);
    }
  }
  SUBCASE("an integrating fit restarts from the measured level: a level jump is followed") {
    const ModelFit f = hand_fit(true, -0.5, 0.2, -0.1, n);
    std::vector<double> y = f.y_sim;
    for (std::size_t t = jump; t < n; ++t) y[t] += 5.0;  // a load moved the level
    const auto p = k_step_output(f, y, k);
    REQUIRE(p.size() == n);
    double worst_k = 0, least_sim = 1e9;
    for (std::size_t t = jump + 1 + k; t < n; ++t) {
      worst_k = std::max(worst_k, std::abs(p[t] - y[t]));
      least_sim = std::min(least_sim, std::abs(f.y_sim[t] - y[t]));
    }
    CHECK(worst_k < 1e-9);
    CHECK(least_sim == doctest::Approx(5.0));  // the simulated output never recovers
    // Before the jump's effect reaches it, the prediction is the model's as well.
    CHECK(std::abs(p[jump - 1] - y[jump - 1]) < 1e-9);
  }
  SUBCASE("no linear part, no prediction") {
    ModelFit f;
    CHECK(k_step_output(f, std::vector<double>(50, 1.0), 3).empty());
  }
}
