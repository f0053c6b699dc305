// Modbus TCP and RTU on libmodbus. libmodbus's own link recovery is off (it can hang forever on a
// dead link); this driver reconnects itself with backoff. After a timeout or a garbled reply a
// late reply would be taken for the next one: on TCP the connection is dropped; on RTU (no
// connection to drop) the line is read and discarded for one more timeout before the next
// request, and flushed before every request. Points with stale_after are flagged stale when
// their raw registers stay bit-identical for longer. Only function codes 3 and 4 are ever sent.
#pragma once

#include <memory>
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
