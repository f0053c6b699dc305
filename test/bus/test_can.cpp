// CAN: the decoding path through candump log replay and through a frame-level mock transport (a
// socketpair carrying struct can_frame, fed by the simulated PLC); the SocketCAN driver's
// message on a kernel without CAN; nothing is ever sent.
#include <doctest/doctest.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <filesystem>
#include <fstream>

#include "bus_test_util.hpp"
#include "valvediag/drivers/can_bus.hpp"
#include "valvediag/drivers/sim_plc.hpp"

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

TEST_CASE("CAN stale_after: frames that keep coming with a frozen value turn stale") {
  SiteConfig site = load_site_config(kCanSite);
  site.loops[0].points[static_cast<std::size_t>(PointName::pv)].stale_after_s = 0.5;
  CanDecoder dec(site.loops);
  auto frame = [](std::uint8_t pv_low) {
    CanFrame c;
    c.id = 0x123;
    c.dlc = 8;
    const std::uint8_t data[8] = {0xD7, 0x11, pv_low, 0x30, 0x27, 0x10, 0, 0};
    std::copy(data, data + 8, c.data);
    return c;
  };
  const auto t0 = Clock::now();
  auto at = [&](double s) {
    return t0 + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(s));
  };
  // A frame every 100 ms (the sample period): fresh, but PV frozen from t = 0.
  for (int i = 0; i <= 5; ++i) dec.apply(frame(0x39), at(0.1 * i));
  CHECK(dec.values(0, at(0.5))[PointName::pv].quality == Quality::good);
  dec.apply(frame(0x39), at(0.6));
  LoopValues v = dec.values(0, at(0.6));
  CHECK(v[PointName::pv].quality == Quality::stale);
  CHECK(v[PointName::op].quality == Quality::good);  // no stale_after on op
  CHECK(v.error.find("FIC101.pv: unchanged for 0.6 s (stale_after 0.5 s)") != std::string::npos);
  dec.apply(frame(0x3A), at(0.7));  // it moves again
  CHECK(dec.values(0, at(0.7))[PointName::pv].quality == Quality::good);
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

namespace {
std::string temp_socket(const std::string& what) {
  return (std::filesystem::temp_directory_path() /
          ("valvediag-" + what + "-" + std::to_string(::getpid()) + ".sock"))
      .string();
}

// A raw client of the simulated PLC's socket (not the read-only transport): it can send.
int raw_client(const std::string& path) {
  const int s = ::socket(AF_UNIX, SOCK_SEQPACKET, 0);
  sockaddr_un a{};
  a.sun_family = AF_UNIX;
  std::memcpy(a.sun_path, path.c_str(), path.size());
  REQUIRE(::connect(s, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0);
  return s;
}
}  // namespace

TEST_CASE("CAN over the simulated PLC's Unix socket: a clear error when it is missing") {
  const std::string path = temp_socket("missing");
  std::filesystem::remove(path);
  try {
    UnixCanTransport t(path);
    FAIL("connected to a socket that does not exist");
  } catch (const std::runtime_error& e) {
    const std::string m = e.what();
    CHECK(m.find("CAN socket '" + path + "' does not exist") != std::string::npos);
    CHECK(m.find("valvediag sim-plc --config SITE --can-socket " + path) != std::string::npos);
  }
  { std::ofstream(path) << "not a socket"; }
  CHECK_THROWS_WITH_AS(UnixCanTransport{path}, doctest::Contains("exists but is not a socket"),
                       std::runtime_error);
  SiteConfig site = load_site_config(kCanSite);
  site.loops[0].simulate = "paper-ex1";
  site.loops[1].simulate = "kano";
  SimPlcOptions o{1.0, 0};
  o.can_socket = path;
  SimPlc plc(site, o);
  CHECK_THROWS_WITH_AS(plc.start(), doctest::Contains("exists and is not a socket"),
                       std::runtime_error);
  std::filesystem::remove(path);
}

TEST_CASE(
    "CAN over the simulated PLC's Unix socket: every client gets the frames, none sends, "
    "reconnect after a restart") {
  SiteConfig site = load_site_config(kCanSite);
  site.loops[0].simulate = "paper-ex1";
  site.loops[1].simulate = "kano";
  const std::string path = temp_socket("can0");
  SimPlcOptions hold{1e-6, 0};  // one step, then the values hold: exact comparison
  hold.can_socket = path;
  auto plc = std::make_unique<SimPlc>(site, hold);
  plc->start();
  REQUIRE(plc->can_sockets() == std::vector<std::string>{path});
  // A second PLC on the same path is refused, not allowed to steal it.
  SimPlc other(site, hold);
  CHECK_THROWS_WITH_AS(other.start(), doctest::Contains("another simulated PLC serves"),
                       std::runtime_error);

  CanBus a(site.buses[0], site.loops, std::make_unique<UnixCanTransport>(path));
  CanBus b(site.buses[0], site.loops, std::make_unique<UnixCanTransport>(path));
  // Three connections: the refused PLC's probe (it found the path alive), a and b.
  REQUIRE(test::wait_for([&] { return plc->can_clients() == 3; }, 5.0));
  // The held PLC published its one step before the clients came: this part is about the
  // connections; the stream comes from the second PLC below.
  plc.reset();
  CHECK(!std::filesystem::exists(path));  // removed on stop
  CHECK(test::wait_for([&] { return a.stats().disconnects == 1 && !a.stats().connected; }, 5.0));
  CHECK(a.stats().last_error.find("CAN socket '" + path + "'") != std::string::npos);

  SimPlcOptions run{10.0, 0};
  run.can_socket = path;
  plc = std::make_unique<SimPlc>(site, run);
  plc->start();
  // Both recorders come back by themselves (backoff capped at 1 s) and receive the stream.
  REQUIRE(
      test::wait_for([&] { return a.stats().reconnects == 1 && b.stats().reconnects == 1; }, 10.0));
  const std::uint64_t fa = a.frames(), fb = b.frames();
  REQUIRE(test::wait_for([&] { return a.frames() >= fa + 10 && b.frames() >= fb + 10; }, 10.0));
  for (CanBus* bus : {&a, &b}) {
    const LoopValues v = bus->read(0);
    INFO(v.error);
    CHECK(v[PointName::op].quality == Quality::good);
    CHECK(v[PointName::op].value >= 0.0);
    CHECK(v[PointName::op].value <= 100.0);
    CHECK(std::fabs(v[PointName::pv].value - 50.0) < 25.0);  // paper-ex1 runs around PV 50
    CHECK(bus->stats().connected);
  }
  // Read only: the transports shut their sending side; a client that does send is counted.
  CHECK(plc->can_bytes_from_clients() == 0);
  const int raw = raw_client(path);
  const char junk[16] = {};
  CHECK(::send(raw, junk, sizeof junk, 0) == 16);
  CHECK(test::wait_for([&] { return plc->can_bytes_from_clients() == 16; }, 5.0));
  ::close(raw);
  plc->stop();
}

TEST_CASE("CAN over the Unix socket: values equal the simulated PLC's") {
  SiteConfig site = load_site_config(kCanSite);
  site.loops[0].simulate = "paper-ex1";
  site.loops[1].simulate = "kano";
  const std::string path = temp_socket("exact");
  SimPlcOptions o{0.2, 0};  // paper-ex1 steps every 2.5 s, kano every 5 s
  o.can_socket = path;
  SimPlc plc(site, o);
  plc.start();
  CanBus bus(site.buses[0], site.loops, std::make_unique<UnixCanTransport>(path));
  // A frame arrives a moment after its step: compare until they agree (bounded). Wrong decoding
  // never agrees.
  LoopValues v;
  LoopSample truth{};
  CHECK(test::wait_for(
      [&] {
        truth = plc.latest()[0];
        v = bus.read(0);
        return v.error.empty() && std::fabs(v[PointName::op].value - truth.op) <= 0.005 + 1e-9 &&
               std::fabs(v[PointName::pv].value - truth.pv) <= 0.005 + 1e-9 &&
               std::fabs(v[PointName::sp].value - truth.sp) <= 0.005 + 1e-9;
      },
      15.0));
  INFO(v.error, " op ", v[PointName::op].value, " vs ", truth.op);
  CHECK(v[PointName::op].quality == Quality::good);
  CHECK(bus.frames() >= 1);
  CHECK(plc.can_bytes_from_clients() == 0);
}
