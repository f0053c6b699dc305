// valvediag: identify sticky control valves from controller output and process variable data.
// The only place that prints or exits; the libraries throw and return.
#include <cstdio>
#include <iostream>

#include "commands.hpp"
#include "valvediag/data_error.hpp"
#include "valvediag/model_spec.hpp"
#include "valvediag/scenarios.hpp"
#include "valvediag/site_config.hpp"

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
        std::cout << sub->get_formatter()->make_help(sub, "valvediag " + topic,
                                                     CLI::AppFormatMode::Sub);
        return;
      }
    throw UsageError("unknown command '" + topic + "'; 'valvediag help' lists them");
  });
  try {
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
