// Simulated PLC: runs the site's simulated loops (the closed-loop simulator of src/sim) in real
// time or faster and serves their OP, PV, SP, MV as registers over a real libmodbus TCP server on
// 127.0.0.1 (only loopback, ever), and as CAN frames on a frame-level transport: a descriptor
// (attach_can) or a Unix SOCK_SEQPACKET socket per CAN bus that any number of recorders connect
// to (interface = "unix:PATH", or SimPlcOptions::can_socket). It is configured like a real site
// (the same site TOML, plus `simulate`/`seed` per loop) and injects faults for the tests:
// delayed replies, timeouts, exception responses, dropped connections, server restarts, garbled
// frames and frozen registers. It counts every function code it receives; write function codes
// are refused with an exception (the PLC is read-only) and counted, as is any byte a CAN client
// sends.
#pragma once

#include <array>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <memory>
#include <vector>

#include "valvediag/drivers/site_config.hpp"
#include "valvediag/sim/loop_simulator.hpp"

namespace valvediag {

struct SimPlcOptions {
  double speed = 1.0;  // simulated seconds per real second
  int port = -1;       // -1: the bus's port from the config; 0: a free port
  // Unix socket for the frames of the site's one socketcan bus, instead of its "unix:" interface.
  std::string can_socket = {};
};

class SimPlc {
 public:
  // Serves the loops of the config's first modbus-tcp bus (each must have `simulate`) and those
  // of socketcan buses. Throws std::invalid_argument (file:line, the loop and bus named) on a
  // config it cannot serve: a loop on another Modbus bus (a second modbus-tcp bus, modbus-rtu,
  // modbus-rtu-over-tcp).
  SimPlc(SiteConfig site, SimPlcOptions options);
  ~SimPlc();
  SimPlc(const SimPlc&) = delete;
  SimPlc& operator=(const SimPlc&) = delete;

  // Binds 127.0.0.1:port and the CAN sockets and starts the simulation and the server; throws
  // std::runtime_error when the port or a socket path cannot be bound (the path named).
  void start();
  void stop();
  int port() const;  // the bound port (after start)
  // When step 0 was published; step k of a loop comes k * Ts / speed later.
  std::chrono::steady_clock::time_point started() const;

  // CAN frames of the socketcan loops are written to `fd` (struct can_frame each) at every
  // simulation step. The fd stays owned by the caller.
  void attach_can(int fd);
  // The Unix sockets served (after start), one per socketcan bus with a path.
  std::vector<std::string> can_sockets() const;
  std::uint64_t can_clients() const;             // CAN socket connections accepted so far
  std::uint64_t can_bytes_from_clients() const;  // anything a CAN client sent (must stay 0)

  // Faults added at run time count their `start_s` from this call.
  void add_fault(FaultConfig fault);
  void clear_faults();
  // Closes the listener and every connection now; listens again on the same port after down_s.
  void restart(double down_s);

  // Requests received per function code (index 0..255), and steps simulated per loop.
  std::array<std::uint64_t, 256> function_counts() const;
  std::uint64_t write_requests() const;  // function codes 5, 6, 15, 16, 22, 23
  std::uint64_t connections() const;     // connections accepted so far
  std::vector<std::uint64_t> steps() const;
  // The last sample of each served loop (in the config's loop order, served loops only).
  std::vector<LoopSample> latest() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace valvediag
