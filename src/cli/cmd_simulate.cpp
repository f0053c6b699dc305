#include <algorithm>
#include <iostream>

#include "commands.hpp"
#include "fit_runner.hpp"
#include "valvediag/io/atomic_file.hpp"
#include "valvediag/io/csv_writer.hpp"
#include "valvediag/sim/random_loop.hpp"
#include "valvediag/sim/scenarios.hpp"

namespace valvediag::cli {

void add_simulate(CLI::App& app, int& exit_code) {
  auto* cmd = app.add_subcommand(
      "simulate", "Simulate a closed loop with a valve effect and write t,sp,op,pv,mv");
  cmd->footer(
      "Example:\n  valvediag simulate --scenario paper-ex1 --seed 1 --samples 3000 --out ex1.csv\n"
      "  valvediag simulate --config configs/scenarios/paper-ex1.toml --out ex1.csv\n"
      "  valvediag simulate --list\n"
      "  valvediag simulate --random stiction --seed 7 --out case.csv   (a benchmark case: a\n"
      "                     drawn loop with `stiction` hidden; it prints the model to start from)");
  struct Args {
    std::string scenario, config, out, random, save_config;
    std::uint64_t seed = 1;
    std::size_t samples = 0;
    bool list = false;
  };
  auto a = std::make_shared<Args>();
  cmd->add_option("--scenario", a->scenario, "named scenario (see --list)");
  cmd->add_option("--config", a->config, "scenario TOML file (configs/scenarios/*.toml)")
      ->check(CLI::ExistingFile);
  cmd->add_option(
      "--random", a->random,
      "a randomized benchmark loop with this effect hidden (an effect name, none, pair; "
      "scripts/accuracy.sh): the loop is drawn from --seed");
  cmd->add_option("--save-config", a->save_config,
                  "also write the loop as a scenario TOML file (--config reads it back)");
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
    if (a->scenario.empty() + a->config.empty() + a->random.empty() != 2)
      throw UsageError("give exactly one of --scenario NAME, --config FILE or --random EFFECT");
    if (a->out.empty()) throw UsageError("--out FILE.csv is required");
    Scenario s;
    std::uint64_t seed = a->seed;
    if (!a->random.empty()) {
      const auto& cats = random_loop_categories();
      if (std::find(cats.begin(), cats.end(), a->random) == cats.end()) {
        std::string known;
        for (const auto& c : cats) known += (known.empty() ? "" : ", ") + c;
        throw UsageError("--random " + a->random + ": not a category (" + known + ")");
      }
      const RandomLoop r = draw_random_loop(a->seed, a->random);
      s = r.scenario;
      seed = r.noise_seed;
      if (a->samples == 0) a->samples = r.samples;
      std::cout << s.description << "\nstart model: " << r.start_model
                << "\ntrue model:  " << r.true_model << "\n";
      for (const auto& t : r.truth)
        std::cout << "true " << t.effect << " " << t.name << ": " << t.value << " " << t.unit
                  << "\n";
    } else {
      s = a->config.empty() ? scenario_by_name(a->scenario) : load_scenario_file(a->config);
    }
    if (!a->save_config.empty()) {
      write_file_atomically(a->save_config, scenario_to_toml(s));
      std::cout << "wrote " << a->save_config << "\n";
    }
    const LoopData d = run_scenario(s, seed, a->samples);
    write_loop_csv(a->out, d);
    std::cout << "wrote " << a->out << ": " << d.size() << " samples of scenario '" << s.name
              << "' (seed " << seed << ", Ts " << d.sample_period() << " s)\n";
    exit_code = kOk;
  });
}

}  // namespace valvediag::cli
