#include <iostream>

#include "commands.hpp"
#include "valvediag/csv_writer.hpp"
#include "valvediag/scenarios.hpp"

namespace valvediag::cli {

void add_simulate(CLI::App& app, int& exit_code) {
  auto* cmd = app.add_subcommand(
      "simulate", "Simulate a closed loop with a valve effect and write t,sp,op,pv,mv");
  cmd->footer(
      "Example:\n  valvediag simulate --scenario paper-ex1 --seed 1 --samples 3000 --out ex1.csv\n"
      "  valvediag simulate --config configs/scenarios/paper-ex1.toml --out ex1.csv\n"
      "  valvediag simulate --list");
  struct Args {
    std::string scenario, config, out;
    std::uint64_t seed = 1;
    std::size_t samples = 0;
    bool list = false;
  };
  auto a = std::make_shared<Args>();
  cmd->add_option("--scenario", a->scenario, "named scenario (see --list)");
  cmd->add_option("--config", a->config, "scenario TOML file (configs/scenarios/*.toml)")
      ->check(CLI::ExistingFile);
  cmd->add_option("--seed", a->seed, "random seed (noise, disturbances)")->capture_default_str();
  cmd->add_option("--samples", a->samples, "number of samples (default: the scenario's)");
  cmd->add_option("--out", a->out, "output CSV file");
  cmd->add_flag("--list", a->list, "list the scenarios and exit");
  cmd->callback([a, &exit_code] {
    if (a->list) {
      for (const auto& n : scenario_names()) {
        const auto s = scenario_by_name(n);
        std::cout << n << "\n    " << s.description << "\n";
      }
      exit_code = kOk;
      return;
    }
    if (a->scenario.empty() == a->config.empty())
      throw UsageError("give exactly one of --scenario NAME or --config FILE");
    if (a->out.empty()) throw UsageError("--out FILE.csv is required");
    const Scenario s =
        a->config.empty() ? scenario_by_name(a->scenario) : load_scenario_file(a->config);
    const LoopData d = run_scenario(s, a->seed, a->samples);
    write_loop_csv(a->out, d);
    std::cout << "wrote " << a->out << ": " << d.size() << " samples of scenario '" << s.name
              << "' (seed " << a->seed << ", Ts " << d.sample_period() << " s)\n";
    exit_code = kOk;
  });
}

}  // namespace valvediag::cli
