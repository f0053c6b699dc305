// The paper's Example 1 reproduced with the simulator: structure and fitness beside the paper's.
#include <doctest/doctest.h>

#include <cstdio>

#include "../common/sanitized.hpp"
#include "valvediag/core/identification.hpp"
#include "valvediag/sim/scenarios.hpp"

using namespace valvediag;

TEST_CASE("paper Example 1: fitness at least 94 % over the full grid" *
          valvediag::test::release_only()) {
  const LoopData d = run_scenario(scenario_by_name("paper-ex1"), 1, 0);
  const auto r = identify(d.op, d.pv, FitOptions{});
  const auto& s = r.best.structure;
  std::printf("Example 1   paper: (na, nb, nk, L) = (1, 1, 5, 16), fitness 94.69 %%\n");
  std::printf("Example 1   ours:  (na, nb, nk, L) = (%d, %d, %d, %d), fitness %.2f %% in %.2f s\n",
              s.na, s.nb, s.nk, s.L, r.fitness_percent, r.elapsed_s);
  REQUIRE(r.status == IdentificationStatus::Ok);
  CHECK(r.fitness_percent >= 94.0);
  for (double w : r.model.mu) CHECK(w >= 0.0);
}

TEST_CASE("paper Example 1 at the paper's structure: joint solve vs the paper's alternation") {
  const LoopData d = run_scenario(scenario_by_name("paper-ex1"), 1, 0);
  const Structure st{1, 1, 5, 16};
  FitOptions joint;
  FitOptions paper;
  paper.method = FitMethod::Alternation;
  paper.stop_rule = StopRule::ParameterChange;
  paper.normalization = Normalization::PaperSign;
  FitOptions creep = paper;
  creep.stop_rule = StopRule::CostDecrease;
  creep.max_iterations = 3000;
  const auto rj = fit_configuration(d.op, d.pv, st, joint);
  const auto rp = fit_configuration(d.op, d.pv, st, paper);
  const auto rc = fit_configuration(d.op, d.pv, st, creep);
  std::printf(
      "(1,1,5,16) joint: %.2f %% (%d it)  paper rule: %.2f %% (%d it)  alternation to cost stop: "
      "%.2f %% (%d it)\n",
      rj.fitness_percent, rj.iterations, rp.fitness_percent, rp.iterations, rc.fitness_percent,
      rc.iterations);
  CHECK(rj.fitness_percent >= rp.fitness_percent - 0.5);
  CHECK(rj.cost <= rc.cost * (1 + 1e-3));
  CHECK(rj.iterations < rc.iterations);
}
