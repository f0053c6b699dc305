// Modbus RTU over TCP against a gateway in a thread: a listening socket on a free loopback port
// that parses RTU requests and answers from its register table, as a serial-to-Ethernet gateway
// in front of unit 7 would. The bus is configured from a site file as Telegraf users write it.
// Faults are injected at configured registers: bad CRC, exception, silence, a wrong unit id or
// function code, truncated and oversized frames, the connection dropped mid-frame, a late reply.
// Every case is counted, flagged, bounded in time and followed by a clean read; the gateway checks
// that only function codes 3 and 4 ever arrive.
#include <doctest/doctest.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <map>
#include <mutex>
#include <thread>
#include <vector>

#include "bus_test_util.hpp"
#include "valvediag/drivers/modbus_bus.hpp"
#include "valvediag/drivers/modbus_rtu_over_tcp.hpp"

using namespace valvediag;
using Clock = std::chrono::steady_clock;

namespace {

constexpr int kUnit = 7;

// A gateway that passes RTU frames to unit 7 and back. One client at a time: a new connection
// replaces the old one, as single-connection gateways do.
class RtuGateway {
 public:
  enum class Fault {
    none,
    bad_crc,     // the reply's CRC spoiled
    exception,   // function | 0x80 and exception_code
    silent,      // no reply
    wrong_unit,  // a valid frame from unit 9
    wrong_fc,    // a valid frame with the other read function code
    truncated,   // the reply without its last 3 bytes, the connection kept open
    oversized,   // two registers more than asked for, with a valid CRC
    drop,        // 3 bytes of the reply, then the connection closed
    late,        // the reply after `delay_s`
    close,       // the connection closed instead of a reply
  };

  // Listens on 127.0.0.1:port (0: a free port, kept across stop() and start()).
  explicit RtuGateway(int port = 0) : port_(port) {
    set_values(0, 11.5, 111);
    set_values(10, 22.5, 222);
    start();
  }
  ~RtuGateway() { stop(); }

  int port() const { return port_; }

  // A loop's op (FLOAT32 ABCD) at holding `address`, pv (INT16, scale 0.1) at holding address + 2
  // and input `address`.
  void set_values(int address, double op, int pv_raw) {
    std::lock_guard lock(mutex_);
    encode_registers(op, DataType::float32, ByteOrder::abcd, 1.0, 0.0,
                     std::span<std::uint16_t>(holding_.data() + address, 2));
    holding_[static_cast<std::size_t>(address) + 2] = static_cast<std::uint16_t>(pv_raw);
    input_[static_cast<std::size_t>(address)] = static_cast<std::uint16_t>(pv_raw);
  }

  // The next `count` requests whose range covers `address` of register type `reg` get `fault`.
  void fault(Fault f, RegisterType reg, int address, int count = 1, double delay_s = 0.0) {
    std::lock_guard lock(mutex_);
    faults_.push_back({f, reg, address, count, delay_s});
  }

  void start() {
    listen_ = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
    REQUIRE(listen_ >= 0);
    const int one = 1;
    ::setsockopt(listen_, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    a.sin_port = htons(static_cast<std::uint16_t>(port_));
    REQUIRE(::bind(listen_, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0);
    REQUIRE(::listen(listen_, 4) == 0);
    socklen_t len = sizeof a;
    ::getsockname(listen_, reinterpret_cast<sockaddr*>(&a), &len);
    port_ = ntohs(a.sin_port);
    running_ = true;
    thread_ = std::thread([this] { serve(); });
  }
  void stop() {
    if (!thread_.joinable()) return;
    running_ = false;
    thread_.join();
    close_client();
    ::close(listen_);
    listen_ = -1;
  }

  // Closes the client's connection between requests (a gateway's idle timeout); returns once
  // it is closed.
  void close_connection() {
    kick_ = true;
    REQUIRE(test::wait_for([&] { return !kick_; }, 5.0));
  }

  int count(int fc) const { return counts_[static_cast<std::size_t>(fc)].load(); }
  int other_than_3_and_4() const {
    int n = 0;
    for (std::size_t fc = 0; fc < counts_.size(); ++fc)
      if (fc != 3 && fc != 4) n += counts_[fc].load();
    return n;
  }
  int requests() const { return count(3) + count(4) + other_than_3_and_4(); }
  int connections() const { return connections_.load(); }
  int bad_requests() const { return bad_requests_.load(); }  // wrong CRC, length or unit

 private:
  struct FaultAt {
    Fault fault;
    RegisterType reg;
    int address, count;
    double delay_s;
  };

  void close_client() {
    if (client_ >= 0) ::close(client_);
    client_ = -1;
    pending_.clear();
  }

  void serve() {
    while (running_) {
      if (kick_) {
        close_client();
        kick_ = false;
      }
      pollfd p[2] = {{listen_, POLLIN, 0}, {client_, POLLIN, 0}};
      if (::poll(p, client_ >= 0 ? 2 : 1, 20) <= 0) continue;
      if (p[0].revents & POLLIN) {
        const int c = ::accept4(listen_, nullptr, nullptr, SOCK_CLOEXEC);
        if (c >= 0) {
          close_client();
          client_ = c;
          ++connections_;
        }
        continue;
      }
      if (client_ < 0 || !(p[1].revents & (POLLIN | POLLHUP | POLLERR))) continue;
      std::uint8_t buf[512];
      const ssize_t n = ::recv(client_, buf, sizeof buf, 0);
      if (n <= 0) {
        close_client();
        continue;
      }
      pending_.insert(pending_.end(), buf, buf + n);
      // Every read request is 8 bytes; anything else is counted by its function code and
      // dropped (a write would be refused here, and fail the test).
      while (pending_.size() >= 2) {
        const std::uint8_t fc = pending_[1];
        if (fc != 3 && fc != 4) {
          ++counts_[fc];
          pending_.clear();
          break;
        }
        if (pending_.size() < 8) break;
        std::array<std::uint8_t, 8> q;
        std::copy(pending_.begin(), pending_.begin() + 8, q.begin());
        pending_.erase(pending_.begin(), pending_.begin() + 8);
        ++counts_[fc];
        answer(q);
        if (client_ < 0) break;
      }
    }
  }

  void answer(const std::array<std::uint8_t, 8>& q) {
    const std::uint16_t crc = modbus_crc16(std::span(q).first(6));
    if (q[0] != kUnit || q[6] != (crc & 0xff) || q[7] != (crc >> 8)) {
      ++bad_requests_;
      return;  // a device ignores a frame that is not for it or fails its CRC
    }
    const RegisterType reg = q[1] == 3 ? RegisterType::holding : RegisterType::input;
    const int address = (q[2] << 8) | q[3], n = (q[4] << 8) | q[5];
    Fault f = Fault::none;
    double delay_s = 0.0;
    std::vector<std::uint8_t> r = {q[0], q[1]};
    {
      std::lock_guard lock(mutex_);
      for (auto& fa : faults_)
        if (fa.count > 0 && fa.reg == reg && fa.address >= address && fa.address < address + n) {
          --fa.count;
          f = fa.fault;
          delay_s = fa.delay_s;
          break;
        }
      if (address + n > static_cast<int>(holding_.size())) {
        f = Fault::exception;
      } else {
        const int regs = f == Fault::oversized ? n + 2 : n;
        r.push_back(static_cast<std::uint8_t>(2 * regs));
        const auto& tab = reg == RegisterType::holding ? holding_ : input_;
        for (int i = 0; i < regs; ++i) {
          const std::uint16_t v = tab[static_cast<std::size_t>(address + i) % tab.size()];
          r.push_back(static_cast<std::uint8_t>(v >> 8));
          r.push_back(static_cast<std::uint8_t>(v & 0xff));
        }
      }
    }
    if (f == Fault::silent) return;
    if (f == Fault::close) {
      close_client();
      return;
    }
    if (f == Fault::exception) r = {q[0], static_cast<std::uint8_t>(q[1] | 0x80), 2};
    if (f == Fault::wrong_unit) r[0] = 9;
    if (f == Fault::wrong_fc) r[1] = q[1] == 3 ? 4 : 3;
    const std::uint16_t rcrc = modbus_crc16(r);
    r.push_back(static_cast<std::uint8_t>(rcrc & 0xff));
    r.push_back(static_cast<std::uint8_t>(rcrc >> 8));
    if (f == Fault::bad_crc) r.back() ^= 0x5A;
    std::size_t send = r.size();
    if (f == Fault::truncated) send -= 3;
    if (f == Fault::drop) send = 3;
    if (f == Fault::late) std::this_thread::sleep_for(std::chrono::duration<double>(delay_s));
    // A send to a client that went away (the driver gave up on a late reply) fails: ignored.
    (void)::send(client_, r.data(), send, MSG_NOSIGNAL);
    if (f == Fault::drop) close_client();
  }

  int port_;
  int listen_ = -1, client_ = -1;
  std::vector<std::uint8_t> pending_;
  std::mutex mutex_;
  std::array<std::uint16_t, 64> holding_{}, input_{};
  std::vector<FaultAt> faults_;
  std::array<std::atomic<int>, 256> counts_{};
  std::atomic<int> connections_{0}, bad_requests_{0};
  std::atomic<bool> running_{false}, kick_{false};
  std::thread thread_;
};

// Loops A and B have the same layout ten registers apart: a reply meant for one would pass for
// the other's. pv in an input register (two requests a read) or next to op (one request).
std::string site_text(int port, const std::string& pv_register, const std::string& bus_extra) {
  const std::string pv_a = pv_register == "input" ? "0" : "2";
  const std::string pv_b = pv_register == "input" ? "10" : "12";
  return "[[bus]]\nname = \"gw\"\ncontroller = \"tcp://127.0.0.1:" + std::to_string(port) +
         "\"\ntransmission_mode = \"RTUoverTCP\"\nslave_id = 7\n" + bus_extra +
         "[[loop]]\nname = \"A\"\nbus = \"gw\"\nsample_period = \"1s\"\n"
         "op = { register = \"holding\", address = 0, data_type = \"FLOAT32-IEEE\" }\n"
         "pv = { register = \"" +
         pv_register + "\", address = " + pv_a +
         ", data_type = \"INT16\", scale = 0.1 }\n"
         "[[loop]]\nname = \"B\"\nbus = \"gw\"\nsample_period = \"1s\"\n"
         "op = { register = \"holding\", address = 10, data_type = \"FLOAT32-IEEE\" }\n"
         "pv = { register = \"" +
         pv_register + "\", address = " + pv_b + ", data_type = \"INT16\", scale = 0.1 }\n";
}

struct Fixture {
  RtuGateway gw;
  SiteConfig site;
  explicit Fixture(const std::string& pv_register = "input",
                   const std::string& bus_extra =
                       "timeout = \"150ms\"\nretries = 0\n"
                       "reconnect_max = \"200ms\"\n")
      : site(parse_site_config(site_text(gw.port(), pv_register, bus_extra), "gw.toml")) {}
  ModbusBus bus() { return ModbusBus(site.buses[0], site.loops); }
};

// op exact to a float's precision, pv to half a count of its 0.1 scale.
void check_good(const LoopValues& v, double op, double pv) {
  INFO(v.error);
  CHECK(v.error == "");
  CHECK(v[PointName::op].quality == Quality::good);
  CHECK(std::fabs(v[PointName::op].value - op) <= 1e-6 * std::fabs(op));
  CHECK(v[PointName::pv].quality == Quality::good);
  CHECK(std::fabs(v[PointName::pv].value - pv) <= 0.05 + 1e-9);
}

}  // namespace

TEST_CASE("CRC-16/MODBUS matches the specification's frames") {
  const std::uint8_t read10[] = {0x01, 0x03, 0x00, 0x00, 0x00, 0x0A};  // sent as ... C5 CD
  CHECK(modbus_crc16(read10) == 0xCDC5);
  const std::uint8_t read1[] = {0x01, 0x03, 0x00, 0x00, 0x00, 0x01};  // sent as ... 84 0A
  CHECK(modbus_crc16(read1) == 0x0A84);
  CHECK(modbus_crc16({}) == 0xFFFF);
}

TEST_CASE("RTU over TCP: a Telegraf-style bus reads the gateway's values with function 3 and 4") {
  Fixture fx;
  REQUIRE(fx.site.buses[0].kind == BusKind::modbus_rtu_over_tcp);
  ModbusBus bus = fx.bus();
  check_good(test::timed_read(bus, 0), 11.5, 11.1);
  check_good(test::timed_read(bus, 1), 22.5, 22.2);
  fx.gw.set_values(0, -3.25, -42);
  check_good(test::timed_read(bus, 0), -3.25, -4.2);
  const BusStats st = bus.stats();
  CHECK(st.requests == 6);
  CHECK(st.errors == 0);
  CHECK(st.connected);
  CHECK(st.connect_attempts == 1);
  CHECK(fx.gw.connections() == 1);
  CHECK(fx.gw.count(3) == 3);
  CHECK(fx.gw.count(4) == 3);
  CHECK(fx.gw.other_than_3_and_4() == 0);
  CHECK(fx.gw.bad_requests() == 0);
}

TEST_CASE("RTU over TCP faults: counted, flagged, bounded, and the next read is clean") {
  Fixture fx;
  ModbusBus bus = fx.bus();
  check_good(test::timed_read(bus, 0), 11.5, 11.1);

  // Each fault hits loop A's holding request (op); pv comes from the input request on its own.
  using F = RtuGateway::Fault;
  struct Case {
    F fault;
    std::uint64_t BusStats::*counter;
    const char* what;
    bool reconnects;
  };
  const Case cases[] = {
      {F::exception, &BusStats::exceptions, "exception 2: Illegal data address", false},
      {F::bad_crc, &BusStats::garbled, "invalid CRC", true},
      {F::wrong_unit, &BusStats::garbled, "reply from unit 9 to a request to unit 7", true},
      {F::wrong_fc, &BusStats::garbled,
       "reply with function code 4 to a request with function "
       "code 3",
       true},
      {F::oversized, &BusStats::garbled, "reply with 8 data bytes to a request for 2 registers",
       true},
      {F::silent, &BusStats::timeouts, "timed out: no reply within 0.15 s", true},
      {F::truncated, &BusStats::timeouts, "stopped after 6 of 9 bytes (truncated)", true},
      {F::drop, &BusStats::disconnects, "connection closed by the peer after 3 bytes", true},
  };
  for (const Case& c : cases) {
    INFO("fault ", static_cast<int>(c.fault));
    const BusStats before = bus.stats();
    const int connections = fx.gw.connections();
    fx.gw.fault(c.fault, RegisterType::holding, 0);
    const LoopValues v = test::timed_read(bus, 0);
    CHECK(v[PointName::op].quality == Quality::comm_error);
    CHECK(std::isnan(v[PointName::op].value));
    CHECK(v.error.find("holding registers 0..1 on 127.0.0.1:" + std::to_string(fx.gw.port()) +
                       " (RTU over TCP): ") != std::string::npos);
    CHECK(v.error.find(c.what) != std::string::npos);
    // After a bad reply the connection is new before pv's request: nothing late is taken.
    CHECK(v[PointName::pv].quality == Quality::good);
    const BusStats after = bus.stats();
    CHECK(after.*(c.counter) == before.*(c.counter) + 1);
    CHECK(after.errors == before.errors + 1);
    CHECK(after.requests == before.requests + 2);
    CHECK(after.reconnects == before.reconnects + (c.reconnects ? 1 : 0));
    CHECK(fx.gw.connections() == connections + (c.reconnects ? 1 : 0));
    check_good(test::timed_read(bus, 0), 11.5, 11.1);
  }
  CHECK(bus.stats().connected);
  CHECK(fx.gw.other_than_3_and_4() == 0);
  CHECK(fx.gw.bad_requests() == 0);
}

TEST_CASE("RTU over TCP: a reply later than the timeout is never taken for the next one") {
  // One request a loop, so that the request after A's is B's, with the same function code and
  // register count: without a transaction id only the new connection tells them apart.
  Fixture fx("holding", "timeout = \"300ms\"\nretries = 0\n");
  ModbusBus bus = fx.bus();
  check_good(test::timed_read(bus, 0), 11.5, 11.1);
  // A's reply comes 0.1 s after the driver gave up, while B's request waits for the gateway.
  fx.gw.fault(RtuGateway::Fault::late, RegisterType::holding, 0, 1, 0.4);
  const LoopValues a = test::timed_read(bus, 0);
  CHECK(a[PointName::op].quality == Quality::comm_error);
  CHECK(a[PointName::pv].quality == Quality::comm_error);
  CHECK(bus.stats().timeouts == 1);
  check_good(test::timed_read(bus, 1), 22.5, 22.2);
  check_good(test::timed_read(bus, 0), 11.5, 11.1);
  check_good(test::timed_read(bus, 1), 22.5, 22.2);
  CHECK(bus.stats().errors == 1);
  CHECK(fx.gw.other_than_3_and_4() == 0);
}

TEST_CASE("RTU over TCP: a retry recovers a lost reply, and a connection the gateway closed") {
  Fixture fx("holding", "timeout = \"150ms\"\nretries = 1\n");
  ModbusBus bus = fx.bus();
  check_good(test::timed_read(bus, 0), 11.5, 11.1);
  fx.gw.fault(RtuGateway::Fault::silent, RegisterType::holding, 0);
  check_good(test::timed_read(bus, 0), 11.5, 11.1);
  CHECK(bus.stats().timeouts == 1);
  CHECK(bus.stats().requests == 3);
  // Closed while idle: found closed before the request is sent; the retry reconnects.
  fx.gw.close_connection();
  check_good(test::timed_read(bus, 1), 22.5, 22.2);
  // Closed instead of a reply.
  fx.gw.fault(RtuGateway::Fault::close, RegisterType::holding, 0);
  check_good(test::timed_read(bus, 0), 11.5, 11.1);
  const BusStats st = bus.stats();
  CHECK(st.errors == 3);
  CHECK(st.disconnects == 2);
  CHECK(st.reconnects == 3);
  CHECK(st.last_error.find("connection closed by the peer before the reply") != std::string::npos);
  CHECK(fx.gw.connections() == 4);
  CHECK(fx.gw.other_than_3_and_4() == 0);
}

TEST_CASE("RTU over TCP: the gateway away, then back on its port") {
  Fixture fx("holding", "timeout = \"150ms\"\nretries = 0\nreconnect_max = \"200ms\"\n");
  ModbusBus bus = fx.bus();
  check_good(test::timed_read(bus, 0), 11.5, 11.1);
  fx.gw.stop();
  // Away: every read fails fast, naming the gateway; no hang, no reconnection storm.
  test::check_reads_while_away(bus, 0,
                               "127.0.0.1:" + std::to_string(fx.gw.port()) + " (RTU over TCP)",
                               "Connection refused");
  CHECK(bus.stats().disconnects == 1);  // the closed connection, found before a request
  fx.gw.set_values(0, 33.5, 333);
  fx.gw.start();
  LoopValues v;
  CHECK(test::wait_for([&] { return (v = test::timed_read(bus, 0)).error.empty(); }, 10.0));
  check_good(v, 33.5, 33.3);
  const BusStats st = bus.stats();
  CHECK(st.connected);
  CHECK(st.reconnects == 1);
  CHECK(fx.gw.other_than_3_and_4() == 0);
}

TEST_CASE("RTU over TCP: a gateway that never accepts fails at the connect timeout") {
  // A listener whose accept queue is full: the kernel drops the next SYN, so connect() waits.
  const int l = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  REQUIRE(::bind(l, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0);
  REQUIRE(::listen(l, 0) == 0);
  socklen_t len = sizeof a;
  ::getsockname(l, reinterpret_cast<sockaddr*>(&a), &len);
  std::vector<int> fill;
  for (int i = 0; i < 4; ++i) {
    const int c = ::socket(AF_INET, SOCK_STREAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
    ::connect(c, reinterpret_cast<sockaddr*>(&a), sizeof a);
    fill.push_back(c);
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(50));
  const SiteConfig site = parse_site_config(
      site_text(ntohs(a.sin_port), "holding", "timeout = \"200ms\"\nretries = 0\n"), "gw.toml");
  ModbusBus bus(site.buses[0], site.loops);
  const auto t0 = Clock::now();
  const LoopValues v = bus.read(0);
  const double took = std::chrono::duration<double>(Clock::now() - t0).count();
  INFO(v.error);
  CHECK(v[PointName::op].quality == Quality::comm_error);
  CHECK(v.error.find("no connection within 0.2 s") != std::string::npos);
  CHECK(took >= 0.15);
  CHECK(took < 2.0);
  CHECK(bus.stats().requests == 0);
  for (int c : fill) ::close(c);
  ::close(l);
}
