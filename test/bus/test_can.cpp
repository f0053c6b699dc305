// CAN: the decoding path through candump log replay and through a frame-level mock transport (a
// socketpair carrying struct can_frame, fed by the simulated PLC); the SocketCAN driver's
// message on a kernel without CAN; nothing is ever sent.
#include <doctest/doctest.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <cmath>

#include "bus_test_util.hpp"
#include "valvediag/can_bus.hpp"
#include "valvediag/sim_plc.hpp"

using namespace valvediag;
using Clock = std::chrono::steady_clock;

namespace {
const std::string kCanSite = std::string(VALVEDIAG_CONFIG_DIR) + "/can-site.toml";
}

TEST_CASE("candump lines") {
  auto f = parse_candump_line("(1436509052.249713) vcan0 123#DEADBEEF");
  REQUIRE(f);
  CHECK(f->id == 0x123);
  CHECK(!f->extended);
  CHECK(f->dlc == 4);
  CHECK(f->data[0] == 0xDE);
  CHECK(f->data[3] == 0xEF);
  f = parse_candump_line("(0.5) can1 18FEF100#0102");
  REQUIRE(f);
  CHECK(f->extended);
  CHECK(f->id == 0x18FEF100);
  CHECK(!parse_candump_line(""));
  CHECK(!parse_candump_line("(1.0) can0 123#R"));
  CHECK_THROWS_AS(parse_candump_line("(1.0) can0 12#00"), std::invalid_argument);
  CHECK_THROWS_AS(parse_candump_line("(1.0) can0 123#0G"), std::invalid_argument);
  CHECK_THROWS_AS(parse_candump_line("can0 123#00"), std::invalid_argument);
  CHECK_THROWS_AS(parse_candump_line("(1.0) can0 123#001122334455667788"), std::invalid_argument);
  try {
    CandumpReplay("(1.0) can0 123#00\n\n(2.0) can0 123#0\n", "dump.log");
    FAIL("no error");
  } catch (const std::invalid_argument& e) {
    CHECK(std::string(e.what()).rfind("dump.log:3:", 0) == 0);
  }
}

TEST_CASE("candump replay decodes the DBC signals of configs/can-site.toml") {
  const SiteConfig site = load_site_config(kCanSite);
  // FIC101 (0x123): OP 45.67 % Intel, PV 123.45 Intel, SP 100.00 Motorola in bytes 4..5.
  // TIC205 (extended 0x322): OP 55.50 % Motorola bytes 0..1, PV 20.0 = (700 * 0.1 - 50) signed.
  CandumpReplay replay(
      "(1436509052.100000) can0 123#D711393027100000\n"
      "(1436509052.200000) can0 00000322#15AE02BC00000000\n"
      "(1436509052.300000) can0 7FF#00\n",
      "replay.log");
  CHECK(replay.size() == 3);
  CanDecoder dec(site.loops);
  const auto now = Clock::now();
  std::size_t updated = 0;
  for (int i = 0; i < 3; ++i) updated += dec.apply(*replay.receive(0.0), now);
  CHECK(updated == 5);
  LoopValues a = dec.values(0, now);
  CHECK(a.error == "");
  CHECK(a[PointName::op].value == doctest::Approx(45.67).epsilon(1e-12));
  CHECK(a[PointName::pv].value == doctest::Approx(123.45).epsilon(1e-12));
  CHECK(a[PointName::sp].value == doctest::Approx(100.0).epsilon(1e-12));
  LoopValues b = dec.values(1, now);
  CHECK(b[PointName::op].value == doctest::Approx(55.5).epsilon(1e-12));
  CHECK(b[PointName::pv].value == doctest::Approx(20.0).epsilon(1e-12));
  CHECK(b[PointName::op].quality == Quality::good);
  // A second later (ten sample periods) the values are stale, not silently current.
  b = dec.values(1, now + std::chrono::seconds(1));
  CHECK(b[PointName::op].quality == Quality::stale);
  CHECK(b[PointName::op].value == doctest::Approx(55.5));
  // A loop whose frame never came: comm_error with the frame id named.
  CanDecoder empty(site.loops);
  const LoopValues c = empty.values(0, now);
  CHECK(c[PointName::op].quality == Quality::comm_error);
  CHECK(c.error.find("0x123") != std::string::npos);
}

TEST_CASE("SocketCAN: a clear message when the kernel has no CAN (or no such interface)") {
  try {
    open_socketcan("vdtest0");
    FAIL("opened a CAN interface that should not exist");
  } catch (const std::runtime_error& e) {
    const std::string m = e.what();
    CHECK((m.find("SocketCAN is not available") != std::string::npos ||
           m.find("not found") != std::string::npos));
  }
}

TEST_CASE("mock transport: simulated PLC frames over a socketpair decode to its values") {
  SiteConfig site = load_site_config(kCanSite);
  site.loops[0].simulate = "paper-ex1";
  site.loops[1].simulate = "kano";
  int sv[2];
  REQUIRE(::socketpair(AF_UNIX, SOCK_SEQPACKET, 0, sv) == 0);
  SimPlc plc(site, SimPlcOptions{1e-6, 0});  // one step, then the values hold
  plc.attach_can(sv[0]);
  plc.start();
  {
    CanBus bus(site.buses[0], site.loops, std::make_unique<FdCanTransport>(sv[1], false));
    REQUIRE(test::wait_for([&] { return bus.frames() >= 2; }, 5.0));
    const auto truth = plc.latest();
    for (std::size_t l = 0; l < 2; ++l) {
      const LoopValues v = bus.read(l);
      INFO(site.loops[l].name);
      CHECK(std::fabs(v[PointName::op].value - truth[l].op) <= 0.005 + 1e-9);
      CHECK(std::fabs(v[PointName::pv].value - truth[l].pv) <= 0.05 + 1e-9);
    }
    CHECK(std::fabs(bus.read(0)[PointName::sp].value - truth[0].sp) <= 0.005 + 1e-9);
    // No new frames: the values turn stale (waited for, bounded, not timed).
    CHECK(
        test::wait_for([&] { return bus.read(0)[PointName::op].quality == Quality::stale; }, 5.0));
  }
  plc.stop();
  // Nothing came back from the recorder's side of the pair.
  char buf[64];
  CHECK(::recv(sv[0], buf, sizeof buf, MSG_DONTWAIT) == -1);
  CHECK((errno == EAGAIN || errno == EWOULDBLOCK));
  ::close(sv[0]);
  ::close(sv[1]);
}
