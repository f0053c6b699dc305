#include "valvediag/drivers/bus_factory.hpp"

#include "valvediag/drivers/can_bus.hpp"
#include "valvediag/drivers/modbus_bus.hpp"

namespace valvediag {

std::unique_ptr<Bus> make_bus(const BusConfig& bus, std::vector<LoopConfigEntry> loops) {
  if (bus.kind == BusKind::socketcan) {
    // interface = "unix:PATH": the simulated PLC's frame socket instead of a CAN interface.
    const std::string path = can_unix_path(bus);
    std::unique_ptr<CanTransport> t;
    if (path.empty())
      t = open_socketcan(bus.interface);
    else
      t = std::make_unique<UnixCanTransport>(path);
    return std::make_unique<CanBus>(bus, std::move(loops), std::move(t));
  }
  return std::make_unique<ModbusBus>(bus, std::move(loops));
}

}  // namespace valvediag
