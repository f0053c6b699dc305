// Site configuration and DBC reader: the example configs load, and every kind of mistake is
// reported at its line with what to do.
#include <doctest/doctest.h>

#include <string>

#include "valvediag/drivers/dbc.hpp"
#include "valvediag/drivers/site_config.hpp"

using namespace valvediag;

namespace {
const std::string kConfigs = VALVEDIAG_CONFIG_DIR;

// The error a config text raises ("" when it parses).
SiteConfigError error_of(const std::string& text) {
  try {
    parse_site_config(text, "t.toml", kConfigs);
  } catch (const SiteConfigError& e) {
    return e;
  }
  FAIL("no error raised for:\n" << text);
  return SiteConfigError("", 0, 0, "", "");
}

const char* kBus =
    "[[bus]]\nname = \"p\"\nprotocol = \"modbus-tcp\"\ncontroller = \"tcp://127.0.0.1:1502\"\n";
}  // namespace

TEST_CASE("configs/site.toml: buses, loops and points as written") {
  const SiteConfig s = load_site_config(kConfigs + "/site.toml");
  REQUIRE(s.buses.size() == 3);
  CHECK(s.buses[0].kind == BusKind::modbus_tcp);
  CHECK(s.buses[0].host == "127.0.0.1");
  CHECK(s.buses[0].port == 5020);
  CHECK(s.buses[0].timeout_s == doctest::Approx(0.3));
  CHECK(s.buses[1].kind == BusKind::modbus_rtu);
  CHECK(s.buses[1].device == "/dev/ttyUSB0");
  CHECK(s.buses[1].parity == 'E');
  CHECK(s.buses[1].pause_s == doctest::Approx(0.02));
  CHECK(s.buses[2].kind == BusKind::modbus_rtu_over_tcp);  // Telegraf's transmission_mode
  CHECK(s.buses[2].port == 4001);
  CHECK(s.buses[2].slave_id == 3);
  REQUIRE(s.loops.size() == 3);
  CHECK(s.loops[2].point(PointName::pv).order == ByteOrder::cdab);
  const auto& tic = s.loops[1];
  CHECK(tic.sample_period_s == 1.0);
  CHECK(tic.point(PointName::op).reg == RegisterType::input);
  CHECK(tic.point(PointName::op).scale == 0.01);
  CHECK(tic.point(PointName::pv).offset == -50.0);
  CHECK(tic.point(PointName::sp).type == DataType::uint32);
  CHECK(tic.point(PointName::sp).order == ByteOrder::cdab);
  CHECK(tic.point(PointName::mode).present);
  CHECK(!tic.point(PointName::mv).present);
  CHECK(s.loops[0].point(PointName::pv).stale_after_s == 30.0);
  CHECK(s.loops[0].point(PointName::sp).stale_after_s == 0.0);
  CHECK(tic.point(PointName::pv).stale_after_s == 0.0);
}

TEST_CASE("configs/sim-can-site.toml: a Modbus loop and two CAN loops on a unix: socket") {
  const SiteConfig s = load_site_config(kConfigs + "/sim-can-site.toml");
  REQUIRE(s.buses.size() == 2);
  CHECK(can_unix_path(s.buses[1]) == "/tmp/valvediag-sim-can0.sock");
  REQUIRE(s.loops.size() == 3);
  CHECK(s.loops[0].point(PointName::pv).stale_after_s == 1.0);
  CHECK(s.loops[1].bus == "can0");
  CHECK(s.loops[1].point(PointName::sp).can.frame_id == 291);
  CHECK(s.loops[2].simulate == "deadband");
}

TEST_CASE("configs/sim-site.toml and configs/can-site.toml load") {
  const SiteConfig sim = load_site_config(kConfigs + "/sim-site.toml");
  CHECK(sim.loops.size() == 3);
  CHECK(sim.loops[0].simulate == "paper-ex1");
  CHECK(sim.loops[2].point(PointName::pv).order == ByteOrder::badc);
  const SiteConfig can = load_site_config(kConfigs + "/can-site.toml");
  REQUIRE(can.loops.size() == 2);
  const auto& sp = can.loops[0].point(PointName::sp).can;
  CHECK(sp.frame_id == 291);
  CHECK(sp.motorola);
  CHECK(sp.start_bit == 39);
  CHECK(sp.factor == 0.01);
  const auto& pv = can.loops[1].point(PointName::pv).can;
  CHECK(pv.extended);
  CHECK(pv.frame_id == 0x322);
  CHECK(pv.is_signed);
  CHECK(pv.offset == -50.0);
}

TEST_CASE("config errors name the line, the key and what to do") {
  const std::string loop =
      "[[loop]]\nname = \"A\"\nbus = \"p\"\nsample_period = \"1s\"\n"
      "op = { address = 0, type = \"FLOAT32\" }\npv = { address = 2, type = \"FLOAT32\" }\n";
  CHECK_NOTHROW(parse_site_config(std::string(kBus) + loop, "t.toml"));

  auto e = error_of(std::string(kBus) + "slave = 3\n" + loop);
  CHECK(e.line() == 5);
  CHECK(std::string(e.what()).find("unknown key; remove it or use one of") != std::string::npos);

  e = error_of(std::string(kBus) + "[[loop]]\nname = \"A\"\nbus = \"q\"\n");
  CHECK(e.line() == 7);
  CHECK(std::string(e.what()).find("no bus named 'q'") != std::string::npos);

  e = error_of(std::string(kBus) + loop + "sp = { address = 3, type = \"FLOAT32\" }\n");
  CHECK(e.line() == 11);
  CHECK(std::string(e.what()).find("overlaps pv at holding register 3") != std::string::npos);

  e = error_of(std::string(kBus) +
               "[[loop]]\nname = \"A\"\nbus = \"p\"\nsample_period = \"1s\"\n"
               "op = { address = 0, type = \"REAL\" }\n");
  CHECK(e.line() == 9);
  CHECK(e.key() == "loop[0].op.type");

  e = error_of(std::string(kBus) +
               "[[loop]]\nname = \"A\"\nbus = \"p\"\nsample_period = \"1s\"\n"
               "op = { address = 0, type = \"INT16\" }\n");
  CHECK(std::string(e.what()).find("missing pv") != std::string::npos);

  e = error_of("[[bus]]\nname = \"p\"\nprotocol = \"modbus-tcp\"\ncontroller = \"127.0.0.1\"\n" +
               loop);
  CHECK(e.line() == 4);
  CHECK(std::string(e.what()).find("tcp://") != std::string::npos);

  e = error_of(std::string(kBus) + "timeout = \"fast\"\n" + loop);
  CHECK(e.line() == 5);
  e = error_of(
      std::string(kBus) +
      "[[loop]]\nname = \"A\"\nbus = \"p\"\nsample_period = \"-1s\"\n"
      "op = { address = 0, type = \"FLOAT32\" }\npv = { address = 2, type = \"FLOAT32\" }\n");
  CHECK(e.line() == 8);
  e = error_of(std::string(kBus) + loop + "op_range = [100, 0]\n");
  CHECK(e.line() == 11);
  e = error_of(std::string(kBus) + loop + "[[fault]]\nkind = \"explode\"\n");
  CHECK(e.line() == 12);
  e = error_of(std::string(kBus) + loop +
               "[[loop]]\nname = \"A\"\nbus = \"p\"\nsample_period = \"1s\"\n"
               "op = { address = 9, type = \"INT16\" }\n"
               "pv = { address = 8, type = \"INT16\" }\n");
  CHECK(std::string(e.what()).find("defined twice") != std::string::npos);
  e = error_of("x = [1,\n");
  CHECK(e.line() >= 1);
  CHECK(std::string(e.what()).find("fix the TOML syntax") != std::string::npos);
  e = error_of(std::string(kBus));
  CHECK(std::string(e.what()).find("no [[loop]]") != std::string::npos);
  // A Modbus key on a CAN bus.
  e = error_of(
      "[[bus]]\nname = \"c\"\nprotocol = \"socketcan\"\ninterface = \"can0\"\n"
      "slave_id = 1\n");
  CHECK(e.line() == 5);
  CHECK(std::string(e.what()).find("only applies to Modbus") != std::string::npos);
  // A DBC signal that is not in the DBC.
  e = error_of(
      "[[bus]]\nname = \"c\"\nprotocol = \"socketcan\"\ninterface = \"can0\"\n"
      "dbc = \"plant.dbc\"\n[[loop]]\nname = \"A\"\nbus = \"c\"\nsample_period = \"1s\"\n"
      "op = { message = \"VALVE_FIC101\", signal = \"OUT\" }\n"
      "pv = { message = \"VALVE_FIC101\", signal = \"PV\" }\n");
  CHECK(e.line() == 10);
  CHECK(std::string(e.what()).find("no signal 'OUT'") != std::string::npos);
}

TEST_CASE("values once taken silently are errors at their line: issue 34 item 9") {
  const std::string points =
      "op = { address = 0, type = \"FLOAT32\" }\npv = { address = 2, type = \"FLOAT32\" }\n";
  // A missing sample_period no longer becomes 1 s.
  auto e = error_of(std::string(kBus) + "[[loop]]\nname = \"A\"\nbus = \"p\"\n" + points);
  CHECK(std::string(e.what()) ==
        "t.toml:5:1: loop[0]: missing key 'sample_period'; add sample_period = \"1s\" (how often "
        "the recorder polls this loop)");
  const std::string loop = "[[loop]]\nname = \"A\"\nbus = \"p\"\nsample_period = \"1s\"\n";

  // Port 0, and a port left empty.
  e = error_of(
      "[[bus]]\nname = \"p\"\nprotocol = \"modbus-tcp\"\ncontroller = \"tcp://10.0.0.1:0\"\n" +
      loop + points);
  CHECK(
      std::string(e.what()) ==
      "t.toml:4:14: bus[0].controller: port '0' is not 1..65535 (Modbus TCP is usually 502; for a "
      "free port of the simulated PLC use sim-plc --port 0)");
  e = error_of(
      "[[bus]]\nname = \"p\"\nprotocol = \"modbus-tcp\"\ncontroller = \"tcp://10.0.0.1:\"\n" +
      loop + points);
  CHECK(e.line() == 4);
  CHECK(parse_site_config("[[bus]]\nname = \"p\"\nprotocol = \"modbus-tcp\"\ncontroller = "
                          "\"tcp://10.0.0.1:65535\"\n" +
                              loop + points,
                          "t.toml")
            .buses[0]
            .port == 65535);

  // A 16-bit type with a 32-bit byte order, and the reverse.
  e = error_of(std::string(kBus) + loop +
               "op = { address = 0, type = \"INT16\", byte_order = \"CDAB\" }\n"
               "pv = { address = 2, type = \"FLOAT32\" }\n");
  CHECK(
      std::string(e.what()) ==
      "t.toml:9:50: loop[0].op.byte_order: 'CDAB' orders the 4 bytes of a 32-bit value, but "
      "INT16 is one register: write \"AB\" or \"BA\", or give the 32-bit type the registers hold");
  e = error_of(std::string(kBus) + loop + "op = { address = 0, type = \"FLOAT32\" }\n" +
               "pv = { address = 2, type = \"UINT32\", byte_order = \"BA\" }\n");
  CHECK(e.line() == 10);
  CHECK(e.key() == "loop[0].pv.byte_order");
  CHECK(std::string(e.what()).find("UINT32 spans two: write ABCD, CDAB, BADC or DCBA") !=
        std::string::npos);
  const SiteConfig ok = parse_site_config(
      std::string(kBus) + loop + "op = { address = 0, type = \"INT16\", byte_order = \"BA\" }\n" +
          "pv = { address = 2, type = \"UINT16\" }\n",
      "t.toml");
  CHECK(ok.loops[0].point(PointName::op).order == ByteOrder::badc);
  CHECK(ok.loops[0].point(PointName::pv).order == ByteOrder::abcd);

  // 64-bit types as Telegraf's Modbus input writes them: `data_type`, 8-letter orders, and its
  // 4-letter orders applied to every width.
  const SiteConfig t64 = parse_site_config(
      std::string(kBus) + loop +
          "op = { address = 0, data_type = \"FLOAT64-IEEE\", byte_order = \"GHEFCDAB\" }\n" +
          "pv = { address = 4, data_type = \"INT64\", byte_order = \"DCBA\" }\n" +
          "sp = { address = 8, type = \"UINT64\" }\n",
      "t.toml");
  CHECK(t64.loops[0].point(PointName::op).type == DataType::float64);
  CHECK(t64.loops[0].point(PointName::op).order == ByteOrder::cdab);
  CHECK(t64.loops[0].point(PointName::pv).type == DataType::int64);
  CHECK(t64.loops[0].point(PointName::pv).order == ByteOrder::dcba);
  CHECK(t64.loops[0].point(PointName::sp).type == DataType::uint64);
  e = error_of(std::string(kBus) + loop +
               "op = { address = 0, type = \"FLOAT32\", data_type = \"FLOAT32\" }\n" +
               "pv = { address = 2, type = \"FLOAT32\" }\n");
  CHECK(e.line() == 9);
  CHECK(e.key() == "loop[0].op.data_type");
  CHECK(std::string(e.what()).find("and `type` both give the point's type: keep one") !=
        std::string::npos);
  e = error_of(std::string(kBus) + loop +
               "op = { address = 0, type = \"INT64\", byte_order = \"BA\" }\n" +
               "pv = { address = 4, type = \"FLOAT32\" }\n");
  CHECK(e.key() == "loop[0].op.byte_order");
  CHECK(std::string(e.what()).find("'BA' orders the 2 bytes of one register, but INT64 spans "
                                   "four: write ABCDEFGH, GHEFCDAB, BADCFEHG or HGFEDCBA") !=
        std::string::npos);
  e = error_of(std::string(kBus) + loop +
               "op = { address = 0, type = \"FLOAT32\", byte_order = \"ABCDEFGH\" }\n" +
               "pv = { address = 2, type = \"FLOAT32\" }\n");
  CHECK(std::string(e.what()).find("'ABCDEFGH' orders the 8 bytes of a 64-bit value, but FLOAT32 "
                                   "spans two: write ABCD, CDAB, BADC or DCBA") !=
        std::string::npos);
  // Four registers must fit below 65536.
  e = error_of(std::string(kBus) + loop + "op = { address = 65533, type = \"FLOAT64\" }\n" +
               "pv = { address = 2, type = \"FLOAT32\" }\n");
  CHECK(e.key() == "loop[0].op.address");
  e = error_of(std::string(kBus) + loop + "op = { address = 0, type = \"FLOAT128\" }\n" +
               "pv = { address = 2, type = \"FLOAT32\" }\n");
  CHECK(std::string(e.what()).find("'FLOAT128' must be INT16, UINT16, INT32, UINT32, FLOAT32, "
                                   "INT64, UINT64 or FLOAT64") != std::string::npos);

  // A NUL inside a string (TOML's \u0000 escape), in a value and in a key.
  e = error_of(std::string(kBus) + "[[loop]]\nname = \"FIC\\u0000101\"\nbus = \"p\"\n" +
               "sample_period = \"1s\"\n" + points);
  CHECK(std::string(e.what()) ==
        "t.toml:6:8: loop[0].name: holds a NUL character (\\u0000); remove it");
  e = error_of(
      "[[bus]]\nname = \"p\"\nprotocol = \"modbus-tcp\"\ncontroller = \"tcp://a:502\"\n"
      "\"x\\u0000y\" = 1\n" +
      loop + points);
  CHECK(e.line() == 5);
  CHECK(e.key() == "bus[0].x?y");

  // Names that differ only in case.
  e = error_of(std::string(kBus) +
               "[[loop]]\nname = \"FIC101\"\nbus = \"p\"\nsample_period = \"1s\"\n" + points +
               "[[loop]]\nname = \"fic101\"\nbus = \"p\"\nsample_period = \"1s\"\n" + points);
  CHECK(std::string(e.what()) ==
        "t.toml:12:8: loop[1].name: loop 'fic101' differs from loop 'FIC101' (line 5) only in "
        "upper and lower case; give the loops distinct names");
  e = error_of(std::string(kBus) +
               "[[bus]]\nname = \"P\"\nprotocol = \"modbus-tcp\"\ncontroller = \"tcp://a:502\"\n" +
               loop + points);
  CHECK(e.line() == 6);
  CHECK(std::string(e.what()).find("bus 'P' differs from bus 'p' (line 1) only in upper and lower "
                                   "case") != std::string::npos);
}

TEST_CASE(
    "stale_after: per loop for op, pv and mv, per point for any, \"off\"; errors at their line") {
  const std::string loop =
      "[[loop]]\nname = \"A\"\nbus = \"p\"\nsample_period = \"1s\"\nstale_after = \"30s\"\n"
      "op = { address = 0, type = \"FLOAT32\" }\n"
      "pv = { address = 2, type = \"FLOAT32\" }\n"
      "sp = { address = 4, type = \"FLOAT32\" }\n"
      "mv = { address = 6, type = \"FLOAT32\", stale_after = \"off\" }\n"
      "mode = { address = 8, type = \"UINT16\", stale_after = \"2m\" }\n";
  const SiteConfig s = parse_site_config(std::string(kBus) + loop, "t.toml");
  const LoopConfigEntry& l = s.loops[0];
  CHECK(l.stale_after_s == 30.0);
  CHECK(l.point(PointName::op).stale_after_s == 30.0);
  CHECK(l.point(PointName::pv).stale_after_s == 30.0);
  CHECK(l.point(PointName::sp).stale_after_s == 0.0);  // a set point stays put on purpose
  CHECK(l.point(PointName::mv).stale_after_s == 0.0);
  CHECK(l.point(PointName::mode).stale_after_s == 120.0);
  // Off by default.
  const SiteConfig d = parse_site_config(
      std::string(kBus) +
          "[[loop]]\nname = \"A\"\nbus = \"p\"\nsample_period = \"1s\"\n"
          "op = { address = 0, type = \"FLOAT32\" }\npv = { address = 2, type = \"FLOAT32\" }\n",
      "t.toml");
  CHECK(d.loops[0].point(PointName::pv).stale_after_s == 0.0);

  auto e = error_of(std::string(kBus) +
                    "[[loop]]\nname = \"A\"\nbus = \"p\"\nsample_period = \"1s\"\n"
                    "stale_after = \"500ms\"\n"
                    "op = { address = 0, type = \"FLOAT32\" }\n"
                    "pv = { address = 2, type = \"FLOAT32\" }\n");
  CHECK(e.line() == 9);
  CHECK(e.key() == "loop[0].stale_after");
  CHECK(std::string(e.what()).find("longer than the sample period (1 s)") != std::string::npos);
  e = error_of(std::string(kBus) +
               "[[loop]]\nname = \"A\"\nbus = \"p\"\nsample_period = \"1s\"\n"
               "op = { address = 0, type = \"FLOAT32\" }\n"
               "pv = { address = 2, type = \"FLOAT32\", stale_after = \"never\" }\n");
  CHECK(e.line() == 10);
  CHECK(e.key() == "loop[0].pv.stale_after");
  CHECK(std::string(e.what()).find("must be a duration") != std::string::npos);
}

TEST_CASE("CAN interface \"unix:PATH\" (the simulated PLC's socket) and the freeze fault") {
  const std::string loop =
      "[[loop]]\nname = \"A\"\nbus = \"c\"\nsample_period = \"1s\"\n"
      "op = { frame_id = 0x100, start_bit = 0, length = 16 }\n"
      "pv = { frame_id = 0x100, start_bit = 16, length = 16 }\n";
  SiteConfig s = parse_site_config(
      "[[bus]]\nname = \"c\"\nprotocol = \"socketcan\"\ninterface = \"unix:sock/can0\"\n" + loop,
      "t.toml", "/srv/site");
  CHECK(can_unix_path(s.buses[0]) == "/srv/site/sock/can0");  // relative to the file, like dbc
  s = parse_site_config(
      "[[bus]]\nname = \"c\"\nprotocol = \"socketcan\"\ninterface = \"can0\"\n" + loop, "t.toml");
  CHECK(can_unix_path(s.buses[0]) == "");
  auto e = error_of("[[bus]]\nname = \"c\"\nprotocol = \"socketcan\"\ninterface = \"unix:/" +
                    std::string(120, 'x') + "\"\n" + loop);
  CHECK(e.line() == 4);
  CHECK(std::string(e.what()).find("at most 107") != std::string::npos);
  e = error_of("[[bus]]\nname = \"c\"\nprotocol = \"socketcan\"\ninterface = \"unix:\"\n" + loop);
  CHECK(std::string(e.what()).find("no socket path") != std::string::npos);

  s = parse_site_config(std::string(kBus) +
                            "[[loop]]\nname = \"A\"\nbus = \"p\"\nsample_period = \"1s\"\n"
                            "op = { address = 0, type = \"FLOAT32\" }\n"
                            "pv = { address = 2, type = \"FLOAT32\" }\n"
                            "[[fault]]\nkind = \"freeze\"\naddress = 2\nstart = \"1s\"\n",
                        "t.toml");
  REQUIRE(s.faults.size() == 1);
  CHECK(s.faults[0].kind == FaultKind::freeze);
  CHECK(s.faults[0].address == 2);
  CHECK(s.faults[0].start_s == 1.0);
}

TEST_CASE("durations") {
  CHECK(parse_duration("500ms") == doctest::Approx(0.5));
  CHECK(parse_duration("10m") == doctest::Approx(600.0));
  CHECK(parse_duration("2") == doctest::Approx(2.0));
  CHECK(parse_duration("1.5h") == doctest::Approx(5400.0));
  CHECK(!parse_duration("-1s"));
  CHECK(!parse_duration("ms"));
  CHECK(!parse_duration("1e400"));
}

TEST_CASE("DBC: messages, signals, extended ids, multiplexing, errors with line numbers") {
  const Dbc d = load_dbc_file(kConfigs + "/plant.dbc");
  REQUIRE(d.messages.size() == 2);
  CHECK(d.messages[0].id == 291);
  CHECK(!d.messages[0].extended);
  CHECK(d.messages[1].extended);
  CHECK(d.messages[1].id == 0x322);
  REQUIRE(d.messages[0].signals.size() == 3);
  const auto& sp = d.messages[0].signals[2];
  CHECK(sp.name == "SP");
  CHECK(sp.signal.motorola);
  CHECK(sp.maximum == 200.0);
  CHECK(sp.unit == "m3/h");
  CHECK(d.messages[1].signals[1].signal.is_signed);

  const Dbc m = parse_dbc(
      "BO_ 100 MUX: 8 X\n SG_ Sel M : 0|8@1+ (1,0) [0|3] \"\" Y\n"
      " SG_ A m1 : 8|8@1+ (1,0) [0|3] \"\" Y\n",
      "m.dbc");
  CHECK(!m.messages[0].signals[0].multiplexed);
  CHECK(m.messages[0].signals[1].multiplexed);

  auto line_of = [](const char* text) {
    try {
      parse_dbc(text, "x.dbc");
    } catch (const DbcError& e) {
      return e.line();
    }
    return -1;
  };
  CHECK(line_of("VERSION \"\"\n SG_ A : 0|8@1+ (1,0) [0|1] \"\" X\n") == 2);   // before any BO_
  CHECK(line_of("BO_ 1 M: 8 X\n SG_ A : 0|8@2+ (1,0) [0|1] \"\" X\n") == 2);   // bad order
  CHECK(line_of("BO_ 1 M: 2 X\n SG_ A : 8|16@1+ (1,0) [0|1] \"\" X\n") == 2);  // beyond 2 bytes
  CHECK(line_of("BO_ 1 M: 8 X\n\n SG_ A : 0|8@1+ (1,0 [0|1] \"\" X\n") == 3);  // missing ')'
  CHECK(line_of("BO_ 4096 M: 8 X\n") == 1);  // 11-bit id too large
  CHECK(line_of("BO_ 1 M: 8 X\nBO_ 2 M: 8 X\n") == 2);
}

TEST_CASE("Modbus RTU over TCP: protocol, or Telegraf's transmission_mode, and their errors") {
  const std::string loop =
      "[[loop]]\nname = \"A\"\nbus = \"gw\"\nsample_period = \"1s\"\n"
      "op = { address = 0, type = \"FLOAT32\" }\npv = { address = 2, type = \"FLOAT32\" }\n";
  auto bus_of = [&](const std::string& keys) {
    return parse_site_config("[[bus]]\nname = \"gw\"\n" + keys + loop, "t.toml").buses.at(0);
  };
  // Our spelling, Telegraf's, and both together.
  for (const char* keys :
       {"protocol = \"modbus-rtu-over-tcp\"\n", "transmission_mode = \"RTUoverTCP\"\n",
        "protocol = \"modbus-rtu-over-tcp\"\ntransmission_mode = \"RTUoverTCP\"\n"}) {
    INFO(keys);
    const BusConfig b =
        bus_of(std::string(keys) + "controller = \"tcp://10.0.0.5:4001\"\nslave_id = 3\n");
    CHECK(b.kind == BusKind::modbus_rtu_over_tcp);
    CHECK(to_string(b.kind) == "modbus-rtu-over-tcp");
    CHECK(b.host == "10.0.0.5");
    CHECK(b.port == 4001);
    CHECK(b.slave_id == 3);
  }
  CHECK(bus_of("transmission_mode = \"RTUoverTCP\"\ncontroller = \"tcp://gw.plant\"\n").port ==
        502);
  // Telegraf's other modes name the existing protocols; "auto" goes by the controller.
  CHECK(bus_of("transmission_mode = \"TCP\"\ncontroller = \"tcp://10.0.0.5:502\"\n").kind ==
        BusKind::modbus_tcp);
  CHECK(bus_of("transmission_mode = \"auto\"\ncontroller = \"tcp://10.0.0.5:502\"\n").kind ==
        BusKind::modbus_tcp);
  CHECK(bus_of("transmission_mode = \"RTU\"\ncontroller = \"file:///dev/ttyUSB0\"\n").kind ==
        BusKind::modbus_rtu);
  CHECK(bus_of("transmission_mode = \"auto\"\ncontroller = \"file:///dev/ttyUSB0\"\n"
               "baud_rate = 9600\n")
            .kind == BusKind::modbus_rtu);
  CHECK(bus_of("protocol = \"modbus-tcp\"\ntransmission_mode = \"TCP\"\n"
               "controller = \"tcp://10.0.0.5:502\"\n")
            .kind == BusKind::modbus_tcp);

  auto error = [&](const std::string& keys) {
    return std::string(error_of("[[bus]]\nname = \"gw\"\n" + keys + loop).what());
  };
  CHECK(error("protocol = \"modbus-tcp\"\ntransmission_mode = \"RTUoverTCP\"\n"
              "controller = \"tcp://10.0.0.5:502\"\n") ==
        "t.toml:4:21: bus[0].transmission_mode: \"RTUoverTCP\" means protocol "
        "\"modbus-rtu-over-tcp\", but protocol is \"modbus-tcp\"; keep one of the two");
  CHECK(error("transmission_mode = \"rtuovertcp\"\ncontroller = \"tcp://10.0.0.5:502\"\n") ==
        "t.toml:3:21: bus[0].transmission_mode: 'rtuovertcp' must be \"TCP\", \"RTUoverTCP\", "
        "\"RTU\" or \"auto\" (Telegraf's spellings, case as shown), or remove it and give "
        "protocol = \"...\"");
  CHECK(error("transmission_mode = \"ASCIIoverTCP\"\ncontroller = \"tcp://10.0.0.5:502\"\n") ==
        "t.toml:3:21: bus[0].transmission_mode: Modbus ASCII is not supported; use \"TCP\", "
        "\"RTUoverTCP\" or \"RTU\"");
  CHECK(error("transmission_mode = 3\ncontroller = \"tcp://10.0.0.5:502\"\n") ==
        "t.toml:3:21: bus[0].transmission_mode: must be a string, got an integer");
  CHECK(error("protocol = \"modbus-rtu-over-tcp\"\ncontroller = \"file:///dev/ttyUSB0\"\n") ==
        "t.toml:4:14: bus[0].controller: 'file:///dev/ttyUSB0' must look like "
        "\"tcp://192.168.0.10:502\" (RTU over TCP goes to the gateway's TCP port; a serial line "
        "on this machine is protocol = \"modbus-rtu\")");
  CHECK(error("protocol = \"modbus-rtu\"\ncontroller = \"tcp://10.0.0.5:4001\"\n") ==
        "t.toml:4:14: bus[0].controller: 'tcp://10.0.0.5:4001' must look like "
        "\"file:///dev/ttyUSB0\" (for a gateway on the network write protocol = "
        "\"modbus-rtu-over-tcp\" or \"modbus-tcp\")");
  CHECK(error("transmission_mode = \"RTUoverTCP\"\ncontroller = \"tcp://10.0.0.5:0\"\n") ==
        "t.toml:4:14: bus[0].controller: port '0' is not 1..65535 (the port the gateway serves "
        "its serial line on, e.g. 4001)");
  CHECK(error("transmission_mode = \"RTUoverTCP\"\ncontroller = \"tcp://10.0.0.5:4001\"\n"
              "baud_rate = 9600\n") ==
        "t.toml:5:13: bus[0].baud_rate: does not apply to RTU over TCP: the gateway sets its "
        "serial line; remove it");
  CHECK(error("protocol = \"socketcan\"\ntransmission_mode = \"RTU\"\ninterface = \"can0\"\n") ==
        "t.toml:4:21: bus[0].transmission_mode: only applies to Modbus buses; remove it");
  CHECK(error("protocol = \"modbus-ascii\"\ncontroller = \"tcp://10.0.0.5:502\"\n") ==
        "t.toml:3:12: bus[0].protocol: 'modbus-ascii' is not a protocol; use modbus-tcp, "
        "modbus-rtu, modbus-rtu-over-tcp or socketcan");
  CHECK(error("controller = \"tcp://10.0.0.5:502\"\n") ==
        "t.toml:1:1: bus[0]: missing key 'protocol'; add protocol = \"...\"");
  CHECK(error("protocol = \"modbus-rtu-over-tcp\"\ncontroller = \"tcp://10.0.0.5:502\"\n"
              "transmision_mode = \"RTUoverTCP\"\n")
            .find("bus[0].transmision_mode: unknown key; remove it or use one of: name, protocol, "
                  "transmission_mode,") != std::string::npos);
}
