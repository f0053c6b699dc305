#include "valvediag/value_codec.hpp"

#include <bit>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace valvediag {

std::optional<DataType> parse_data_type(std::string_view s) {
  if (s == "INT16") return DataType::int16;
  if (s == "UINT16") return DataType::uint16;
  if (s == "INT32") return DataType::int32;
  if (s == "UINT32") return DataType::uint32;
  if (s == "FLOAT32" || s == "FLOAT32-IEEE") return DataType::float32;
  return std::nullopt;
}

std::optional<ByteOrder> parse_byte_order(std::string_view s) {
  if (s == "ABCD" || s == "AB") return ByteOrder::abcd;
  if (s == "CDAB") return ByteOrder::cdab;
  if (s == "BADC" || s == "BA") return ByteOrder::badc;
  if (s == "DCBA") return ByteOrder::dcba;
  return std::nullopt;
}

std::string to_string(DataType t) {
  switch (t) {
    case DataType::int16:
      return "INT16";
    case DataType::uint16:
      return "UINT16";
    case DataType::int32:
      return "INT32";
    case DataType::uint32:
      return "UINT32";
    case DataType::float32:
      return "FLOAT32";
  }
  return "?";
}

std::string to_string(ByteOrder o) {
  switch (o) {
    case ByteOrder::abcd:
      return "ABCD";
    case ByteOrder::cdab:
      return "CDAB";
    case ByteOrder::badc:
      return "BADC";
    case ByteOrder::dcba:
      return "DCBA";
  }
  return "?";
}

std::size_t register_count(DataType t) {
  return t == DataType::int16 || t == DataType::uint16 ? 1 : 2;
}

namespace {

// Wire position (0..3) of each value byte A..D for an order.
constexpr int kWirePos[4][4] = {
    {0, 1, 2, 3},  // ABCD
    {2, 3, 0, 1},  // CDAB
    {1, 0, 3, 2},  // BADC
    {3, 2, 1, 0},  // DCBA
};

std::uint32_t assemble(std::span<const std::uint16_t> regs, DataType type, ByteOrder order) {
  const std::size_t n = register_count(type);
  if (regs.size() < n)
    throw std::invalid_argument(to_string(type) + " needs " + std::to_string(n) +
                                " registers, got " + std::to_string(regs.size()));
  std::uint8_t wire[4] = {0, 0, 0, 0};
  for (std::size_t i = 0; i < n; ++i) {
    wire[2 * i] = static_cast<std::uint8_t>(regs[i] >> 8);
    wire[2 * i + 1] = static_cast<std::uint8_t>(regs[i] & 0xff);
  }
  const int o = static_cast<int>(order);
  if (n == 1) {
    // 16 bits: "AB" for ABCD/CDAB, "BA" for BADC/DCBA.
    const bool swapped = order == ByteOrder::badc || order == ByteOrder::dcba;
    return swapped ? (std::uint32_t{wire[1]} << 8) | wire[0]
                   : (std::uint32_t{wire[0]} << 8) | wire[1];
  }
  std::uint32_t v = 0;
  for (int b = 0; b < 4; ++b) v = (v << 8) | wire[kWirePos[o][b]];
  return v;
}

void disassemble(std::uint32_t v, DataType type, ByteOrder order, std::span<std::uint16_t> out) {
  const std::size_t n = register_count(type);
  if (out.size() < n) throw std::invalid_argument("encode: too few registers");
  std::uint8_t wire[4] = {0, 0, 0, 0};
  if (n == 1) {
    const bool swapped = order == ByteOrder::badc || order == ByteOrder::dcba;
    const auto hi = static_cast<std::uint8_t>(v >> 8), lo = static_cast<std::uint8_t>(v & 0xff);
    wire[0] = swapped ? lo : hi;
    wire[1] = swapped ? hi : lo;
  } else {
    const int o = static_cast<int>(order);
    for (int b = 0; b < 4; ++b) wire[kWirePos[o][b]] = static_cast<std::uint8_t>(v >> (24 - 8 * b));
  }
  for (std::size_t i = 0; i < n; ++i)
    out[i] = static_cast<std::uint16_t>((wire[2 * i] << 8) | wire[2 * i + 1]);
}

}  // namespace

double decode_raw(std::span<const std::uint16_t> regs, DataType type, ByteOrder order) {
  const std::uint32_t v = assemble(regs, type, order);
  switch (type) {
    case DataType::int16:
      return static_cast<std::int16_t>(static_cast<std::uint16_t>(v));
    case DataType::uint16:
      return static_cast<std::uint16_t>(v);
    case DataType::int32:
      return static_cast<std::int32_t>(v);
    case DataType::uint32:
      return v;
    case DataType::float32:
      return std::bit_cast<float>(v);
  }
  return 0.0;
}

double decode_registers(std::span<const std::uint16_t> regs, DataType type, ByteOrder order,
                        double scale, double offset) {
  return decode_raw(regs, type, order) * scale + offset;
}

void encode_registers(double value, DataType type, ByteOrder order, double scale, double offset,
                      std::span<std::uint16_t> out) {
  const double raw = scale != 0.0 ? (value - offset) / scale : 0.0;
  auto saturate = [&](double lo, double hi) {
    if (std::isnan(raw)) return 0.0;
    return std::round(std::min(hi, std::max(lo, raw)));
  };
  std::uint32_t v = 0;
  switch (type) {
    case DataType::int16:
      v = static_cast<std::uint16_t>(static_cast<std::int16_t>(saturate(-32768.0, 32767.0)));
      break;
    case DataType::uint16:
      v = static_cast<std::uint16_t>(saturate(0.0, 65535.0));
      break;
    case DataType::int32:
      v = static_cast<std::uint32_t>(
          static_cast<std::int32_t>(saturate(-2147483648.0, 2147483647.0)));
      break;
    case DataType::uint32:
      v = static_cast<std::uint32_t>(saturate(0.0, 4294967295.0));
      break;
    case DataType::float32:
      v = std::bit_cast<std::uint32_t>(static_cast<float>(raw));
      break;
  }
  disassemble(v, type, order, out);
}

namespace {

// Byte/bit positions of a signal's bits from most to least significant (Motorola) or least to
// most (Intel); false when a bit falls outside `bytes`.
template <class F>
bool walk_bits(const CanSignal& s, std::size_t bytes, F&& f) {
  const std::size_t total = bytes * 8;
  if (s.length < 1 || s.length > 64) return false;
  if (!s.motorola) {
    if (std::size_t{s.start_bit} + s.length > total) return false;
    for (unsigned i = 0; i < s.length; ++i) f(s.start_bit + i, i);
    return true;
  }
  std::size_t pos = s.start_bit;
  for (unsigned i = 0; i < s.length; ++i) {
    if (pos >= total) return false;
    f(pos, s.length - 1 - i);  // the first bit visited is the most significant
    if (pos % 8 == 0)
      pos += 15;
    else
      --pos;
  }
  return true;
}

}  // namespace

std::string check_can_signal(const CanSignal& s, std::size_t dlc) {
  if (s.length < 1 || s.length > 64)
    return "length " + std::to_string(s.length) + " is outside 1..64 bits";
  if (s.extended ? s.frame_id > 0x1FFFFFFFu : s.frame_id > 0x7FFu)
    return "frame id " + std::to_string(s.frame_id) + " is too large for " +
           (s.extended ? "a 29-bit" : "an 11-bit") + " identifier";
  if (!walk_bits(s, dlc, [](std::size_t, unsigned) {}))
    return "start bit " + std::to_string(s.start_bit) + " with length " + std::to_string(s.length) +
           (s.motorola ? " (Motorola)" : " (Intel)") + " does not fit in " + std::to_string(dlc) +
           " data bytes";
  if (!std::isfinite(s.factor) || s.factor == 0.0) return "factor must be a nonzero number";
  if (!std::isfinite(s.offset)) return "offset must be a finite number";
  return "";
}

std::int64_t can_signal_raw(const CanSignal& s, std::span<const std::uint8_t> data) {
  std::uint64_t raw = 0;
  const bool ok = walk_bits(s, data.size(), [&](std::size_t pos, unsigned weight) {
    const std::uint64_t bit = (data[pos / 8] >> (pos % 8)) & 1u;
    raw |= bit << weight;
  });
  if (!ok)
    throw std::invalid_argument("CAN signal does not fit in a frame of " +
                                std::to_string(data.size()) + " bytes");
  if (s.is_signed && s.length < 64 && ((raw >> (s.length - 1)) & 1u))
    raw |= ~std::uint64_t{0} << s.length;  // sign extension
  if (s.is_signed) return static_cast<std::int64_t>(raw);
  // Unsigned 64-bit values above INT64_MAX do not occur in process signals; saturate.
  return raw > static_cast<std::uint64_t>(std::numeric_limits<std::int64_t>::max())
             ? std::numeric_limits<std::int64_t>::max()
             : static_cast<std::int64_t>(raw);
}

double decode_can_signal(const CanSignal& s, std::span<const std::uint8_t> data) {
  return static_cast<double>(can_signal_raw(s, data)) * s.factor + s.offset;
}

void encode_can_signal(const CanSignal& s, double value, std::span<std::uint8_t> data) {
  const double r = std::round((value - s.offset) / s.factor);
  const double bits = static_cast<double>(s.length);
  const double lo = s.is_signed ? -std::ldexp(1.0, static_cast<int>(bits) - 1) : 0.0;
  // Capped below 2^63 so the conversion through int64 stays defined.
  const double hi = std::min(9.0e18, s.is_signed ? std::ldexp(1.0, static_cast<int>(bits) - 1) - 1
                                                 : std::ldexp(1.0, static_cast<int>(bits)) - 1);
  const double c = std::isnan(r) ? 0.0 : std::min(hi, std::max(lo, r));
  const auto raw = static_cast<std::uint64_t>(static_cast<std::int64_t>(c));
  const bool ok = walk_bits(s, data.size(), [&](std::size_t pos, unsigned weight) {
    const auto bit = static_cast<std::uint8_t>(1u << (pos % 8));
    if ((raw >> weight) & 1u)
      data[pos / 8] |= bit;
    else
      data[pos / 8] &= static_cast<std::uint8_t>(~bit);
  });
  if (!ok) throw std::invalid_argument("CAN signal does not fit in the frame");
}

}  // namespace valvediag
