#include <chrono>
#include <cstdio>
#include <iostream>

#include "commands.hpp"
#include "fit_runner.hpp"
#include "valvediag/scenarios.hpp"

namespace valvediag::cli {

void add_demo(CLI::App& app, int& exit_code) {
  auto* cmd = app.add_subcommand(
      "demo",
      "Simulate the paper's Example 1 (PI loop, He stiction), identify it, compare with the paper");
  cmd->footer("Example:\n  valvediag demo\n  valvediag demo --seed 7 --json ex1.json");
  struct Args {
    std::uint64_t seed = 1;
    std::string json;
  };
  auto a = std::make_shared<Args>();
  cmd->add_option("--seed", a->seed, "random seed of the simulation")->capture_default_str();
  cmd->add_option("--json", a->json, "also write the fit result as JSON");
  cmd->callback([a, &exit_code] {
    const Scenario s = scenario_by_name("paper-ex1");
    std::cout << "Simulating scenario 'paper-ex1': " << s.description << "\n";
    const LoopData d = run_scenario(s, a->seed, 0);
    std::cout
        << "Identifying over the paper's full grid (na <= 3, nb <= 3, nk <= 10, L <= 20) ...\n\n";
    FitOptions fo;
    FitRun run = run_fit(d, fo, "pv");
    std::cout << run.summary << "\n";
    const auto& st = run.result.best.structure;
    std::printf("%-22s %-28s %s\n", "", "structure (na, nb, nk, L)", "fitness");
    std::printf("%-22s %-28s %.2f %%\n", "paper (Example 1)", "(1, 1, 5, 16)", 94.69);
    char ours[64];
    std::snprintf(ours, sizeof ours, "(%d, %d, %d, %d)", st.na, st.nb, st.nk, st.L);
    std::printf("%-22s %-28s %.2f %%   in %.2f s\n", "valvediag", ours, run.result.fitness_percent,
                run.result.elapsed_s);
    if (!a->json.empty()) {
      write_text(a->json, run.json.dump(2) + "\n");
      std::cout << "wrote " << a->json << "\n";
    }
    exit_code = run.result.status == IdentificationStatus::Ok ? kOk : kNoModel;
  });
}

}  // namespace valvediag::cli
