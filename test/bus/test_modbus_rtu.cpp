// Modbus RTU through a pseudo-terminal: the driver opens the pty's slave side as its serial
// device; a libmodbus RTU server answers on the master side. Checks framing (CRC), the decoded
// values, that only function codes 3 and 4 arrive, and the faults of a serial line: slow and
// missing replies, exceptions, bad CRC, truncated frames, and the adapter unplugged and back.
#include <doctest/doctest.h>
#include <fcntl.h>
#include <modbus/modbus.h>
#include <poll.h>
#include <pty.h>
#include <termios.h>
#include <unistd.h>

#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <mutex>
#include <thread>

#include "bus_test_util.hpp"
#include "valvediag/drivers/modbus_bus.hpp"
#include "valvediag/drivers/modbus_rtu_over_tcp.hpp"  // modbus_crc16

using namespace valvediag;
using Clock = std::chrono::steady_clock;
namespace fs = std::filesystem;

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

namespace {

// A Modbus RTU device (slave 7) at the end of a pseudo-terminal, reached through a symbolic link
// as a USB serial adapter is through /dev/serial/by-id: unplug() closes the pty and removes the
// link, plug() puts a new pty behind the same link. Faults apply to the next `fault_count`
// requests. Loop A's op lives at holding registers 0..1 and its pv at holding 2 and input 0;
// loop B's at 10..12 and 10: the same layout, so a reply meant for one would pass for the other's.
class RtuDevice {
 public:
  enum class Fault { none, delay, silent, exception, bad_crc, truncated };

  explicit RtuDevice(fs::path link) : link_(std::move(link)) {
    map_ = modbus_mapping_new(0, 0, 32, 32);
    REQUIRE(map_);
    set_values(0, 11.0, 111);
    set_values(10, 22.0, 222);
    plug();
  }
  ~RtuDevice() {
    unplug();
    modbus_mapping_free(map_);
  }

  void set_values(int address, double op, int pv) {
    std::lock_guard lock(mutex_);
    encode_registers(op, DataType::float32, ByteOrder::abcd, 1.0, 0.0,
                     std::span<std::uint16_t>(map_->tab_registers + address, 2));
    map_->tab_registers[address + 2] = static_cast<std::uint16_t>(pv);
    map_->tab_input_registers[address] = static_cast<std::uint16_t>(pv);
  }
  void fault(Fault f, int count = 1, double delay_s = 0.0) {
    std::lock_guard lock(mutex_);
    fault_ = f;
    fault_count_ = count;
    delay_s_ = delay_s;
  }

  void plug() {
    char name[128] = {};
    REQUIRE(::openpty(&master_, &slave_, name, nullptr, nullptr) == 0);
    termios raw{};
    ::tcgetattr(slave_, &raw);
    ::cfmakeraw(&raw);
    ::tcsetattr(slave_, TCSANOW, &raw);
    fs::remove(link_);
    fs::create_symlink(name, link_);
    srv_ = modbus_new_rtu("/dev/null", 19200, 'N', 8, 1);
    REQUIRE(srv_);
    modbus_set_slave(srv_, 7);
    modbus_set_socket(srv_, master_);
    running_ = true;
    thread_ = std::thread([this] { serve(); });
  }
  void unplug() {
    if (!thread_.joinable()) return;
    running_ = false;
    thread_.join();
    modbus_free(srv_);
    ::close(master_);  // the driver's descriptor hangs up: EIO on write, EOF on read
    ::close(slave_);
    fs::remove(link_);
  }

  int count(int fc) const { return counts_[static_cast<std::size_t>(fc)].load(); }
  int other_than_3_and_4() const {
    int n = 0;
    for (std::size_t fc = 0; fc < counts_.size(); ++fc)
      if (fc != 3 && fc != 4) n += counts_[fc].load();
    return n;
  }

 private:
  void serve() {
    std::uint8_t q[MODBUS_RTU_MAX_ADU_LENGTH];
    while (running_) {
      pollfd p{master_, POLLIN, 0};
      if (::poll(&p, 1, 20) <= 0) continue;
      const int rc = modbus_receive(srv_, q);
      if (rc <= 0) continue;
      ++counts_[q[1]];
      Fault f = Fault::none;
      double delay = 0.0;
      {
        std::lock_guard lock(mutex_);
        if (fault_count_ > 0) {
          --fault_count_;
          f = fault_;
          delay = delay_s_;
        }
      }
      if (f == Fault::silent) continue;
      if (f == Fault::delay) std::this_thread::sleep_for(std::chrono::duration<double>(delay));
      if (f == Fault::exception) {
        modbus_reply_exception(srv_, q, MODBUS_EXCEPTION_ILLEGAL_DATA_ADDRESS);
        continue;
      }
      if (f == Fault::bad_crc || f == Fault::truncated) {
        send_raw(q, f);
        continue;
      }
      std::lock_guard lock(mutex_);
      modbus_reply(srv_, q, rc, map_);
    }
  }

  // A read reply built by hand: with its CRC spoiled, or cut off half-way.
  void send_raw(const std::uint8_t* q, Fault f) {
    const int address = (q[2] << 8) | q[3], n = (q[4] << 8) | q[5];
    std::uint8_t r[300];
    r[0] = q[0];
    r[1] = q[1];
    r[2] = static_cast<std::uint8_t>(2 * n);
    {
      std::lock_guard lock(mutex_);
      const std::uint16_t* tab = q[1] == 3 ? map_->tab_registers : map_->tab_input_registers;
      for (int i = 0; i < n; ++i) {
        r[3 + 2 * i] = static_cast<std::uint8_t>(tab[address + i] >> 8);
        r[4 + 2 * i] = static_cast<std::uint8_t>(tab[address + i] & 0xff);
      }
    }
    const std::size_t len = 3 + 2 * static_cast<std::size_t>(n);
    const std::uint16_t crc = modbus_crc16(std::span(r, len));
    r[len] = static_cast<std::uint8_t>(crc & 0xff);
    r[len + 1] = static_cast<std::uint8_t>((crc >> 8) ^ (f == Fault::bad_crc ? 0x5A : 0));
    const std::size_t send = f == Fault::truncated ? len - 1 : len + 2;
    CHECK(::write(master_, r, send) == static_cast<ssize_t>(send));
  }

  fs::path link_;
  int master_ = -1, slave_ = -1;
  modbus_t* srv_ = nullptr;
  modbus_mapping_t* map_ = nullptr;
  std::mutex mutex_;
  Fault fault_ = Fault::none;
  int fault_count_ = 0;
  double delay_s_ = 0.0;
  std::array<std::atomic<int>, 256> counts_{};
  std::atomic<bool> running_{false};
  std::thread thread_;
};

// op and pv of a loop; pv in an input register (two requests) or next to op (one request).
LoopConfigEntry rtu_loop(const std::string& name, int address, RegisterType pv_reg) {
  LoopConfigEntry l;
  l.name = name;
  l.bus = "rtu";
  PointConfig& op = l.points[0];
  op.present = true;
  op.address = address;
  op.type = DataType::float32;
  PointConfig& pv = l.points[1];
  pv.present = true;
  pv.reg = pv_reg;
  pv.address = pv_reg == RegisterType::input ? address : address + 2;
  pv.type = DataType::int16;
  return l;
}

struct RtuFixture {
  fs::path link =
      fs::temp_directory_path() / ("valvediag-rtu-" + std::to_string(::getpid()) + "-ttyUSB0");
  RtuDevice dev{link};
  BusConfig cfg = [this] {
    BusConfig b;
    b.name = "rtu";
    b.kind = BusKind::modbus_rtu;
    b.device = link.string();
    b.slave_id = 7;
    b.timeout_s = 0.15;
    b.retries = 0;
    b.reconnect_max_s = 0.2;
    return b;
  }();
  std::vector<LoopConfigEntry> loops{rtu_loop("A", 0, RegisterType::input),
                                     rtu_loop("B", 10, RegisterType::input)};
};

void check_good(const LoopValues& v, double op, double pv) {
  INFO(v.error);
  CHECK(v.error == "");
  CHECK(v[PointName::op].quality == Quality::good);
  CHECK(v[PointName::op].value == op);
  CHECK(v[PointName::pv].quality == Quality::good);
  CHECK(v[PointName::pv].value == pv);
}

}  // namespace

TEST_CASE(
    "Modbus RTU faults: exception, no reply, bad CRC, truncated frame; counted, flagged, "
    "recovered") {
  RtuFixture fx;
  ModbusBus bus(fx.cfg, fx.loops);
  check_good(test::timed_read(bus, 0), 11.0, 111);

  // Each fault hits the loop's first request (holding registers: op); pv comes on its own.
  struct Case {
    RtuDevice::Fault fault;
    std::uint64_t BusStats::*counter;
    const char* what;
  };
  const Case cases[] = {
      {RtuDevice::Fault::exception, &BusStats::exceptions, "Illegal data address"},
      {RtuDevice::Fault::silent, &BusStats::timeouts, "timed out"},
      {RtuDevice::Fault::bad_crc, &BusStats::garbled, "CRC"},
      {RtuDevice::Fault::truncated, &BusStats::timeouts, "timed out"},
  };
  for (const Case& c : cases) {
    INFO("fault ", static_cast<int>(c.fault));
    const BusStats before = bus.stats();
    fx.dev.fault(c.fault);
    LoopValues v = test::timed_read(bus, 0);
    CHECK(v[PointName::op].quality == Quality::comm_error);
    CHECK(std::isnan(v[PointName::op].value));
    CHECK(v[PointName::pv].quality == Quality::good);
    CHECK(v.error.find("holding registers 0..1 on " + fx.link.string()) != std::string::npos);
    CHECK(v.error.find(c.what) != std::string::npos);
    const BusStats after = bus.stats();
    CHECK(after.*(c.counter) == before.*(c.counter) + 1);
    CHECK(after.errors == before.errors + 1);
    check_good(test::timed_read(bus, 0), 11.0, 111);  // the next read is clean
  }
  CHECK(bus.stats().disconnects == 0);  // a fault on the line is not a lost link
  CHECK(fx.dev.count(3) >= 9);
  CHECK(fx.dev.count(4) >= 9);
  CHECK(fx.dev.other_than_3_and_4() == 0);
}

TEST_CASE("Modbus RTU: a reply later than the timeout is never taken for the next one") {
  RtuFixture fx;
  fx.cfg.timeout_s = 0.3;
  // One request per loop, so that the request after A's is B's, with the same function code
  // and register count.
  fx.loops = {rtu_loop("A", 0, RegisterType::holding), rtu_loop("B", 10, RegisterType::holding)};
  {
    ModbusBus bus(fx.cfg, fx.loops);
    check_good(test::timed_read(bus, 0), 11.0, 111);
    // A's holding reply comes 0.4 s after the request, 0.1 s after the driver gave up. Modbus
    // RTU has no transaction id: read at once, B (same layout) would get A's late reply.
    fx.dev.fault(RtuDevice::Fault::delay, 1, 0.4);
    const LoopValues a = test::timed_read(bus, 0);
    CHECK(a[PointName::op].quality == Quality::comm_error);
    CHECK(bus.stats().timeouts == 1);
    check_good(test::timed_read(bus, 1), 22.0, 222);
    check_good(test::timed_read(bus, 0), 11.0, 111);
    check_good(test::timed_read(bus, 1), 22.0, 222);
  }
  // With a retry the late reply is dropped and the second attempt answers the read.
  fx.cfg.retries = 1;
  ModbusBus bus(fx.cfg, fx.loops);
  check_good(test::timed_read(bus, 1), 22.0, 222);
  fx.dev.fault(RtuDevice::Fault::delay, 1, 0.4);
  check_good(test::timed_read(bus, 0), 11.0, 111);
  CHECK(bus.stats().timeouts == 1);
  CHECK(bus.stats().requests == 3);  // B once, A twice
  check_good(test::timed_read(bus, 1), 22.0, 222);
  CHECK(fx.dev.other_than_3_and_4() == 0);
}

TEST_CASE("Modbus RTU: the serial adapter unplugged and plugged back") {
  RtuFixture fx;
  ModbusBus bus(fx.cfg, fx.loops);
  check_good(test::timed_read(bus, 0), 11.0, 111);
  fx.dev.unplug();
  // Away: every read fails fast with the device named; no hang, no reconnection storm.
  test::check_reads_while_away(bus, 0, fx.link.string(), "No such file or directory");
  fx.dev.set_values(0, 33.0, 333);
  fx.dev.plug();
  // Back: within the backoff cap (0.2 s) plus a read, polled with a generous deadline.
  LoopValues v;
  CHECK(test::wait_for([&] { return (v = test::timed_read(bus, 0)).error.empty(); }, 10.0));
  check_good(v, 33.0, 333);
  const BusStats st = bus.stats();
  CHECK(st.connected);
  CHECK(st.reconnects == 1);
  CHECK(fx.dev.other_than_3_and_4() == 0);
}
