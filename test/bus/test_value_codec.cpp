// Register and CAN signal decoding against hand-computed wire bytes.
#include <doctest/doctest.h>

#include <array>
#include <cmath>
#include <cstdint>
#include <stdexcept>

#include "valvediag/drivers/value_codec.hpp"

using namespace valvediag;

TEST_CASE("FLOAT32 in the four byte orders") {
  // 1.5f = 0x3FC00000; -123.25f = 0xC2F68000. A = 0x3F/0xC2 ... D = 0x00.
  struct Case {
    ByteOrder order;
    std::array<std::uint16_t, 2> one_five, minus;
  };
  const Case cases[] = {
      {ByteOrder::abcd, {0x3FC0, 0x0000}, {0xC2F6, 0x8000}},
      {ByteOrder::cdab, {0x0000, 0x3FC0}, {0x8000, 0xC2F6}},
      {ByteOrder::badc, {0xC03F, 0x0000}, {0xF6C2, 0x0080}},
      {ByteOrder::dcba, {0x0000, 0xC03F}, {0x0080, 0xF6C2}},
  };
  for (const auto& c : cases) {
    INFO(to_string(c.order));
    CHECK(decode_raw(c.one_five, DataType::float32, c.order) == 1.5);
    CHECK(decode_raw(c.minus, DataType::float32, c.order) == -123.25);
    std::array<std::uint16_t, 2> out{};
    encode_registers(-123.25, DataType::float32, c.order, 1.0, 0.0, out);
    CHECK(out == c.minus);
  }
}

TEST_CASE("integer types, 16-bit byte swap, scale and offset") {
  const std::array<std::uint16_t, 1> r16{0xFF38};  // -200 as INT16, 65336 as UINT16
  CHECK(decode_raw(r16, DataType::int16, ByteOrder::abcd) == -200);
  CHECK(decode_raw(r16, DataType::uint16, ByteOrder::abcd) == 65336);
  CHECK(decode_raw(r16, DataType::uint16, ByteOrder::badc) == 0x38FF);  // "BA"
  CHECK(decode_raw(r16, DataType::int16, ByteOrder::dcba) == 0x38FF);
  CHECK(decode_registers(r16, DataType::int16, ByteOrder::abcd, 0.1, -50.0) ==
        doctest::Approx(-70.0).epsilon(1e-12));
  // 0x12345678 and -2 as 32-bit integers.
  const std::array<std::uint16_t, 2> abcd{0x1234, 0x5678}, cdab{0x5678, 0x1234},
      badc{0x3412, 0x7856}, dcba{0x7856, 0x3412};
  CHECK(decode_raw(abcd, DataType::uint32, ByteOrder::abcd) == 0x12345678);
  CHECK(decode_raw(cdab, DataType::uint32, ByteOrder::cdab) == 0x12345678);
  CHECK(decode_raw(badc, DataType::uint32, ByteOrder::badc) == 0x12345678);
  CHECK(decode_raw(dcba, DataType::uint32, ByteOrder::dcba) == 0x12345678);
  const std::array<std::uint16_t, 2> m2{0xFFFF, 0xFFFE};
  CHECK(decode_raw(m2, DataType::int32, ByteOrder::abcd) == -2);
  CHECK(decode_raw(m2, DataType::uint32, ByteOrder::abcd) == 4294967294.0);
  const std::array<std::uint16_t, 1> short_regs{1};
  CHECK_THROWS_AS(decode_raw(short_regs, DataType::float32, ByteOrder::abcd),
                  std::invalid_argument);
}

TEST_CASE("encode then decode returns the value to the resolution of the type") {
  const DataType types[] = {DataType::int16,  DataType::uint16,  DataType::int32,
                            DataType::uint32, DataType::float32, DataType::int64,
                            DataType::uint64, DataType::float64};
  const ByteOrder orders[] = {ByteOrder::abcd, ByteOrder::cdab, ByteOrder::badc, ByteOrder::dcba};
  for (auto t : types)
    for (auto o : orders) {
      const double scale = t == DataType::float32 ? 1.0 : 0.01, offset = 2.0;
      for (double v : {2.0, 37.21, 99.99, 150.0}) {
        std::array<std::uint16_t, kMaxRegisters> regs{};
        encode_registers(v, t, o, scale, offset, regs);
        const double back = decode_registers(regs, t, o, scale, offset);
        INFO(to_string(t), " ", to_string(o), " ", v);
        CHECK(std::fabs(back - v) <= (t == DataType::float32 ? 1e-5 : 0.005 + 1e-12));
      }
    }
  // Saturation instead of wrap-around: 1000 % does not fit INT16 at scale 0.1.
  std::array<std::uint16_t, 1> r{};
  encode_registers(1e9, DataType::int16, ByteOrder::abcd, 0.1, 0.0, r);
  CHECK(decode_raw(r, DataType::int16, ByteOrder::abcd) == 32767);
}

TEST_CASE("64-bit values in the four byte orders, saturated at their range") {
  // 0x0102030405060700 (exact in a double) and 1.0 = 0x3FF0000000000000; A = 0x01 ... H = 0x00.
  struct Case {
    ByteOrder order;
    const char* name;
    std::array<std::uint16_t, 4> count, one;
  };
  const Case cases[] = {
      {ByteOrder::abcd, "ABCDEFGH", {0x0102, 0x0304, 0x0506, 0x0700}, {0x3FF0, 0, 0, 0}},
      {ByteOrder::cdab, "GHEFCDAB", {0x0700, 0x0506, 0x0304, 0x0102}, {0, 0, 0, 0x3FF0}},
      {ByteOrder::badc, "BADCFEHG", {0x0201, 0x0403, 0x0605, 0x0007}, {0xF03F, 0, 0, 0}},
      {ByteOrder::dcba, "HGFEDCBA", {0x0007, 0x0605, 0x0403, 0x0201}, {0, 0, 0, 0xF03F}},
  };
  for (const auto& c : cases) {
    INFO(c.name);
    CHECK(parse_byte_order(c.name) == c.order);
    CHECK(to_string(c.order, DataType::float64) == c.name);
    CHECK(decode_raw(c.count, DataType::uint64, c.order) == 72623859790382848.0);
    CHECK(decode_raw(c.count, DataType::int64, c.order) == 72623859790382848.0);
    CHECK(decode_raw(c.one, DataType::float64, c.order) == 1.0);
    std::array<std::uint16_t, 4> out{};
    encode_registers(72623859790382848.0, DataType::uint64, c.order, 1.0, 0.0, out);
    CHECK(out == c.count);
    encode_registers(1.0, DataType::float64, c.order, 1.0, 0.0, out);
    CHECK(out == c.one);
    // A double keeps what a float would round: FLOAT64 carries the value, not FLOAT32's 7 digits.
    encode_registers(-1234.56789012345, DataType::float64, c.order, 1.0, 0.0, out);
    CHECK(decode_raw(out, DataType::float64, c.order) == -1234.56789012345);
  }
  const std::array<std::uint16_t, 4> m2{0xFFFF, 0xFFFF, 0xFFFF, 0xFFFE};
  CHECK(decode_raw(m2, DataType::int64, ByteOrder::abcd) == -2.0);
  // Out of range: the nearest end, never a wrapped or undefined conversion; NaN is 0.
  std::array<std::uint16_t, 4> r{};
  encode_registers(1e30, DataType::int64, ByteOrder::abcd, 1.0, 0.0, r);
  CHECK(r == std::array<std::uint16_t, 4>{0x7FFF, 0xFFFF, 0xFFFF, 0xFFFF});
  encode_registers(-1e30, DataType::int64, ByteOrder::abcd, 1.0, 0.0, r);
  CHECK(r == std::array<std::uint16_t, 4>{0x8000, 0, 0, 0});
  encode_registers(1e30, DataType::uint64, ByteOrder::abcd, 1.0, 0.0, r);
  CHECK(r == std::array<std::uint16_t, 4>{0xFFFF, 0xFFFF, 0xFFFF, 0xFFFF});
  encode_registers(-5.0, DataType::uint64, ByteOrder::abcd, 1.0, 0.0, r);
  CHECK(r == std::array<std::uint16_t, 4>{0, 0, 0, 0});
  encode_registers(std::nan(""), DataType::int64, ByteOrder::abcd, 1.0, 0.0, r);
  CHECK(r == std::array<std::uint16_t, 4>{0, 0, 0, 0});
  const std::array<std::uint16_t, 2> two{1, 2};
  CHECK_THROWS_AS(decode_raw(two, DataType::float64, ByteOrder::abcd), std::invalid_argument);
  CHECK(register_count(DataType::int64) == 4);
  CHECK(register_count(DataType::float64) == 4);
}

TEST_CASE("names of types and byte orders") {
  CHECK(parse_data_type("FLOAT32") == DataType::float32);
  CHECK(parse_data_type("FLOAT64-IEEE") == DataType::float64);  // Telegraf's name
  CHECK(parse_data_type("INT64") == DataType::int64);
  CHECK(parse_data_type("UINT64") == DataType::uint64);
  CHECK(!parse_data_type("float"));
  CHECK(parse_byte_order("BA") == ByteOrder::badc);
  CHECK(!parse_byte_order("ACBD"));
}

TEST_CASE("CAN signals: Intel and Motorola layouts, sign, factor") {
  const std::array<std::uint8_t, 8> d{0x34, 0x12, 0xFF, 0x0F, 0x0A, 0xBC, 0x80, 0x00};
  CanSignal s;
  s.start_bit = 0;
  s.length = 16;
  CHECK(can_signal_raw(s, d) == 0x1234);  // Intel: LSB first
  s.start_bit = 16;
  s.length = 12;
  CHECK(can_signal_raw(s, d) == 0xFFF);
  s.is_signed = true;
  CHECK(can_signal_raw(s, d) == -1);
  s.is_signed = false;
  s.motorola = true;
  s.start_bit = 7;  // Motorola: start bit is the MSB; 16 bits = bytes 0..1 big-endian
  s.length = 16;
  CHECK(can_signal_raw(s, d) == 0x3412);
  s.start_bit = 35;  // bits 3..0 of byte 4, then byte 5: 0xA, 0xBC -> 0xABC
  s.length = 12;
  CHECK(can_signal_raw(s, d) == 0xABC);
  s.factor = 0.5;
  s.offset = -10;
  CHECK(decode_can_signal(s, d) == doctest::Approx(0xABC * 0.5 - 10));
  s.start_bit = 3;
  s.length = 64;  // runs off the end of 8 bytes
  CHECK(check_can_signal(s) != "");
  CHECK_THROWS_AS(can_signal_raw(s, d), std::invalid_argument);
  const std::array<std::uint8_t, 2> short_frame{1, 2};
  s.start_bit = 23;
  s.length = 8;
  CHECK_THROWS_AS(can_signal_raw(s, short_frame), std::invalid_argument);
}

TEST_CASE("CAN encode/decode round trip, both layouts, signed") {
  for (bool motorola : {false, true})
    for (bool is_signed : {false, true}) {
      CanSignal s;
      s.motorola = motorola;
      s.is_signed = is_signed;
      s.start_bit = motorola ? 13 : 13;
      s.length = 13;
      s.factor = 0.1;
      s.offset = is_signed ? 0.0 : -20.0;
      REQUIRE(check_can_signal(s) == "");
      for (double v : {-5.3, 0.0, 12.7, 150.0}) {
        std::array<std::uint8_t, 8> d{};
        d.fill(0xA5);  // bits outside the signal must survive
        encode_can_signal(s, v, d);
        INFO(motorola, is_signed, v);
        CHECK(decode_can_signal(s, d) == doctest::Approx(v).epsilon(1e-9));
        CHECK((d[7] == 0xA5 && d[6] == 0xA5));
      }
    }
}
