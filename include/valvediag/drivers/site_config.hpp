// Site configuration: the buses of a plant and where each control loop's OP, PV, SP (optional
// MV, MODE) live on them. Read from TOML (configs/*.toml document every key); field names follow
// Telegraf's Modbus input (controller, slave_id, transmission_mode, register, address, type,
// data_type, byte_order, scale) and DBC files (start_bit, length, factor, offset). Every problem is
// reported with file, line and what to change before any bus traffic.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "valvediag/drivers/value_codec.hpp"

namespace valvediag {

// modbus_rtu_over_tcp: RTU frames (with CRC, no MBAP header) on a TCP stream, as serial-to-Ethernet
// gateways pass them on; Telegraf's transmission_mode = "RTUoverTCP".
enum class BusKind : std::uint8_t { modbus_tcp, modbus_rtu, socketcan, modbus_rtu_over_tcp };
std::string to_string(BusKind k);

struct BusConfig {
  std::string name;
  BusKind kind = BusKind::modbus_tcp;
  int line = 0;  // where the [[bus]] table starts, for messages
  // Modbus TCP, RTU over TCP
  std::string host = "127.0.0.1";
  int port = 502;
  // Modbus RTU
  std::string device;  // /dev/ttyUSB0
  int baud_rate = 19200;
  char parity = 'N';  // N, E, O
  int data_bits = 8;
  int stop_bits = 1;
  // Modbus (all three)
  int slave_id = 1;
  double timeout_s = 0.5;        // response timeout per request
  int retries = 1;               // extra attempts of a failed request before the value is flagged
  double pause_s = 0.0;          // pause between requests (slow serial gateways)
  double reconnect_max_s = 1.0;  // backoff cap between reconnection attempts
  // SocketCAN
  std::string interface;  // can0, or "unix:PATH": the simulated PLC's frame socket (a mock)
  std::string dbc;        // DBC file (resolved against the config's directory)
};
// The socket path of a socketcan bus whose interface is "unix:PATH" (resolved against the
// config's directory); "" for a real CAN interface or a Modbus bus.
std::string can_unix_path(const BusConfig& bus);

enum class RegisterType : std::uint8_t { holding, input };
std::string to_string(RegisterType r);

enum class PointName : std::uint8_t { op = 0, pv, sp, mv, mode };
constexpr std::size_t kPointCount = 5;
std::string to_string(PointName p);  // "op", "pv", ...

// Where one value lives: a Modbus register block or a CAN signal.
struct PointConfig {
  bool present = false;
  int line = 0;
  // Modbus
  RegisterType reg = RegisterType::holding;
  int address = 0;  // 0-based protocol address
  DataType type = DataType::float32;
  ByteOrder order = ByteOrder::abcd;
  double scale = 1.0, offset = 0.0;
  // Flag the value stale when its raw value has not changed for longer than this (0: never).
  // Set per point, or for op, pv and mv by the loop's stale_after.
  double stale_after_s = 0.0;
  // CAN
  CanSignal can;
  std::string message, signal;  // DBC names, when taken from the DBC
};

struct LoopConfigEntry {
  std::string name;
  std::string bus;
  int line = 0;
  double sample_period_s = 1.0;
  double op_min = 0.0, op_max = 100.0;  // range of OP in %
  double stale_after_s = 0.0;           // the loop's stale_after (already applied to points)
  std::array<PointConfig, kPointCount> points;
  // Simulated PLC only: which simulated loop serves these registers.
  std::string simulate;  // scenario name, or a scenario TOML path (resolved like dbc)
  std::uint64_t seed = 1;
  const PointConfig& point(PointName p) const { return points[static_cast<std::size_t>(p)]; }
};

// Fault injection for the simulated PLC (tests and demos): applies to requests that cover
// `address` (any address when unset) during [start_s, start_s + duration_s), to every `every`-th
// matching request. `freeze` is not about requests: the registers of the points covering
// `address` (all registers when unset) stop being updated, as when a PLC stops its program.
enum class FaultKind : std::uint8_t { delay, timeout, exception, drop, restart, garble, freeze };
std::string to_string(FaultKind k);
std::optional<FaultKind> parse_fault_kind(std::string_view s);
struct FaultConfig {
  FaultKind kind = FaultKind::delay;
  std::optional<int> address;
  std::optional<RegisterType> reg;
  double start_s = 0.0;
  double duration_s = 1e300;
  int every = 1;
  double delay_s = 0.2;    // delay: reply after this long
  int exception_code = 4;  // exception: Modbus exception code (1..11)
  double down_s = 1.0;     // restart: server away this long
  int line = 0;
};

struct SiteConfig {
  std::string file;  // for messages
  std::vector<BusConfig> buses;
  std::vector<LoopConfigEntry> loops;
  std::vector<FaultConfig> faults;
  const BusConfig* find_bus(std::string_view name) const;
  const LoopConfigEntry* find_loop(std::string_view name) const;
};

// "<file>:<line>:<column>: <key>: <problem>; <what to do>".
class SiteConfigError : public std::runtime_error {
 public:
  SiteConfigError(std::string file, int line, int column, std::string key, std::string problem);
  const std::string& file() const { return file_; }
  int line() const { return line_; }
  const std::string& key() const { return key_; }

 private:
  std::string file_;
  int line_;
  std::string key_;
};

// Reads and checks a site configuration; relative dbc/simulate paths are resolved against the
// file's directory. Throws SiteConfigError.
SiteConfig load_site_config(const std::string& path);
// The same from text; `base_dir` resolves relative paths ("" = current directory).
SiteConfig parse_site_config(std::string_view text, const std::string& source_name,
                             const std::string& base_dir = "");

// Parses "500ms", "2s", "1.5", "10m", "1h" (a bare number is seconds); nullopt when malformed.
std::optional<double> parse_duration(std::string_view s);

}  // namespace valvediag
