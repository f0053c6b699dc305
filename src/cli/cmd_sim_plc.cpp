#include <chrono>
#include <iostream>
#include <thread>

#include "commands.hpp"
#include "stop_signal.hpp"
#include "valvediag/sim_plc.hpp"

namespace valvediag::cli {

void add_sim_plc(CLI::App& app, int& exit_code) {
  auto* cmd = app.add_subcommand(
      "sim-plc",
      "Serve simulated loops as Modbus TCP registers on 127.0.0.1 (a PLC for tests and demos)");
  cmd->footer(
      "Examples:\n"
      "  valvediag sim-plc --config configs/sim-site.toml\n"
      "  valvediag sim-plc --config configs/sim-site.toml --speed 50 --port 0   (free port, "
      "printed)\n"
      "With --speed S the loops run S times faster than real time; record them with sample "
      "periods divided by S.\nStops on Ctrl-C and prints the function codes it received.");
  struct Args {
    std::string config;
    double speed = 1.0;
    int port = -1;
    std::string duration;
  };
  auto a = std::make_shared<Args>();
  cmd->add_option("--config", a->config, "site TOML with simulate = \"scenario\" per loop")
      ->required();
  cmd->add_option("--speed", a->speed, "simulated seconds per real second")->capture_default_str();
  cmd->add_option("--port", a->port,
                  "TCP port on 127.0.0.1 (0: a free one; default: the config's)");
  cmd->add_option("--duration", a->duration, "stop after this long (\"30s\", \"10m\")");
  cmd->callback([a, &exit_code] {
    if (!(a->speed > 0) || a->speed > 1e4) throw UsageError("--speed must lie in (0, 10000]");
    if (a->port < -1 || a->port > 65535) throw UsageError("--port must lie in 0..65535");
    std::optional<double> duration;
    if (!a->duration.empty()) {
      duration = parse_duration(a->duration);
      if (!duration) throw UsageError("--duration '" + a->duration + "': give e.g. 30s or 10m");
    }
    const SiteConfig site = load_site_config(a->config);
    auto& stop = install_stop_signals();
    SimPlc plc(site, SimPlcOptions{a->speed, a->port});
    plc.start();
    std::cout << "simulated PLC on 127.0.0.1:" << plc.port() << " (speed " << a->speed << "x):";
    for (const auto& l : site.loops)
      if (!l.simulate.empty()) std::cout << " " << l.name << "=" << l.simulate;
    std::cout << "\nport " << plc.port() << "\nCtrl-C stops." << std::endl;
    const auto t0 = std::chrono::steady_clock::now();
    while (!stop.load()) {
      if (duration &&
          std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() >= *duration)
        break;
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    plc.stop();
    const auto counts = plc.function_counts();
    std::cout << "stopped after " << plc.connections()
              << " connection(s); requests by function code:";
    bool any = false;
    for (std::size_t fc = 0; fc < counts.size(); ++fc)
      if (counts[fc]) {
        std::cout << " " << fc << ":" << counts[fc];
        any = true;
      }
    std::cout << (any ? "" : " none") << "; write requests (refused): " << plc.write_requests()
              << "\n";
    exit_code = kOk;
  });
}

}  // namespace valvediag::cli
