// Modbus RTU over TCP (Telegraf's transmission_mode = "RTUoverTCP"): the RTU frame (unit id,
// function code, data, CRC-16 low byte first) sent as it is on a TCP stream, as serial-to-Ethernet
// gateways in transparent mode pass it on to their serial line. libmodbus has no such backend, so
// this is a plain POSIX socket. There is no MBAP header and so no transaction id: a reply is
// framed by its function code and byte count and checked by its CRC, and after a timeout or a bad
// reply the bus drops the connection, so that a late reply cannot pass for the next one. Only
// function codes 3 and 4 are ever built.
#pragma once

#include <cstdint>
#include <memory>
#include <span>

#include "valvediag/drivers/modbus_bus.hpp"

namespace valvediag {

// CRC-16/MODBUS (reflected polynomial 0xA001, initial 0xFFFF); on the wire low byte first.
std::uint16_t modbus_crc16(std::span<const std::uint8_t> bytes);

// The transport of a modbus-rtu-over-tcp bus (host, port, slave_id, timeout of `bus`). Every
// wait is bounded by the bus's timeout: the connection, sending the request, the whole reply.
std::unique_ptr<ModbusTransport> make_rtu_over_tcp_transport(const BusConfig& bus);

}  // namespace valvediag
