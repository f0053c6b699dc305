// Stiction quantification from identified Preisach models: properties on models built by hand,
// and a validation over simulated loops with known He parameters (truth vs estimate table).
#include <doctest/doctest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <string>
#include <vector>

#include "../common/sanitized.hpp"
#include "valvediag/core/identification.hpp"
#include "valvediag/core/stiction_quantification.hpp"
#include "valvediag/sim/scenarios.hpp"
#include "valvediag/sim/valve_effects.hpp"

using namespace valvediag;

namespace {

HammersteinModel valve_only(const PreisachGrid& g, std::vector<double> mu) {
  HammersteinModel m;
  m.grid = g;
  m.structure.L = g.L;
  m.mu = std::move(mu);
  m.a = {-0.5};
  m.b = {1.0};
  return m;
}

// A slow triangle between lo and hi, `cycles` times, then back to the middle.
std::vector<double> triangle(double lo, double hi, int cycles, double step) {
  std::vector<double> u;
  for (int c = 0; c < cycles; ++c) {
    for (double v = lo; v < hi; v += step) u.push_back(v);
    for (double v = hi; v > lo; v -= step) u.push_back(v);
  }
  return u;
}

bool within(double est, double truth) {
  return std::abs(est - truth) <= std::max(0.5, 0.2 * std::abs(truth));
}

// The same refined figures: overall, their interval's ends, and every visited region's.
void check_same_figures(const StictionQuantification& a, const StictionQuantification& b) {
  CHECK(a.overall.fs_percent == b.overall.fs_percent);
  CHECK(a.overall.fd_percent == b.overall.fd_percent);
  CHECK(a.interval.fs_lo == b.interval.fs_lo);
  CHECK(a.interval.fs_hi == b.interval.fs_hi);
  CHECK(a.interval.fd_lo == b.interval.fd_lo);
  CHECK(a.interval.fd_hi == b.interval.fd_hi);
  REQUIRE(a.regions.size() == b.regions.size());
  for (std::size_t i = 0; i < a.regions.size(); ++i) {
    CHECK(a.regions[i].valid == b.regions[i].valid);
    if (!a.regions[i].valid) continue;
    CHECK(a.regions[i].figures.fs_percent == b.regions[i].figures.fs_percent);
    CHECK(a.regions[i].figures.fd_percent == b.regions[i].figures.fd_percent);
  }
}

}  // namespace

TEST_CASE("He's Preisach weights give back He's fs and fd") {
  // fs + fd and fs - fd whole grid steps, the last slip inside the grid: the weights are He's
  // model exactly (Proposition 1). The probe's input is on the grid, so the band is known to a
  // grid step (the estimate is the middle of the interval that fits exactly): fs and fd are
  // within half a step.
  const PreisachGrid g{0.0, 100.0, 40};  // delta 2.5
  const double half = g.delta() / 2;
  for (auto [fs, fd] : {std::pair{8.75, 3.75}, std::pair{6.25, 1.25}}) {
    CAPTURE(fs);
    CAPTURE(fd);
    const PreisachWeights w = he_stiction_weights(g, fs, fd);
    const auto q = quantify_stiction(valve_only(g, w.mu));
    CHECK(q.valid);
    CHECK(q.stiction);
    CHECK(q.jump_identified);
    CHECK(!q.data_given);
    CHECK(std::abs(q.overall.fs_percent - fs) <= half);
    CHECK(std::abs(q.overall.fd_percent - fd) <= half);
    CHECK(std::abs(q.overall.band_percent - (fs + fd)) <= g.delta());
    CHECK(q.overall.fit_percent > 99.0);
    CHECK(q.scale == doctest::Approx(1.0).epsilon(0.02));
    REQUIRE(q.regions.size() == 3);
    for (const auto& r : q.regions) {
      CHECK(r.valid);
      CHECK(std::abs(r.figures.fs_percent - fs) <= g.delta());  // fewer reversals: a step
    }
  }
}

TEST_CASE("the figures do not depend on the output scale of the model") {
  const PreisachGrid g{20.0, 80.0, 24};  // delta 2.5
  PreisachWeights w = he_stiction_weights(g, 6.25, 1.25);
  const auto q1 = quantify_stiction(valve_only(g, w.mu));
  for (double& m : w.mu) m *= 0.013;  // as after ||b|| = 1 with a small process gain
  const auto q2 = quantify_stiction(valve_only(g, w.mu));
  CHECK(q2.overall.fs_percent == doctest::Approx(q1.overall.fs_percent));
  CHECK(q2.overall.fd_percent == doctest::Approx(q1.overall.fd_percent));
  CHECK(q2.scale == doctest::Approx(0.013 * q1.scale));
}

TEST_CASE("OP in other units than %: the figures in % of the OP span") {
  // The same valve (fs 8.75 %, fd 3.75 % of travel) on an OP scale of 0..200: 17.5 and 7.5 OP
  // units, whole steps of the grid (delta 2.5 OP units = 1.25 % of the span).
  const PreisachGrid g{0.0, 200.0, 80};
  const auto raw = quantify_stiction(valve_only(g, he_stiction_weights(g, 17.5, 7.5).mu));
  REQUIRE(raw.stiction);
  const auto q = in_percent_of_span(raw, OpRange{0.0, 200.0});
  const double half = 1.25 / 2;
  CHECK(std::abs(q.overall.fs_percent - 8.75) <= half);
  CHECK(std::abs(q.overall.fd_percent - 3.75) <= half);
  CHECK(q.overall.band_percent == doctest::Approx(raw.overall.band_percent / 2));
  CHECK(q.overall.jump_percent == doctest::Approx(raw.overall.jump_percent / 2));
  CHECK(q.resolution_percent == doctest::Approx(1.25));
  CHECK(q.scale == doctest::Approx(2 * raw.scale));  // output per % of span, not per OP unit
  CHECK(q.op_lo == raw.op_lo);                       // OP ranges stay in OP units
  CHECK(q.op_hi == raw.op_hi);
  REQUIRE(q.regions.size() == raw.regions.size());
  for (std::size_t i = 0; i < q.regions.size(); ++i) {
    CHECK(q.regions[i].figures.fs_percent ==
          doctest::Approx(raw.regions[i].figures.fs_percent / 2));
    CHECK(q.regions[i].op_lo == raw.regions[i].op_lo);
  }
  CHECK(q.summary.find("of the OP span 0.0:200.0") != std::string::npos);
  CHECK_THROWS_AS(in_percent_of_span(raw, OpRange{5.0, 5.0}), std::invalid_argument);
  CHECK_THROWS_AS(in_percent_of_span(raw, OpRange{0.0, std::nan("")}), std::invalid_argument);
}

TEST_CASE("a valve without hysteresis shows no stiction") {
  const PreisachGrid g{0.0, 100.0, 20};
  std::vector<double> mu(static_cast<std::size_t>(g.relay_count()), 0.0);
  for (int i = 1; i <= g.L; ++i) mu[static_cast<std::size_t>(g.relay_index(i, i))] = 2.5;
  const auto q = quantify_stiction(valve_only(g, mu));
  CHECK(q.valid);
  CHECK(!q.stiction);
  CHECK(q.overall.fs_percent == 0.0);
  CHECK(q.overall.band_percent == 0.0);
  CHECK(q.summary.find("no stiction") != std::string::npos);
  for (const auto& r : q.regions) CHECK(!r.stiction);
}

TEST_CASE("an asymmetric valve gives different figures per region") {
  // Severe stiction (He 10, 4) on the low half of the travel, mild (He 2.5, 0.5) on the high
  // half: the sum of two He weight sets, each kept to its half.
  const PreisachGrid g{0.0, 100.0, 40};
  const auto severe = he_stiction_weights(g, 10.0, 4.0);
  const auto mild = he_stiction_weights(g, 2.5, 1.25);
  std::vector<double> mu(severe.mu.size(), 0.0);
  for (int i = 1; i <= g.L; ++i)
    for (int j = i; j <= g.L; ++j) {
      const auto k = static_cast<std::size_t>(g.relay_index(i, j));
      const double centre = g.umin + (i + j) / 2.0 * g.delta();
      mu[k] = centre < 50.0 ? severe.mu[k] : mild.mu[k];
    }
  const auto q = quantify_stiction(valve_only(g, mu));
  REQUIRE(q.regions.size() == 3);
  const auto& low = q.regions.front().figures;
  const auto& high = q.regions.back().figures;
  CHECK(low.band_percent > 2 * high.band_percent);
  CHECK(low.fs_percent > 7.0);
  CHECK(high.fs_percent < 4.0);
}

TEST_CASE("regions the data did not visit are flagged, the probe stays in the visited range") {
  const PreisachGrid g{0.0, 100.0, 40};
  const auto w = he_stiction_weights(g, 5.0, 2.5);
  // The OP spends its time low, with one excursion to the top.
  std::vector<double> u = triangle(5.0, 30.0, 6, 0.5);
  for (double v = 40.0; v < 95.0; v += 0.5) u.push_back(v);
  for (double v = 95.0; v > 20.0; v -= 0.5) u.push_back(v);
  const auto q = quantify_stiction(valve_only(g, w.mu), u);
  CHECK(q.data_given);
  CHECK(q.op_lo == doctest::Approx(5.0));
  CHECK(q.op_hi == doctest::Approx(95.0).epsilon(0.01));
  REQUIRE(q.regions.size() == 3);
  CHECK(q.regions[0].visited);
  CHECK(q.regions[0].data_reversals >= 6);
  CHECK(!q.regions[1].visited);  // crossed once, no reversal there
  CHECK(!q.regions[1].valid);
  CHECK(std::abs(q.overall.fs_percent - 5.0) <= 1.25);  // half a grid step
  CHECK(std::abs(q.overall.fd_percent - 2.5) <= 1.25);
  // Too little data: less than two grid levels.
  const auto flat = quantify_stiction(valve_only(g, w.mu), std::vector<double>(100, 50.0));
  CHECK(!flat.valid);
  CHECK(!flat.stiction);
  CHECK(std::isnan(flat.overall.fs_percent));
  // Weights that do not match the grid are an error.
  CHECK_THROWS_AS(quantify_stiction(valve_only(g, {1.0, 2.0})), std::invalid_argument);
}

namespace {

struct Case {
  // "ex1": the paper's Example 1 loop; "fopdt": a faster temperature-like loop; "so": a
  // second-order loop; "int": an integrating (level-like) loop.
  std::string loop;
  double fs, fd, noise;
  std::uint64_t seed;
};

double process_gain(const std::string& loop) {
  return loop == "ex1" ? 3.8163 : loop == "fopdt" ? 1.2 : loop == "so" ? 1.5 : 1.0;
}

// The loop of a case: the scenario's controller and process with He's valve, the noise level,
// and set-point steps large enough that the OP sweeps more than 2 fs (so that the data says how
// the band splits into fs and fd).
Scenario case_loop(const Case& c) {
  Scenario s = scenario_by_name(c.loop == "ex1"     ? "paper-ex1"
                                : c.loop == "fopdt" ? "deadband"
                                : c.loop == "so"    ? "second-order"
                                                    : "integrating");
  s.loop.valve = {HeStiction(c.fs, c.fd)};
  s.loop.measurement_noise_std = c.noise;
  s.loop.disturbances = {};
  const double step = process_gain(c.loop) * std::max(2.2 * c.fs, 6.0);  // OP move of 2.2 fs
  const double pv0 = 50.0;
  const double T = c.loop == "ex1" ? 500.0 : 600.0;
  s.loop.setpoint = {{0.0, pv0},
                     {0.1 * T, pv0 + step / 2},
                     {T, pv0 - step / 2},
                     {2 * T, pv0 + step / 2},
                     {3 * T, pv0}};
  s.default_samples = 3000;
  return s;
}

FitOptions case_fit_options(const std::string& loop) {
  FitOptions o;
  o.na_max = 2;
  o.nb_max = loop == "so" ? 2 : 1;
  o.nk_min = loop == "ex1" ? 3 : 2;
  o.nk_max = loop == "ex1" ? 7 : 6;
  o.L_min = 12;
  o.L_max = 30;
  return o;
}

}  // namespace

TEST_CASE("validation: He's fs and fd recovered from identified Preisach models of closed loops" *
          valvediag::test::accuracy()) {
  // Cases 1-12 were chosen before the method was refined; 13-19 were added afterwards to check
  // that it generalises (other seeds, a second-order and an integrating process, small bands).
  const std::vector<Case> cases = {
      {"ex1", 8.4, 3.5243, 0.1, 1},  {"ex1", 8.4, 3.5243, 0.3, 2},  {"ex1", 4.0, 1.0, 0.1, 3},
      {"ex1", 6.0, 3.0, 0.2, 4},     {"ex1", 3.0, 1.5, 0.05, 5},    {"ex1", 10.0, 2.0, 0.1, 6},
      {"fopdt", 8.0, 3.0, 0.1, 7},   {"fopdt", 5.0, 2.0, 0.1, 8},   {"fopdt", 3.0, 1.0, 0.05, 9},
      {"fopdt", 6.0, 1.0, 0.3, 10},  {"fopdt", 10.0, 4.0, 0.2, 11}, {"fopdt", 4.0, 3.0, 0.1, 12},
      {"ex1", 8.4, 3.5243, 0.1, 21}, {"fopdt", 6.0, 2.0, 0.2, 22},  {"so", 5.0, 2.0, 0.1, 23},
      {"so", 8.0, 1.5, 0.2, 24},     {"int", 5.0, 2.0, 0.1, 25},    {"so", 3.0, 0.5, 0.1, 26},
      {"fopdt", 2.0, 1.0, 0.05, 27},
  };
  const auto start = std::chrono::steady_clock::now();
  int ok_count = 0, preisach_ok = 0;
  std::printf(
      "\nstiction quantification (He truth vs estimate, %% of travel): Preisach probe, "
      "then refined on the data\n");
  int covered = 0, regions = 0, regions_covered = 0;
  std::printf("%-4s %-5s %5s %3s %5s | %5s %5s | %5s %5s | %5s %5s | %5s %-4s | %-11s %-11s %s\n",
              "case", "loop", "noise", "L", "delta", "fs", "fd", "P fs^", "P fd^", "fs^", "fd^",
              "fit", "ok", "fs 95 %", "fd 95 %", "N_eff");
  std::size_t run = 0;
  for (std::size_t i = 0; i < cases.size(); ++i, ++run) {
    const Case& c = cases[i];
    const LoopData d = run_scenario(case_loop(c), c.seed, 0);
    const IdentificationResult r = identify(d.op, d.pv, case_fit_options(c.loop));
    const auto q = quantify_stiction(r.model, d.op, d.pv);
    CHECK(q.refined);
    const bool ok =
        q.stiction && within(q.overall.fs_percent, c.fs) && within(q.overall.fd_percent, c.fd);
    ok_count += ok;
    preisach_ok += within(q.preisach.fs_percent, c.fs) && within(q.preisach.fd_percent, c.fd);
    const StictionInterval& iv = q.interval;
    REQUIRE(iv.valid);
    CHECK(iv.fs_lo <= q.overall.fs_percent);
    CHECK(q.overall.fs_percent <= iv.fs_hi);
    CHECK(iv.fd_lo <= q.overall.fd_percent);
    CHECK(q.overall.fd_percent <= iv.fd_hi);
    CHECK(iv.fd_hi <= iv.fs_hi);
    CHECK_FALSE(iv.fs_open_above);  // the slips bound fs: below the OP span
    // A valve with one band everywhere: each region's range holds its own fs, and mostly the
    // truth.
    for (const StictionRegion& g : q.regions) {
      if (!g.valid) continue;
      REQUIRE(std::isfinite(g.fs_lo));
      CHECK(g.fs_lo <= g.figures.fs_percent);
      CHECK(g.figures.fs_percent <= g.fs_hi);
      ++regions;
      regions_covered += g.fs_lo <= c.fs && c.fs <= g.fs_hi;
    }
    const bool inside =
        iv.fs_lo <= c.fs && c.fs <= iv.fs_hi && iv.fd_lo <= c.fd && c.fd <= iv.fd_hi;
    covered += inside;
    std::printf(
        "%-4zu %-5s %5.2f %3d %5.2f | %5.2f %5.2f | %5.2f %5.2f | %5.2f %5.2f | %5.1f %-4s | "
        "%5.2f-%-5.2f %5.2f-%-5.2f %5.0f%s\n",
        i + 1, c.loop.c_str(), c.noise, r.model.grid.L, q.resolution_percent, c.fs, c.fd,
        q.preisach.fs_percent, q.preisach.fd_percent, q.overall.fs_percent, q.overall.fd_percent,
        q.overall.fit_percent, ok ? "ok" : "MISS", iv.fs_lo, iv.fs_hi, iv.fd_lo, iv.fd_hi,
        iv.effective_samples, inside ? "" : " truth outside");
  }
  const double elapsed =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::printf(
      "%d of %zu within 20 %% or 0.5 %% of travel (Preisach probe alone: %d); the truth inside "
      "the 95 %% interval on %d; regions: the truth's fs inside the region's range on %d of %d "
      "(%.1f s)\n",
      ok_count, run, preisach_ok, covered, regions_covered, regions, elapsed);
  // Measured (Release): 19 of 19 refined; the Preisach probe alone 10 of 19 (5 of the first 12):
  // its band is known to a grid step only and a fitted lattice's weights shorten it, even fitted
  // to the noise-free valve position. The goal is 90 %; the floor is the measurement.
  CHECK(ok_count >= static_cast<int>(run));  // 19 of 19 in Release
  // Measured: 19 of 19. On these loops the cost's valleys are narrower than the lattice step,
  // so the interval is the step's bracket around the estimate, and the truth is inside it
  // because the estimate is within a step of it.
  CHECK(10 * covered >= 9 * static_cast<int>(run));
  // Measured: 46 of 49 regions hold the truth (the ranges are local, and a region's band is
  // fitted with the others held).
  CHECK(regions - regions_covered <= 3);
}

// The interval says how well the data fix the figures: the same loop with more measurement noise
// (and so a flatter cost) must give a wider one, still holding the truth.
TEST_CASE("the stiction interval widens with the measurement noise" * valvediag::test::accuracy()) {
  double previous = 0.0, first = 0.0;
  for (double noise : {0.1, 1.0, 3.0}) {
    CAPTURE(noise);
    const Case c{"fopdt", 5.0, 2.0, noise, 8};
    const LoopData d = run_scenario(case_loop(c), c.seed, 0);
    const IdentificationResult r = identify(d.op, d.pv, case_fit_options(c.loop));
    const auto q = quantify_stiction(r.model, d.op, d.pv);
    REQUIRE(q.interval.valid);
    const StictionInterval& iv = q.interval;
    std::printf("noise %.1f: fs %.2f [%.2f, %.2f], fd %.2f [%.2f, %.2f], N_eff %.0f, %zu points\n",
                noise, q.overall.fs_percent, iv.fs_lo, iv.fs_hi, q.overall.fd_percent, iv.fd_lo,
                iv.fd_hi, iv.effective_samples, iv.points);
    CHECK(iv.fs_lo <= c.fs);
    CHECK(c.fs <= iv.fs_hi);
    // Measured: 0.20, 0.20 (the lattice step's bracket: the valley is still a needle), 1.00.
    CHECK(iv.fs_hi - iv.fs_lo >= previous);
    if (noise > 2) CHECK(iv.fs_hi - iv.fs_lo > 4 * first);
    if (first == 0) first = iv.fs_hi - iv.fs_lo;
    previous = iv.fs_hi - iv.fs_lo;
  }
}

// Paper Example 1 as `fit` sees it by default: 3000 samples, the full grid of orders. The coarse
// search decides which valleys are polished; scored with the linear part fitted to the Preisach
// valve it can rank the true valley below ones at fd 1.1-1.4, scored with each candidate's own
// poles the true one ranks among the first. Measured on seeds 1-40 with 4 valleys polished: own
// poles 40 of 40 within 20 %; the Preisach valve's poles miss fd on seeds 24, 27 and 29 (and
// were 1-2 % of travel low on fs on many others). With the default 8 both find seed 24's, and so
// does the coarse lattice over every band: the window's ranking is compared without it.
TEST_CASE("paper Example 1 with the default orders: each candidate's own poles find the true fd" *
          valvediag::test::release_only()) {
  const LoopData d = run_scenario(scenario_by_name("paper-ex1"), 24, 3000);
  const IdentificationResult r = identify(d.op, d.pv, FitOptions{});
  const auto q = quantify_stiction(r.model, d.op, d.pv);
  REQUIRE(q.refined);
  CHECK(within(q.overall.fs_percent, 8.4));
  CHECK(within(q.overall.fd_percent, 3.5243));
  CHECK(q.overall.fd_percent == doctest::Approx(3.5243).epsilon(0.05));
  StictionQuantificationOptions four;
  four.refine_starts = 4;
  four.global_starts = 0;
  const auto q4 = quantify_stiction(r.model, d.op, d.pv, four);
  CHECK(q4.overall.fd_percent == doctest::Approx(3.5243).epsilon(0.05));
  // With the Preisach valve's poles for every candidate the split is missed (measured: fs 7.82,
  // fd 1.20). Should that ever find it, this case no longer tests the own poles: take another seed.
  StictionQuantificationOptions preisach_poles = four;
  preisach_poles.refine_own_linear = false;
  const auto q1 = quantify_stiction(r.model, d.op, d.pv, preisach_poles);
  CHECK(!within(q1.overall.fd_percent, 3.5243));
}

// The refinement's grid, polish and region grids run on several threads, each worker with a fit
// of its own; the figures must be those of one thread, and the remembered costs those computed.
TEST_CASE("the refined figures do not depend on the threads or on remembered costs" *
          valvediag::test::release_only()) {
  const LoopData d = run_scenario(scenario_by_name("paper-ex1"), 2, 3000);
  FitOptions fo;
  fo.na_max = fo.nb_max = 2;
  fo.nk_max = 10;
  const IdentificationResult r = identify(d.op, d.pv, fo);
  StictionQuantificationOptions one, three, every;
  one.threads = 1;
  three.threads = 3;  // more workers than this machine's cores, and an odd split
  every.threads = 2;
  every.reuse_costs = false;
  const auto a = quantify_stiction(r.model, d.op, d.pv, one);
  REQUIRE(a.refined);
  CHECK(within(a.overall.fs_percent, 8.4));
  CHECK(within(a.overall.fd_percent, 3.5243));
  for (const auto& b : {quantify_stiction(r.model, d.op, d.pv, three),
                        quantify_stiction(r.model, d.op, d.pv, every)}) {
    check_same_figures(b, a);
    CHECK(b.overall.fit_percent == a.overall.fit_percent);
    CHECK(b.interval.points == a.interval.points);
  }
}

// The taps' Gram block from shifted sums (one dot product per lag difference and the window's
// ends) against every product summed: a wrong end row or lag moves every cost, so the fit and
// the figures would differ.
TEST_CASE("the taps' products from shifted sums give the plain sums' figures") {
  const LoopData d = run_scenario(scenario_by_name("paper-ex1"), 3, 3000);
  FitOptions fo;
  fo.nb_min = fo.nb_max = 3;  // several taps, so the shifted sums are used
  const IdentificationResult r = identify(d.op, d.pv, fo);
  REQUIRE(r.model.b.size() == 3);
  const auto a = quantify_stiction(r.model, d.op, d.pv);
  REQUIRE(a.refined);
#ifndef VALVEDIAG_SANITIZED  // sanitized, the shifted sums run once (a); comparing is for Release
  StictionQuantificationOptions plain;
  plain.plain_sums = true;
  const auto b = quantify_stiction(r.model, d.op, d.pv, plain);
  REQUIRE(b.refined);
  check_same_figures(a, b);
  CHECK(a.overall.fit_percent == doctest::Approx(b.overall.fit_percent).epsilon(1e-9));
#endif
}

TEST_CASE("an asymmetric valve in closed loop: the region table shows where it sticks more" *
          valvediag::test::release_only()) {
  // PositionDependentStiction: fs 8, fd 3 below 40 % of travel, fs 3, fd 1 above 60 %
  // (interpolated between), in the fast loop with the OP held low, then high, then low.
  Scenario s = scenario_by_name("deadband");
  s.loop.valve = {PositionDependentStiction({{40.0, 8.0, 3.0}, {60.0, 3.0, 1.0}})};
  s.loop.disturbances = {};
  s.loop.setpoint = {{0.0, 50.0}, {100.0, 30.0}, {1000.0, 70.0}, {2000.0, 30.0}, {2600.0, 50.0}};
  const std::uint64_t seeds[] = {31, 32};
  for (std::uint64_t seed : seeds) {
    CAPTURE(seed);
    const LoopData d = run_scenario(s, seed, 3000);
    const IdentificationResult r = identify(d.op, d.pv, case_fit_options("fopdt"));
    const auto q = quantify_stiction(r.model, d.op, d.pv);
    REQUIRE(q.regions.size() == 3);
    std::printf("\nasymmetric valve, seed %d: truth fs 8 fd 3 below 40 %%, fs 3 fd 1 above 60 %%\n",
                static_cast<int>(seed));
    std::printf("%12s | %5s %5s | %5s %5s | %-11s | %s\n", "OP region", "P fs^", "P fd^", "fs^",
                "fd^", "fs 95 %", "valid");
    for (const auto& g : q.regions)
      std::printf("%5.1f-%5.1f | %5.2f %5.2f | %5.2f %5.2f | %5.2f-%-5.2f | %s\n", g.op_lo, g.op_hi,
                  g.preisach.fs_percent, g.preisach.fd_percent, g.figures.fs_percent,
                  g.figures.fd_percent, g.fs_lo, g.fs_hi, g.valid ? "yes" : "no");
    const auto& low = q.regions.front();
    const auto& high = q.regions.back();
    REQUIRE(low.valid);
    REQUIRE(high.valid);
    for (const auto& g : q.regions) {
      REQUIRE(std::isfinite(g.fs_lo));
      CHECK(g.fs_lo <= g.figures.fs_percent);
      CHECK(g.figures.fs_percent <= g.fs_hi);
    }
    // The ranges say which figures the data fix: measured low 7.85-8.25 and 7.22-7.92, high
    // 6.35-8.45 and 4.50-8.90 (the high region's band is placed by fewer, smaller slips).
    CHECK(high.fs_hi - high.fs_lo > low.fs_hi - low.fs_lo);
    // The regions are equal parts of the visited OP range, not the valve's: the middle one mixes
    // both frictions and the outer ones are only roughly the truth (measured: low 5.8/4.2 and
    // 8.0/3.6, high 3.1/1.1 and 6.8/2.1), so only the order is asserted.
    CHECK(low.figures.band_percent > high.figures.band_percent);
    CHECK(low.figures.fs_percent > 5.0);
  }
}

// Measurement noise biases the Preisach model (equation error), and with it the probe's window:
// at noise 1 the probe says fs 13.7 for a true 5. The coarse lattice over every band finds the
// true valley anyway on most of these loops; it only adds valleys to polish, so its fit is never
// worse than the window's alone.
TEST_CASE("noisy loops: the coarse lattice finds bands the biased probe's window misses" *
          valvediag::test::accuracy()) {
  const std::vector<Case> cases = {
      {"ex1", 8.4, 3.5243, 1.0, 1}, {"ex1", 4.0, 1.0, 1.0, 3},   {"ex1", 6.0, 3.0, 1.0, 4},
      {"fopdt", 8.0, 3.0, 1.0, 7},  {"fopdt", 5.0, 2.0, 1.0, 8}, {"fopdt", 3.0, 1.0, 1.0, 9},
      {"so", 5.0, 2.0, 1.0, 23},    {"so", 8.0, 1.5, 1.0, 24},   {"int", 5.0, 2.0, 1.0, 25},
      {"fopdt", 6.0, 2.0, 2.0, 22}, {"ex1", 10.0, 2.0, 2.0, 6},  {"so", 3.0, 0.5, 0.5, 26},
  };
  StictionQuantificationOptions window;
  window.global_starts = 0;
  int ok_window = 0, ok = 0;
  std::size_t run = 0;
  std::printf("\nnoisy loops: He truth vs the probe's window alone vs with the coarse lattice\n");
  std::printf("%-5s %5s | %5s %5s | %5s %5s | %5s %5s %-4s %5s | %5s %5s %-4s %5s | %s\n", "loop",
              "noise", "fs", "fd", "P fs^", "P fd^", "fs^", "fd^", "", "fit", "fs^", "fd^", "",
              "fit", "fs 95 %");
  for (std::size_t i = 0; i < cases.size(); ++i, ++run) {
    const Case& c = cases[i];
    const LoopData d = run_scenario(case_loop(c), c.seed, 0);
    const IdentificationResult r = identify(d.op, d.pv, case_fit_options(c.loop));
    const auto a = quantify_stiction(r.model, d.op, d.pv, window);
    const auto b = quantify_stiction(r.model, d.op, d.pv);
    const bool a_ok = within(a.overall.fs_percent, c.fs) && within(a.overall.fd_percent, c.fd);
    const bool b_ok = within(b.overall.fs_percent, c.fs) && within(b.overall.fd_percent, c.fd);
    ok_window += a_ok;
    ok += b_ok;
    std::printf(
        "%-5s %5.1f | %5.2f %5.2f | %5.2f %5.2f | %5.2f %5.2f %-4s %5.1f | %5.2f %5.2f %-4s %5.1f "
        "| "
        "%5.2f-%.2f\n",
        c.loop.c_str(), c.noise, c.fs, c.fd, a.preisach.fs_percent, a.preisach.fd_percent,
        a.overall.fs_percent, a.overall.fd_percent, a_ok ? "ok" : "MISS", a.overall.fit_percent,
        b.overall.fs_percent, b.overall.fd_percent, b_ok ? "ok" : "MISS", b.overall.fit_percent,
        b.interval.fs_lo, b.interval.fs_hi);
    CHECK(b.overall.fit_percent >= a.overall.fit_percent - 1e-9);
  }
  std::printf("within 20 %% or 0.5 %% of travel: window alone %d, with the lattice %d of %zu\n",
              ok_window, ok, run);
  // Measured (Release): 2 and 11 of 12. Steps: the lattice alone 7; with Steiglitz-McBride's
  // poles 8 (the integrating loop left fs 21); its best cells at a quarter step 9 (so 8/1.5);
  // lattice starts beyond the window's polish but within 2 lattice steps of its starts, polished
  // from the poles that scored them best, 11 (ex1 6/3 at noise 1, 10/2 at noise 2). The miss,
  // fopdt 8/3: the truth fits the data better than the estimate (cost 2923 against 7185), but
  // the lattice points near it rank about 1250th of 3080: its pit is narrower than a cell.
  CHECK(ok >= 11);
  CHECK(ok >= ok_window + 8);
}

// The probe's band is known to a grid step, and NNLS shortens it: a valve that sticks by 2 % (it
// jumps to the OP once they differ by 2 %) read "below the grid step 1.36 %". Refined on the data
// the band is found; a linear valve in the same kind of loop stays without stiction, and its
// interval reaches fs = 0.
TEST_CASE("a band below the probe's grid step is refined on the data" *
          valvediag::test::release_only()) {
  std::vector<double> op, pv;
  double x = 50, y = 0;
  for (int k = 0; k < 1200; ++k) {
    const double u = 50 + 10 * std::sin(0.02 * k) + 3 * std::sin(0.13 * k);
    if (std::abs(u - x) > 2.0) x = u;
    y = 0.9 * y + 0.1 * (x - 50);
    op.push_back(u);
    pv.push_back(y);
  }
  const IdentificationResult r = identify(op, pv, FitOptions{});
  StictionQuantificationOptions probe_only;
  probe_only.refine_unresolved = false;
  const auto p = quantify_stiction(r.model, op, pv, probe_only);
  CHECK(!p.stiction);  // measured: below the step 1.36 %; should it resolve, the case is moot
  CHECK(!p.refined);
  const auto q = quantify_stiction(r.model, op, pv);
  REQUIRE(q.refined);
  CHECK(q.stiction);
  CHECK(q.overall.fs_percent == doctest::Approx(2.0).epsilon(0.05));
  CHECK(q.overall.fd_percent < 0.1);
  CHECK(q.interval.fs_lo > 1.8);
  CHECK(q.interval.fs_hi < 2.2);

  const LoopData d = run_scenario(scenario_by_name("paper-ex1-linear"), 1, 3000);
  const IdentificationResult lr = identify(d.op, d.pv, FitOptions{});
  const auto l = quantify_stiction(lr.model, d.op, d.pv);
  std::printf("linear valve: refined %d, fs %.3f %%, interval %.2f-%.2f %%\n", l.refined,
              l.overall.fs_percent, l.interval.fs_lo, l.interval.fs_hi);
  CHECK(!l.stiction);
  REQUIRE(l.refined);
  CHECK(l.interval.fs_lo == 0.0);
}
