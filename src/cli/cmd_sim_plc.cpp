#include <chrono>
#include <iostream>
#include <thread>

#include "commands.hpp"
#include "stop_signal.hpp"
#include "valvediag/drivers/sim_plc.hpp"

namespace valvediag::cli {

void add_sim_plc(CLI::App& app, int& exit_code) {
  auto* cmd = app.add_subcommand(
      "sim-plc",
      "Serve simulated loops as Modbus TCP registers on 127.0.0.1 and as CAN frames on a Unix "
      "socket (a PLC for tests and demos)");
  cmd->footer(
      "Examples:\n"
      "  valvediag sim-plc --config configs/sim-site.toml\n"
      "  valvediag sim-plc --config configs/sim-site.toml --speed 50 --port 0   (free port, "
      "printed)\n"
      "  valvediag sim-plc --config configs/sim-can-site.toml --speed 10   (CAN frames on its "
      "unix: socket)\n"
      "With --speed S the loops run S times faster than real time; record them with sample "
      "periods divided by S.\nLoops on a socketcan bus are served as struct can_frame messages on "
      "a Unix SOCK_SEQPACKET socket\n(the bus's interface = \"unix:PATH\", or --can-socket PATH), "
      "never on a real CAN interface;\nrecord them with the same site file. Stops on Ctrl-C and "
      "prints the function codes it received.");
  struct Args {
    std::string config;
    double speed = 1.0;
    int port = -1;
    std::string duration;
    std::string can_socket;
  };
  auto a = std::make_shared<Args>();
  cmd->add_option("--config", a->config, "site TOML with simulate = \"scenario\" per loop")
      ->required();
  cmd->add_option("--speed", a->speed, "simulated seconds per real second")->capture_default_str();
  cmd->add_option("--port", a->port,
                  "TCP port on 127.0.0.1 (0: a free one; default: the config's)");
  cmd->add_option("--duration", a->duration, "stop after this long (\"30s\", \"10m\")");
  cmd->add_option("--can-socket", a->can_socket,
                  "Unix socket for the CAN frames of the site's socketcan bus (default: its "
                  "interface = \"unix:PATH\")");
  cmd->callback([a, &exit_code] {
    if (!(a->speed > 0) || a->speed > 1e4) throw UsageError("--speed must lie in (0, 10000]");
    if (a->port < -1 || a->port > 65535) throw UsageError("--port must lie in 0..65535");
    std::optional<double> duration;
    if (!a->duration.empty()) {
      duration = parse_duration(a->duration);
      if (!duration) throw UsageError("--duration '" + a->duration + "': give e.g. 30s or 10m");
    }
    const SiteConfig site = load_site_config(a->config);
    // The frames of a socketcan bus go to a Unix socket only, never onto a real CAN interface.
    if (a->can_socket.empty())
      for (const auto& b : site.buses) {
        if (b.kind != BusKind::socketcan || !can_unix_path(b).empty()) continue;
        for (const auto& l : site.loops)
          if (l.bus == b.name)
            throw UsageError(site.file + ":" + std::to_string(b.line) + ": bus '" + b.name +
                             "' has interface \"" + b.interface +
                             "\"; the simulated PLC sends CAN frames only on a Unix socket: set "
                             "interface = \"unix:/tmp/" +
                             b.name + ".sock\" or pass --can-socket PATH");
      }
    auto& stop = install_stop_signals();
    // A config it cannot serve: std::invalid_argument (exit 2); a port or path taken: exit 1.
    SimPlc plc(site, SimPlcOptions{a->speed, a->port, a->can_socket});
    plc.start();
    std::cout << "simulated PLC on 127.0.0.1:" << plc.port() << " (speed " << a->speed << "x):";
    for (const auto& l : site.loops)
      if (!l.simulate.empty()) std::cout << " " << l.name << "=" << l.simulate;
    std::cout << "\nport " << plc.port() << "\n";
    for (const auto& path : plc.can_sockets()) std::cout << "can-socket " << path << "\n";
    std::cout << "Ctrl-C stops." << std::endl;
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
    if (!plc.can_sockets().empty() || plc.can_clients() > 0)
      std::cout << "CAN: " << plc.can_clients()
                << " client(s); bytes received from them: " << plc.can_bytes_from_clients() << "\n";
    exit_code = kOk;
  });
}

}  // namespace valvediag::cli
