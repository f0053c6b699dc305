#include "valvediag/bus_factory.hpp"

#include "valvediag/can_bus.hpp"
#include "valvediag/modbus_bus.hpp"

namespace valvediag {

std::unique_ptr<Bus> make_bus(const BusConfig& bus, std::vector<LoopConfigEntry> loops) {
  if (bus.kind == BusKind::socketcan)
    return std::make_unique<CanBus>(bus, std::move(loops), open_socketcan(bus.interface));
  return std::make_unique<ModbusBus>(bus, std::move(loops));
}

}  // namespace valvediag
