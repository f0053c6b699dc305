// Modbus TCP and RTU on libmodbus, and RTU over TCP on a plain socket (modbus_rtu_over_tcp.hpp),
// all behind one ModbusBus: the wire is a ModbusTransport, and the bus keeps what they share
// (request planning, retries, reconnection with backoff, counters, decoding, stale_after).
// libmodbus's own link recovery is off (it can hang forever on a dead link). After a timeout or a
// garbled reply a late reply would be taken for the next one: on a TCP stream the connection is
// dropped; on RTU (no connection to drop) the line is read and discarded for one more timeout
// before the next request, and flushed before every request. Points with stale_after are flagged
// stale when their raw registers stay bit-identical for longer. Only function codes 3 and 4 are
// ever sent.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "valvediag/drivers/bus.hpp"

namespace valvediag {

// One read request: `count` registers of type `reg` from `address`.
struct RegisterBlock {
  RegisterType reg = RegisterType::holding;
  int address = 0;
  int count = 0;
};
// The requests that read one loop: points of the same register type merge into one block when
// the gap between them is at most 16 registers and the block stays within 125 registers.
std::vector<RegisterBlock> plan_requests(const LoopConfigEntry& loop);

// How one request ended.
enum class ModbusFailure : std::uint8_t { none, exception, timeout, garbled, link };

// The wire under a ModbusBus. It sends only function codes 3 and 4 and keeps no counters: the bus
// counts, retries and reconnects.
class ModbusTransport {
 public:
  virtual ~ModbusTransport() = default;
  // Where requests go, for messages: "10.0.0.5:502", "/dev/ttyUSB0 @19200 baud".
  virtual std::string where() const = 0;
  // One connection attempt, bounded by the bus's timeout: "" when connected, else why not.
  virtual std::string connect() = 0;
  virtual void close() = 0;
  // Reads the `b.count` (1..125) registers of `b` into `dest`; on failure `error` says why.
  virtual ModbusFailure read(const RegisterBlock& b, std::uint16_t* dest, std::string& error) = 0;
  // After a timeout or garbled reply: true when only a new connection keeps a late reply from
  // being taken for the next one (a stream); false when the transport clears the line itself.
  virtual bool reconnect_after_bad_reply() const = 0;
};

class ModbusBus final : public Bus {
 public:
  // The transport the bus's protocol needs. Nothing is sent before the first read(); throws
  // std::invalid_argument for a non-Modbus bus.
  ModbusBus(BusConfig config, std::vector<LoopConfigEntry> loops);
  ~ModbusBus() override;
  const std::string& name() const override;
  LoopValues read(std::size_t loop) override;
  BusStats stats() const override;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace valvediag
