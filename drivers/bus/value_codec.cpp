#include "valvediag/drivers/value_codec.hpp"

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
  if (s == "INT64") return DataType::int64;
  if (s == "UINT64") return DataType::uint64;
  if (s == "FLOAT64" || s == "FLOAT64-IEEE") return DataType::float64;
  return std::nullopt;
}

std::optional<ByteOrder> parse_byte_order(std::string_view s) {
  if (s == "ABCD" || s == "AB" || s == "ABCDEFGH") return ByteOrder::abcd;
  if (s == "CDAB" || s == "GHEFCDAB") return ByteOrder::cdab;
  if (s == "BADC" || s == "BA" || s == "BADCFEHG") return ByteOrder::badc;
  if (s == "DCBA" || s == "HGFEDCBA") return ByteOrder::dcba;
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
    case DataType::int64:
      return "INT64";
    case DataType::uint64:
      return "UINT64";
    case DataType::float64:
      return "FLOAT64";
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

std::string to_string(ByteOrder o, DataType width) {
  static const char* const k16[] = {"AB", "AB", "BA", "BA"};
  static const char* const k64[] = {"ABCDEFGH", "GHEFCDAB", "BADCFEHG", "HGFEDCBA"};
  const auto i = static_cast<std::size_t>(o);
  switch (register_count(width)) {
    case 1:
      return k16[i];
    case 4:
      return k64[i];
    default:
      return to_string(o);
  }
}

std::size_t register_count(DataType t) {
  switch (t) {
    case DataType::int16:
    case DataType::uint16:
      return 1;
    case DataType::int64:
    case DataType::uint64:
    case DataType::float64:
      return 4;
    default:
      return 2;
  }
}

namespace {

// Wire position (0 .. 2n - 1) of the value's byte k (0 the most significant) in n registers.
std::size_t wire_position(std::size_t k, std::size_t n, ByteOrder order) {
  const bool words_reversed = order == ByteOrder::cdab || order == ByteOrder::dcba;
  const bool bytes_swapped = order == ByteOrder::badc || order == ByteOrder::dcba;
  const std::size_t reg = words_reversed ? n - 1 - k / 2 : k / 2;
  return 2 * reg + (bytes_swapped ? 1 - k % 2 : k % 2);
}

std::uint64_t assemble(std::span<const std::uint16_t> regs, DataType type, ByteOrder order) {
  const std::size_t n = register_count(type);
  if (regs.size() < n)
    throw std::invalid_argument(to_string(type) + " needs " + std::to_string(n) +
                                " registers, got " + std::to_string(regs.size()));
  std::uint8_t wire[2 * kMaxRegisters] = {};
  for (std::size_t i = 0; i < n; ++i) {
    wire[2 * i] = static_cast<std::uint8_t>(regs[i] >> 8);
    wire[2 * i + 1] = static_cast<std::uint8_t>(regs[i] & 0xff);
  }
  std::uint64_t v = 0;
  for (std::size_t k = 0; k < 2 * n; ++k) v = (v << 8) | wire[wire_position(k, n, order)];
  return v;
}

void disassemble(std::uint64_t v, DataType type, ByteOrder order, std::span<std::uint16_t> out) {
  const std::size_t n = register_count(type);
  if (out.size() < n) throw std::invalid_argument("encode: too few registers");
  std::uint8_t wire[2 * kMaxRegisters] = {};
  for (std::size_t k = 0; k < 2 * n; ++k)
    wire[wire_position(k, n, order)] = static_cast<std::uint8_t>(v >> (8 * (2 * n - 1 - k)));
  for (std::size_t i = 0; i < n; ++i)
    out[i] = static_cast<std::uint16_t>((wire[2 * i] << 8) | wire[2 * i + 1]);
}

}  // namespace

double decode_raw(std::span<const std::uint16_t> regs, DataType type, ByteOrder order) {
  const std::uint64_t v = assemble(regs, type, order);
  switch (type) {
    case DataType::int16:
      return static_cast<std::int16_t>(static_cast<std::uint16_t>(v));
    case DataType::uint16:
      return static_cast<std::uint16_t>(v);
    case DataType::int32:
      return static_cast<std::int32_t>(v);
    case DataType::uint32:
      return static_cast<double>(v);
    case DataType::float32:
      return std::bit_cast<float>(static_cast<std::uint32_t>(v));
    case DataType::int64:
      return static_cast<double>(static_cast<std::int64_t>(v));
    case DataType::uint64:
      return static_cast<double>(v);
    case DataType::float64:
      return std::bit_cast<double>(v);
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
  std::uint64_t v = 0;
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
    case DataType::int64: {
      // 2^63 is the first double past INT64_MAX: saturate before converting (no UB).
      const double r = saturate(-9223372036854775808.0, 9223372036854775808.0);
      v = static_cast<std::uint64_t>(r >= 9223372036854775808.0
                                         ? std::numeric_limits<std::int64_t>::max()
                                         : static_cast<std::int64_t>(r));
      break;
    }
    case DataType::uint64: {
      const double r = saturate(0.0, 18446744073709551616.0);
      v = r >= 18446744073709551616.0 ? std::numeric_limits<std::uint64_t>::max()
                                      : static_cast<std::uint64_t>(r);
      break;
    }
    case DataType::float64:
      v = std::bit_cast<std::uint64_t>(raw);
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
