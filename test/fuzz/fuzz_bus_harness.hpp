// Shared by the libFuzzer targets of the bus layer and test_bus (which replays their seed corpora
// and every saved crash input): site config loader, DBC parser, register and CAN decoders.
// Each returns "" when the input was handled correctly (parsed into something consistent, or
// refused with the documented error), otherwise what is wrong. Other exceptions escape: bugs.
#pragma once

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <string>
#include <string_view>

#include "valvediag/drivers/dbc.hpp"
#include "valvediag/drivers/site_config.hpp"
#include "valvediag/drivers/value_codec.hpp"

namespace valvediag::fuzz {

inline std::string run_site_config(std::string_view text) {
  SiteConfig s;
  try {
    // No base directory: relative file names resolve from the fuzzer's working directory.
    s = parse_site_config(text, "fuzz.toml", "");
  } catch (const SiteConfigError& e) {
    if (std::string_view(e.what()).substr(0, 9) != "fuzz.toml") return "message without file";
    return "";
  }
  if (s.loops.empty()) return "accepted a site without loops";
  // Written apart from the loader's check, so that one checks the other.
  auto same_but_case = [](std::string a, std::string b) {
    if (a == b) return false;
    for (std::string* x : {&a, &b})
      for (char& c : *x) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    return a == b;
  };
  for (std::size_t i = 0; i < s.buses.size(); ++i) {
    const BusConfig& b = s.buses[i];
    if ((b.kind == BusKind::modbus_tcp || b.kind == BusKind::modbus_rtu_over_tcp) &&
        (b.port < 1 || b.port > 65535))
      return "Modbus TCP port outside 1..65535 accepted";
    for (const std::string* v : {&b.host, &b.device, &b.interface, &b.dbc})
      if (v->find('\0') != std::string::npos) return "NUL in a bus string accepted";
    for (std::size_t j = 0; j < i; ++j)
      if (same_but_case(b.name, s.buses[j].name)) return "bus names equal but for case accepted";
  }
  for (std::size_t i = 0; i < s.loops.size(); ++i) {
    if (s.loops[i].simulate.find('\0') != std::string::npos) return "NUL in simulate accepted";
    for (std::size_t j = 0; j < i; ++j)
      if (same_but_case(s.loops[i].name, s.loops[j].name))
        return "loop names equal but for case accepted";
  }
  for (const auto& l : s.loops) {
    const BusConfig* b = s.find_bus(l.bus);
    if (!b) return "loop on an unknown bus accepted";
    if (!(l.sample_period_s > 0) || !(l.op_min < l.op_max)) return "bad loop numbers accepted";
    if (!l.point(PointName::op).present || !l.point(PointName::pv).present)
      return "loop without op/pv accepted";
    for (const auto& p : l.points) {
      if (!p.present) continue;
      if (b->kind == BusKind::socketcan) {
        if (!check_can_signal(p.can).empty()) return "CAN signal outside the frame accepted";
      } else {
        if (p.address < 0 || p.address + static_cast<int>(register_count(p.type)) > 65536)
          return "register address out of range accepted";
        if (p.scale == 0.0 || !std::isfinite(p.scale) || !std::isfinite(p.offset))
          return "bad scale accepted";
      }
    }
  }
  return "";
}

inline std::string run_dbc(std::string_view text) {
  Dbc d;
  try {
    d = parse_dbc(text, "fuzz.dbc");
  } catch (const DbcError& e) {
    if (std::string_view(e.what()).substr(0, 8) != "fuzz.dbc") return "message without file";
    return "";
  }
  for (const auto& m : d.messages)
    for (const auto& s : m.signals) {
      if (!check_can_signal(s.signal, m.dlc).empty()) return "signal outside its message accepted";
      if (s.signal.frame_id != m.id) return "signal frame id differs from its message";
    }
  return "";
}

// Bytes: [type/order][scale/offset][4 register bytes][start bit][length][flags][8 data bytes];
// a 64-bit type's third and fourth registers are the first 4 data bytes.
inline std::string run_codec(std::string_view in) {
  std::uint8_t b[17] = {};
  std::memcpy(b, in.data(), std::min<std::size_t>(in.size(), sizeof b));
  const auto type = static_cast<DataType>(b[0] % 8);
  const auto order = static_cast<ByteOrder>((b[0] >> 3) % 4);
  static const double kScale[] = {1, 0.1, 0.01, -2.5, 1e-3, 10, 0.5, 3};
  static const double kOffset[] = {0, -50, 12.5, 1e6};
  const double scale = kScale[b[1] & 7], offset = kOffset[(b[1] >> 3) & 3];
  const std::uint16_t regs[kMaxRegisters] = {static_cast<std::uint16_t>((b[2] << 8) | b[3]),
                                             static_cast<std::uint16_t>((b[4] << 8) | b[5]),
                                             static_cast<std::uint16_t>((b[9] << 8) | b[10]),
                                             static_cast<std::uint16_t>((b[11] << 8) | b[12])};
  const std::size_t n = register_count(type);
  const double raw = decode_raw(regs, type, order);
  const bool is_float = type == DataType::float32 || type == DataType::float64;
  std::uint16_t back[kMaxRegisters] = {};
  if (!is_float) {
    if (!std::isfinite(raw) || raw != std::floor(raw)) return "integer decoded to a fraction";
    // 64-bit integers beyond 2^53 are read to the nearest double: no exact round trip there.
    if (std::fabs(raw) < 9007199254740992.0) {
      encode_registers(raw, type, order, 1.0, 0.0, back);
      if (!std::equal(back, back + n, regs)) return "integer register round trip differs";
    }
  } else if (std::isfinite(raw) && raw != 0.0) {
    encode_registers(raw, type, order, 1.0, 0.0, back);
    if (!std::equal(back, back + n, regs)) return "float register round trip differs";
  }
  const double eng = decode_registers(regs, type, order, scale, offset);
  if (std::isfinite(raw) &&
      !(std::fabs(eng - (raw * scale + offset)) <= 1e-9 * (1 + std::fabs(eng))))
    return "scale/offset misapplied";

  CanSignal s;
  s.start_bit = b[6] % 64;
  s.length = b[7] % 64 + 1;
  s.motorola = (b[8] & 1) != 0;
  s.is_signed = (b[8] & 2) != 0;
  const std::size_t dlc = (b[8] >> 2) % 9;
  const std::span<const std::uint8_t> data(b + 9, dlc);
  if (!check_can_signal(s, dlc).empty()) {
    try {
      (void)can_signal_raw(s, data);
    } catch (const std::invalid_argument&) {
      return "";
    }
    return "a signal outside the frame decoded";
  }
  const std::int64_t r = can_signal_raw(s, data);
  if (s.length < 64) {
    // In integers: a double would round 2^57 - 1 up to 2^57.
    const bool ok = s.is_signed ? ((r >> (s.length - 1)) == 0 || (r >> (s.length - 1)) == -1)
                                : (r >= 0 && (static_cast<std::uint64_t>(r) >> s.length) == 0);
    if (!ok) return "CAN raw value outside its bit range";
  }
  if (s.length <= 52) {  // exact in a double
    std::uint8_t copy[8];
    std::memcpy(copy, b + 9, 8);
    encode_can_signal(s, static_cast<double>(r), std::span<std::uint8_t>(copy, dlc));
    if (std::memcmp(copy, b + 9, dlc) != 0) return "CAN round trip changed the frame";
  }
  return "";
}

}  // namespace valvediag::fuzz
