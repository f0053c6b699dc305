// Modbus TCP and RTU on libmodbus. libmodbus's own link recovery is off (it can hang forever on a
// dead link); this driver reconnects itself with backoff, and after a timeout or a garbled reply
// it drops the connection, since a late reply would otherwise be taken for the next one.
// Only function codes 3 and 4 are ever sent.
#pragma once

#include <memory>
#include <vector>

#include "valvediag/bus.hpp"

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

class ModbusBus final : public Bus {
 public:
  // Nothing is sent before the first read(); throws std::invalid_argument for a non-Modbus bus.
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
