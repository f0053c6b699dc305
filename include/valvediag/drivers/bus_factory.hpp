// Builds the driver for one bus of a site: Modbus TCP/RTU/RTU over TCP or SocketCAN. The only place
// that knows every driver; the recorder gets buses through this (or through a test's own factory).
#pragma once

#include <memory>
#include <vector>

#include "valvediag/drivers/bus.hpp"

namespace valvediag {

// `loops` are the loops read on this bus, in the order read() numbers them. Throws
// std::runtime_error when the bus cannot be opened at all (SocketCAN missing from the kernel);
// an unreachable Modbus device is not an error here (the driver keeps retrying).
std::unique_ptr<Bus> make_bus(const BusConfig& bus, std::vector<LoopConfigEntry> loops);

}  // namespace valvediag
