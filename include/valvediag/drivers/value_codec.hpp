// Decoding of field-bus values to engineering units: Modbus registers (INT16, UINT16, INT32,
// UINT32, FLOAT32, INT64, UINT64, FLOAT64 in the byte orders ABCD, CDAB, BADC, DCBA and their
// 64-bit forms ABCDEFGH, GHEFCDAB, BADCFEHG, HGFEDCBA) and CAN signals (Intel/Motorola bit
// layout as in DBC files). Floats are assembled here bit by bit, not by libmodbus (the Debian
// 3.1.6 float setters are byte-swapped). Pure functions: no bus, no I/O.
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>

namespace valvediag {

enum class DataType : std::uint8_t {
  int16,
  uint16,
  int32,
  uint32,
  float32,
  int64,
  uint64,
  float64
};
// Order of the value's bytes A (most significant) .. D on the wire: ABCD big-endian (the Modbus
// default), CDAB word-swapped, BADC byte-swapped, DCBA little-endian. Each names two choices that
// hold for any width: are the registers in order or reversed, are the two bytes of each register
// in order or swapped. 16-bit values read "AB" (ABCD, CDAB) or "BA" (BADC, DCBA); 64-bit values
// ABCDEFGH, GHEFCDAB, BADCFEHG, HGFEDCBA (Telegraf's names, which parse_byte_order also reads).
enum class ByteOrder : std::uint8_t { abcd, cdab, badc, dcba };

// "INT16" .. "FLOAT64"; also Telegraf's "FLOAT32-IEEE" and "FLOAT64-IEEE".
std::optional<DataType> parse_data_type(std::string_view s);
// The 2-, 4- and 8-letter names above.
std::optional<ByteOrder> parse_byte_order(std::string_view s);
std::string to_string(DataType t);
std::string to_string(ByteOrder o);                  // its 4-letter name
std::string to_string(ByteOrder o, DataType width);  // its name for that type's width
// Number of 16-bit registers a value of this type occupies (1, 2 or 4).
std::size_t register_count(DataType t);
inline constexpr std::size_t kMaxRegisters = 4;  // of any type

// Raw value of `regs` (at least register_count(type) registers, as received: each register
// big-endian on the wire, already in host order). Throws std::invalid_argument when too few.
// INT64 and UINT64 beyond 2^53 come back rounded to the nearest double (a reading, not a count).
double decode_raw(std::span<const std::uint16_t> regs, DataType type, ByteOrder order);
// Engineering value: raw * scale + offset. A float32 NaN or infinity decodes as such; the caller
// flags it.
double decode_registers(std::span<const std::uint16_t> regs, DataType type, ByteOrder order,
                        double scale, double offset);
// Inverse for the simulated PLC and the tests: (value - offset) / scale, rounded and saturated
// to the integer type's range, written into `out` (register_count(type) registers).
void encode_registers(double value, DataType type, ByteOrder order, double scale, double offset,
                      std::span<std::uint16_t> out);

// One CAN signal, with the fields of a DBC SG_ line.
struct CanSignal {
  std::uint32_t frame_id = 0;  // 11-bit, or 29-bit with `extended`
  bool extended = false;
  unsigned start_bit = 0;  // DBC numbering: Intel the LSB, Motorola the MSB (sawtooth)
  unsigned length = 1;     // 1..64 bits
  bool motorola = false;   // DBC "@0" (big-endian); "@1" is Intel (little-endian)
  bool is_signed = false;  // DBC "-"
  double factor = 1.0;
  double offset = 0.0;
};

// Checks that the signal lies inside a frame of `dlc` bytes (8 for classic CAN); "" when it does,
// else what is wrong.
std::string check_can_signal(const CanSignal& s, std::size_t dlc = 8);
// Raw (integer) value of the signal in `data`; throws std::invalid_argument when the signal does
// not fit in `data` (a short frame).
std::int64_t can_signal_raw(const CanSignal& s, std::span<const std::uint8_t> data);
double decode_can_signal(const CanSignal& s, std::span<const std::uint8_t> data);
// Inverse (for the simulated PLC and tests): writes the signal's bits into `data`.
void encode_can_signal(const CanSignal& s, double value, std::span<std::uint8_t> data);

}  // namespace valvediag
