// refit_by_prediction (prediction_refit.hpp): a trial's valve effect fitted again to predict PV
// one step ahead; best_arx_prediction_error's dead-time profile.
#include <doctest/doctest.h>

#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "valvediag/diagnose/prediction_refit.hpp"
#include "valvediag/model/model_fit.hpp"
#include "valvediag/model/model_spec.hpp"
#include "valvediag/sim/random_loop.hpp"

using namespace valvediag;

namespace {

double parameter(const std::vector<NamedValue>& p, const std::string& name) {
  for (const auto& v : p)
    if (v.name == name) return v.value;
  return std::nan("");
}

ModelFit fit_of(const LoopData& d, const char* spec) {
  ModelFitOptions fo;
  fo.validation_fraction = 0.3;
  return fit_model(d.op, d.pv, d.sample_period(), parse_model_spec(spec), fo);
}

PredictionRefitOptions options_for(const ModelFit& f) {
  PredictionRefitOptions o;
  o.nk_max = 10;
  o.from = f.first_sample + o.nk_max + o.order + 2;
  o.estimation_end = f.estimation_end;
  return o;
}

}  // namespace

TEST_CASE("best_arx_prediction_error finds the dead time of an ARX system") {
  std::mt19937 rng(11);
  std::normal_distribution<double> e(0.0, 0.1);
  std::uniform_real_distribution<double> level(-5.0, 5.0);
  const std::size_t N = 3000;
  std::vector<double> x(N), y(N, 0.0);
  for (std::size_t t = 0; t < N; ++t) x[t] = t % 20 == 0 || t == 0 ? level(rng) : x[t - 1];
  // B's first tap at x(t - 6): nk 5.
  for (std::size_t t = 6; t < N; ++t) y[t] = 0.7 * y[t - 1] + 0.4 * x[t - 6] + e(rng);
  const PredictionError p = best_arx_prediction_error(y, x, 12, 2, 20, 2000);
  REQUIRE(p.ok);
  CHECK(p.nk == 5);
  CHECK(p.estimation_variance == doctest::Approx(0.01).epsilon(0.1));
  // The range below the true dead time cannot reach it.
  const PredictionError short_range = best_arx_prediction_error(y, x, 3, 2, 20, 2000);
  REQUIRE(short_range.ok);
  CHECK(short_range.estimation_variance > 2.0 * p.estimation_variance);
  CHECK_FALSE(best_arx_prediction_error(y, x, 30, 2, 20, 2000).ok);  // lags before `from`
  // The profile picks its dead time by PredictionErrorSearch's variances: the same dead time
  // and figures as fitting every one row by row, levels and changes alike.
  for (const bool integrating : {false, true}) {
    PredictionError direct;
    for (std::size_t nk = 0; nk <= 12; ++nk) {
      const PredictionError q = arx_prediction_error(y, x, nk, 6, 20, 2000, integrating);
      if (q.ok && (!direct.ok || q.estimation_variance < direct.estimation_variance)) direct = q;
    }
    const PredictionError profiled = best_arx_prediction_error(y, x, 12, 6, 20, 2000, integrating);
    REQUIRE(direct.ok);
    REQUIRE(profiled.ok);
    CHECK(profiled.nk == direct.nk);
    CHECK(profiled.estimation_variance == direct.estimation_variance);
    CHECK(profiled.validation_variance == direct.validation_variance);
    CHECK(profiled.validation_samples == N - 2000);
  }
}

// Development seed 48 (the case of test_prediction_error): Kano stiction S 1.97, J 0.48 in a
// regulatory loop. Fitted to simulated output from OP, the friction collapses (a band of 0.003);
// refitted to the one-step prediction it comes back near the truth and predicts clearly better.
TEST_CASE("refitted to the one-step prediction, a collapsed friction finds its band") {
  const RandomLoop r = draw_random_loop(48, "stiction");
  const LoopData d = simulate_random_loop(r);
  const ModelFit trial = fit_of(d, "stiction:kano");
  REQUIRE(trial.valve.size() == 1);
  CHECK(parameter(block_parameters(trial.valve[0]), "S") < 1.0);  // the collapse, as measured
  const PredictionRefitOptions po = options_for(trial);
  const PredictionRefit refit =
      refit_by_prediction(d.op, d.pv, d.sample_period(), trial, "stiction", po);
  REQUIRE(refit.ok);
  CHECK(parameter(refit.parameters, "S") == doctest::Approx(1.97).epsilon(0.2));
  const PredictionError before =
      best_arx_prediction_error(d.pv, trial.x_hat, po.nk_max, po.order, po.from, po.estimation_end);
  REQUIRE(before.ok);
  // Likelihood ratio on the estimation part far beyond chi-square(2) at 99 % (9.2).
  // (The likelihood ratio is the BIC change without a penalty, sign reversed.)
  const double lr = -prediction_bic_change(refit.error, before);
  CHECK(lr > 30.0);
  CHECK(refit.error.validation_variance < before.validation_variance);
  CHECK(refit.x_hat.size() == d.pv.size());
}

// Development seed 264 of the 65-case stiction run: He's friction, fs 1.06, fd 0.30 (a jump of 70 %
// of the band). Refitted over the band alone (the jump held where the simulated-output fit left
// it, or at half), the friction predicted no better than a deadband (PE BIC -173 against -180),
// and the diagnosis named `deadband`. The grid over band and fd/fs together finds the jump.
TEST_CASE("refitted to the one-step prediction, a friction's jump predicts beyond a deadband") {
  const RandomLoop r = draw_random_loop(264, "stiction");
  const LoopData d = simulate_random_loop(r);
  const ModelFit he = fit_of(d, "stiction");
  const ModelFit db = fit_of(d, "deadband");
  const PredictionRefitOptions po = options_for(he);
  REQUIRE(po.estimation_end == db.estimation_end);
  const PredictionRefit with_jump =
      refit_by_prediction(d.op, d.pv, d.sample_period(), he, "stiction", po);
  const PredictionRefit without =
      refit_by_prediction(d.op, d.pv, d.sample_period(), db, "deadband", po);
  REQUIRE(with_jump.ok);
  REQUIRE(without.ok);
  CHECK(parameter(with_jump.parameters, "fs") == doctest::Approx(1.06).epsilon(0.15));
  CHECK(parameter(with_jump.parameters, "fd") == doctest::Approx(0.30).epsilon(0.5));
  // The deadband refuted by the likelihood ratio (one parameter more: chi-square(1) at 99 % is
  // 6.6; measured about 100), and the held-out part predicted no worse.
  REQUIRE(with_jump.error.estimation_samples == without.error.estimation_samples);
  const double lr = -prediction_bic_change(with_jump.error, without.error);
  CHECK(lr > 30.0);
  CHECK(with_jump.error.validation_variance < without.error.validation_variance);
}

// A linear valve (the benchmark's control, development seed 10): the deadband refitted to the
// prediction gains nothing worth a parameter.
TEST_CASE("on a linear valve the refitted deadband predicts no better than its parameter costs") {
  const RandomLoop r = draw_random_loop(10, "none");
  const LoopData d = simulate_random_loop(r);
  const ModelFit model = fit_of(d, "linear");
  const ModelFit trial = fit_of(d, "deadband");
  const PredictionRefitOptions po = options_for(trial);
  const PredictionRefit refit =
      refit_by_prediction(d.op, d.pv, d.sample_period(), trial, "deadband", po);
  REQUIRE(refit.ok);
  const PredictionError base =
      best_arx_prediction_error(d.pv, model.x_hat, po.nk_max, po.order, po.from, po.estimation_end);
  REQUIRE(base.ok);
  const double bic = prediction_bic_change(refit.error, base, 1.0);  // d: one parameter
  CHECK(bic > 0.0);
  CHECK(parameter(refit.parameters, "d") < 0.2);
}

TEST_CASE("refit_by_prediction refuses what it cannot refit") {
  const RandomLoop r = draw_random_loop(10, "none");
  const LoopData d = simulate_random_loop(r);
  const ModelFit trial = fit_of(d, "deadband");
  const PredictionRefitOptions po = options_for(trial);
  CHECK_FALSE(refit_by_prediction(d.op, d.pv, d.sample_period(), trial, "stiction", po).ok);
  const ModelFit linear = fit_of(d, "linear");
  CHECK_FALSE(refit_by_prediction(d.op, d.pv, d.sample_period(), linear, "deadband", po).ok);
  PredictionRefitOptions early = po;
  early.from = early.nk_max + early.order - 1;  // lags before the record
  CHECK_FALSE(refit_by_prediction(d.op, d.pv, d.sample_period(), trial, "deadband", early).ok);
  std::vector<double> short_u(d.op.begin(), d.op.end() - 1);
  CHECK_FALSE(refit_by_prediction(short_u, d.pv, d.sample_period(), trial, "deadband", po).ok);
}
