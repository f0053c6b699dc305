// Modbus RTU through a pseudo-terminal: the driver opens the pty's slave side as its serial
// device; a libmodbus RTU server answers on the master side. Checks framing (CRC), the decoded
// values, and that only function code 3 arrives.
#include <doctest/doctest.h>
#include <fcntl.h>
#include <modbus/modbus.h>
#include <poll.h>
#include <pty.h>
#include <termios.h>
#include <unistd.h>

#include <array>
#include <atomic>
#include <thread>

#include "valvediag/modbus_bus.hpp"

using namespace valvediag;

TEST_CASE("Modbus RTU over a pseudo-terminal: values decode, only function code 3 is sent") {
  int master = -1, slave = -1;
  char name[128] = {};
  REQUIRE(::openpty(&master, &slave, name, nullptr, nullptr) == 0);
  termios raw{};
  ::tcgetattr(slave, &raw);
  ::cfmakeraw(&raw);
  ::tcsetattr(slave, TCSANOW, &raw);

  // Server: an RTU context on the master fd (never "connected": it is handed the descriptor).
  modbus_t* srv = modbus_new_rtu("/dev/null", 19200, 'N', 8, 1);
  REQUIRE(srv);
  modbus_set_slave(srv, 7);
  modbus_set_socket(srv, master);
  modbus_mapping_t* map = modbus_mapping_new(0, 0, 16, 16);
  REQUIRE(map);
  std::uint16_t f[2];
  encode_registers(42.25, DataType::float32, ByteOrder::cdab, 1.0, 0.0, f);
  map->tab_registers[4] = f[0];
  map->tab_registers[5] = f[1];
  map->tab_registers[6] = static_cast<std::uint16_t>(-1234);  // INT16, scale 0.1
  std::array<std::atomic<int>, 256> counts{};
  std::atomic<bool> running{true};
  std::thread server([&] {
    std::uint8_t q[MODBUS_RTU_MAX_ADU_LENGTH];
    for (int i = 0; i < 200 && running; ++i) {  // bounded: at most 200 polls of 20 ms
      pollfd p{master, POLLIN, 0};
      if (::poll(&p, 1, 20) <= 0) continue;
      const int rc = modbus_receive(srv, q);
      if (rc > 0) {
        ++counts[q[1]];
        modbus_reply(srv, q, rc, map);
      }
    }
  });

  BusConfig b;
  b.name = "rtu";
  b.kind = BusKind::modbus_rtu;
  b.device = name;
  b.slave_id = 7;
  b.timeout_s = 0.5;
  LoopConfigEntry l;
  l.name = "TIC1";
  PointConfig& op = l.points[0];
  op.present = true;
  op.address = 4;
  op.type = DataType::float32;
  op.order = ByteOrder::cdab;
  PointConfig& pv = l.points[1];
  pv.present = true;
  pv.address = 6;
  pv.type = DataType::int16;
  pv.scale = 0.1;
  {
    ModbusBus bus(b, {l});
    const LoopValues v = bus.read(0);
    INFO(v.error);
    CHECK(v.error == "");
    CHECK(v[PointName::op].value == 42.25);
    CHECK(v[PointName::pv].value == doctest::Approx(-123.4));
    CHECK(bus.stats().requests == 1);
  }
  running = false;
  server.join();
  CHECK(counts[3] == 1);
  int others = 0;
  for (std::size_t fc = 0; fc < counts.size(); ++fc)
    if (fc != 3) others += counts[fc];
  CHECK(others == 0);
  modbus_mapping_free(map);
  modbus_free(srv);  // frees the context only: the pty ends are closed here
  ::close(master);
  ::close(slave);
}
