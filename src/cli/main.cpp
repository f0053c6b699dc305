// valvediag: identify sticky control valves from controller output and process variable data.
// The only place that prints or exits; the libraries throw and return.
#include <algorithm>
#include <cstdio>
#include <iostream>
#include <string>
#include <vector>

#include "commands.hpp"
#include "valvediag/drivers/site_config.hpp"
#include "valvediag/io/data_error.hpp"
#include "valvediag/model/model_spec.hpp"
#include "valvediag/sim/scenarios.hpp"

namespace {

// Edits (insert, delete, substitute) between two words: a typed command's nearest name.
std::size_t edit_distance(const std::string& a, const std::string& b) {
  std::vector<std::size_t> row(b.size() + 1);
  for (std::size_t j = 0; j <= b.size(); ++j) row[j] = j;
  for (std::size_t i = 1; i <= a.size(); ++i) {
    std::size_t diag = row[0];
    row[0] = i;
    for (std::size_t j = 1; j <= b.size(); ++j) {
      const std::size_t up = row[j];
      row[j] = std::min({row[j] + 1, row[j - 1] + 1, diag + (a[i - 1] == b[j - 1] ? 0 : 1)});
      diag = up;
    }
  }
  return row[b.size()];
}

// CLI11 says "A subcommand is required" for a mistyped one: name it and the nearest command.
std::string unknown_command_message(const CLI::App& app, const std::string& word) {
  std::string nearest;
  std::size_t best = word.size() / 2 + 2;  // farther than that is not a typo of it
  for (const auto* sub : app.get_subcommands({})) {
    const std::size_t d = edit_distance(word, sub->get_name());
    if (d < best) {
      best = d;
      nearest = sub->get_name();
    }
  }
  return "unknown command '" + word + "'" +
         (nearest.empty() ? ";" : "; did you mean '" + nearest + "'?") +
         " 'valvediag help' lists the commands";
}

}  // namespace

int main(int argc, char** argv) {
  using namespace valvediag::cli;
  CLI::App app{
      "valvediag: diagnose sticky control valves from OP/PV data with a Preisach-Hammerstein "
      "model.\n"
      "Run 'valvediag CMD --help' for a command's options and an example."};
  app.require_subcommand(1);
  app.set_version_flag("--version", "valvediag 0.1.0");
  int code = kOk;
  add_demo(app, code);
  add_fit(app, code);
  add_simulate(app, code);
  add_diagnose(app, code);
  add_ladder(app, code);
  add_sim_plc(app, code);
  add_record(app, code);
  add_export(app, code);
  add_report(app, code);
  add_sweep(app, code);
  add_sweep_merge(app, code);
  add_trend(app, code);
  add_import(app, code);
  add_serve(app, code);
  auto* help = app.add_subcommand("help", "List the commands, or explain one: valvediag help fit");
  std::string topic;
  help->add_option("command", topic, "command to explain");
  help->callback([&] {
    // App::help() would describe the parsed subcommand ('help' itself): ask the formatter.
    if (topic.empty()) {
      std::cout << app.get_formatter()->make_help(&app, "valvediag", CLI::AppFormatMode::Normal);
      return;
    }
    for (auto* sub : app.get_subcommands({}))
      if (sub->get_name() == topic) {
        // As `valvediag CMD --help` prints it, examples included.
        std::cout << sub->get_formatter()->make_help(sub, "valvediag " + topic,
                                                     CLI::AppFormatMode::Normal);
        return;
      }
    throw UsageError(unknown_command_message(app, topic));
  });
  try {
    if (argc > 1 && argv[1][0] != '-') {
      const auto subs = app.get_subcommands({});
      if (std::none_of(subs.begin(), subs.end(),
                       [&](const CLI::App* s) { return s->check_name(argv[1]); }))
        throw UsageError(unknown_command_message(app, argv[1]));
    }
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForVersion& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    app.exit(e);  // prints the message
    return kBadInput;
  } catch (const valvediag::DataError& e) {
    std::cerr << "error: " << e.what() << "\n";
    return kBadInput;
  } catch (const valvediag::ScenarioFileError& e) {
    std::cerr << "error: " << e.what() << "\n";
    return kBadInput;
  } catch (const valvediag::SiteConfigError& e) {
    std::cerr << "error: " << e.what() << "\n";
    return kBadInput;
  } catch (const UsageError& e) {
    std::cerr << "error: " << e.what() << "\n";
    return kBadInput;
  } catch (const std::invalid_argument& e) {
    std::cerr << "error: " << e.what() << "\n";
    return kBadInput;
  } catch (const std::exception& e) {
    std::cerr << "error: " << e.what() << "\n";
    return kFailure;
  }
  return code;
}
