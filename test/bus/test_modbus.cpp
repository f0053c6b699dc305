// The Modbus driver against the simulated PLC over a real libmodbus TCP server on 127.0.0.1:
// every decoder over the wire, one request per loop, no write function code ever, and each
// injected fault counted and flagged without a hang.
#include <doctest/doctest.h>

#include <chrono>
#include <cmath>

#include "bus_test_util.hpp"
#include "valvediag/drivers/modbus_bus.hpp"
#include "valvediag/drivers/sim_plc.hpp"

using namespace valvediag;
using Clock = std::chrono::steady_clock;

namespace {
const std::string kSimSite = std::string(VALVEDIAG_CONFIG_DIR) + "/sim-site.toml";

// A PLC that holds its first sample (speed so low that no second step comes during a test).
struct Fixture {
  SiteConfig site = load_site_config(kSimSite);
  SimPlc plc{site, SimPlcOptions{1e-6, 0}};
  Fixture() {
    plc.start();
    for (auto& b : site.buses) b.port = plc.port();
    REQUIRE(test::wait_for([&] { return plc.steps()[0] >= 1; }, 5.0));
  }
  ModbusBus bus() { return ModbusBus(site.buses[0], site.loops); }
};

double tolerance(const PointConfig& p, double v) {
  return p.type == DataType::float32 ? 1e-6 * std::max(1.0, std::fabs(v)) : p.scale * 0.5 + 1e-12;
}
}  // namespace

TEST_CASE("requests: contiguous registers of a loop in one request") {
  const SiteConfig s = load_site_config(kSimSite);
  auto b = plan_requests(s.loops[0]);
  REQUIRE(b.size() == 1);
  CHECK(b[0].address == 0);
  CHECK(b[0].count == 8);
  b = plan_requests(s.loops[2]);
  REQUIRE(b.size() == 1);
  CHECK(b[0].reg == RegisterType::input);
  CHECK(b[0].address == 20);
  CHECK(b[0].count == 5);
  LoopConfigEntry far = s.loops[0];
  far.points[2].address = 200;  // sp far away: a second request
  CHECK(plan_requests(far).size() == 2);
}

TEST_CASE("values read over Modbus TCP equal the simulated ones, in every type and byte order") {
  Fixture fx;
  ModbusBus bus = fx.bus();
  const auto truth = fx.plc.latest();
  for (std::size_t l = 0; l < fx.site.loops.size(); ++l) {
    const LoopValues v = bus.read(l);
    INFO(fx.site.loops[l].name, " ", v.error);
    CHECK(v.error == "");
    const double expected[] = {truth[l].op, truth[l].pv, truth[l].sp, truth[l].mv};
    for (std::size_t i = 0; i < 4; ++i) {
      const PointConfig& p = fx.site.loops[l].points[i];
      if (!p.present) continue;
      CHECK(v.points[i].quality == Quality::good);
      CHECK(std::fabs(v.points[i].value - expected[i]) <= tolerance(p, expected[i]));
    }
  }
  const auto counts = fx.plc.function_counts();
  CHECK(counts[3] == 2);  // FIC101 and LIC201: holding registers, one request each
  CHECK(counts[4] == 1);  // PIC301: input registers
  CHECK(fx.plc.write_requests() == 0);
  const BusStats st = bus.stats();
  CHECK(st.requests == 3);
  CHECK(st.errors == 0);
  CHECK(st.connected);
}

TEST_CASE("64-bit values over Modbus TCP, as a Telegraf configuration gives them") {
  SiteConfig site = parse_site_config(
      "[[bus]]\nname = \"t\"\nprotocol = \"modbus-tcp\"\ncontroller = \"tcp://127.0.0.1:5020\"\n"
      "[[loop]]\nname = \"FIC64\"\nbus = \"t\"\nsimulate = \"paper-ex1\"\n"
      "sample_period = \"1s\"\n"
      "op = { address = 0, data_type = \"FLOAT64-IEEE\", byte_order = \"GHEFCDAB\" }\n"
      "pv = { address = 4, data_type = \"INT64\", byte_order = \"HGFEDCBA\", scale = 1e-9 }\n"
      "sp = { address = 8, data_type = \"UINT64\", byte_order = \"BADC\", scale = 1e-6 }\n",
      "t64.toml");
  SimPlc plc{site, SimPlcOptions{1e-6, 0}};
  plc.start();
  site.buses[0].port = plc.port();
  REQUIRE(test::wait_for([&] { return plc.steps()[0] >= 1; }, 5.0));
  ModbusBus bus(site.buses[0], site.loops);
  const auto truth = plc.latest();
  const LoopValues v = bus.read(0);
  INFO(v.error);
  CHECK(v.error == "");
  CHECK(plan_requests(site.loops[0]).front().count == 12);  // three values, four registers each
  // A double is exact; 1e-9 and 1e-6 per count resolve far below the values' noise.
  CHECK(v[PointName::op].value == truth[0].op);
  CHECK(std::fabs(v[PointName::pv].value - truth[0].pv) <= 0.5e-9 + 1e-12);
  CHECK(std::fabs(v[PointName::sp].value - truth[0].sp) <= 0.5e-6 + 1e-12);
  for (auto p : {PointName::op, PointName::pv, PointName::sp}) CHECK(v[p].quality == Quality::good);
  CHECK(plc.write_requests() == 0);
}

TEST_CASE("faults: exception, timeout, garbled reply, dropped connection, slow reply") {
  Fixture fx;
  for (auto& b : fx.site.buses) {
    b.timeout_s = 0.15;
    b.retries = 0;
  }
  ModbusBus bus = fx.bus();
  REQUIRE(bus.read(0).error == "");

  FaultConfig f;
  f.kind = FaultKind::exception;
  f.address = 12;  // LIC201's PV: only that loop's request is refused
  f.exception_code = 2;
  fx.plc.add_fault(f);
  LoopValues v = bus.read(1);
  CHECK(v[PointName::op].quality == Quality::comm_error);
  CHECK(std::isnan(v[PointName::op].value));
  CHECK(v.error.find("holding registers 10..15") != std::string::npos);
  CHECK(bus.read(0)[PointName::pv].quality == Quality::good);
  CHECK(bus.stats().exceptions == 1);
  fx.plc.clear_faults();

  auto once = [&](FaultKind k, double delay = 0.0) {
    FaultConfig g;
    g.kind = k;
    g.every = 1000000;  // the first matching request only
    g.delay_s = delay;
    fx.plc.add_fault(g);
  };
  once(FaultKind::timeout);
  const auto t0 = Clock::now();
  v = bus.read(0);
  const double waited = std::chrono::duration<double>(Clock::now() - t0).count();
  CHECK(v[PointName::op].quality == Quality::comm_error);
  CHECK(waited < 2.0);  // bounded by the 0.15 s timeout, far from a hang
  CHECK(bus.stats().timeouts == 1);
  CHECK(bus.read(0).error == "");  // a clean connection afterwards
  fx.plc.clear_faults();

  once(FaultKind::garble);
  v = bus.read(0);
  CHECK(v[PointName::pv].quality == Quality::comm_error);
  CHECK(bus.stats().garbled == 1);
  CHECK(bus.read(0).error == "");
  fx.plc.clear_faults();

  once(FaultKind::drop);
  v = bus.read(0);
  CHECK(v[PointName::pv].quality == Quality::comm_error);
  CHECK(bus.stats().disconnects == 1);
  CHECK(bus.read(0).error == "");
  CHECK(bus.stats().reconnects >= 1);
  fx.plc.clear_faults();

  once(FaultKind::delay, 0.05);  // slow but within the timeout: good
  v = bus.read(0);
  CHECK(v.error == "");
  CHECK(v[PointName::op].quality == Quality::good);
  fx.plc.clear_faults();

  CHECK(fx.plc.write_requests() == 0);
}

TEST_CASE("a retry recovers from a single dropped reply") {
  Fixture fx;
  fx.site.buses[0].timeout_s = 0.15;
  fx.site.buses[0].retries = 1;
  ModbusBus bus = fx.bus();
  FaultConfig g;
  g.kind = FaultKind::timeout;
  g.every = 1000000;
  fx.plc.add_fault(g);
  const LoopValues v = bus.read(0);
  CHECK(v.error == "");
  CHECK(v[PointName::op].quality == Quality::good);
  CHECK(bus.stats().timeouts == 1);
  CHECK(bus.stats().requests == 2);
}

TEST_CASE("server away: fails fast, backs off, reconnects when it returns") {
  Fixture fx;
  ModbusBus bus = fx.bus();
  REQUIRE(bus.read(0).error == "");
  fx.plc.restart(0.6);
  // Bounded: at most 400 reads 10 ms apart.
  int failures = 0;
  bool back = false;
  for (int i = 0; i < 400 && !back; ++i) {
    const auto t0 = Clock::now();
    const LoopValues v = bus.read(0);
    CHECK(std::chrono::duration<double>(Clock::now() - t0).count() < 1.0);
    if (v.error.empty())
      back = failures > 0;
    else
      ++failures;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  CHECK(failures > 0);
  CHECK(back);
  CHECK(bus.stats().reconnects >= 1);
  CHECK(fx.plc.write_requests() == 0);
}

TEST_CASE("nobody listening: a clear message, no hang, no connection storm") {
  SiteConfig s = test::site_on_port(kSimSite, test::unused_port());
  ModbusBus bus(s.buses[0], s.loops);
  const LoopValues v = bus.read(0);
  CHECK(v[PointName::op].quality == Quality::comm_error);
  CHECK(v.error.find("cannot connect to 127.0.0.1:") != std::string::npos);
  // Within the backoff no new attempt is made: the second read answers at once.
  const LoopValues w = bus.read(0);
  CHECK(w.error.find("not connected") != std::string::npos);
  CHECK(bus.stats().connect_attempts == 1);
  CHECK(bus.stats().requests == 0);
}

TEST_CASE(
    "stale_after: frozen registers are flagged stale, other values stay good, off by default") {
  // paper-ex1 at 10x: a new step every 50 ms; its PV carries measurement noise, so it changes at
  // every step unless the PLC stops updating it.
  SiteConfig site = load_site_config(kSimSite);
  SimPlc plc(site, SimPlcOptions{10.0, 0});
  plc.start();
  for (auto& b : site.buses) b.port = plc.port();
  LoopConfigEntry watched = site.loops[0];  // FIC101
  watched.points[static_cast<std::size_t>(PointName::pv)].stale_after_s = 0.3;
  watched.points[static_cast<std::size_t>(PointName::op)].stale_after_s = 0.3;
  ModbusBus bus(site.buses[0], {watched, site.loops[0]});  // with and without stale_after
  REQUIRE(test::wait_for([&] { return bus.read(0).error.empty(); }, 5.0));

  FaultConfig freeze;
  freeze.kind = FaultKind::freeze;
  freeze.address = 2;  // FIC101's PV: the PLC stops updating it
  plc.add_fault(freeze);
  LoopValues v;
  CHECK(test::wait_for([&] { return (v = bus.read(0))[PointName::pv].quality == Quality::stale; },
                       10.0));
  INFO(v.error);
  CHECK(std::isfinite(v[PointName::pv].value));  // the value is kept, flagged
  CHECK(v[PointName::op].quality == Quality::good);
  CHECK(v.error.find("FIC101.pv: holding register(s) 2..3 unchanged for") != std::string::npos);
  CHECK(v.error.find("stale_after 0.3 s") != std::string::npos);
  const LoopValues plain = bus.read(1);
  CHECK(plain[PointName::pv].quality == Quality::good);  // no stale_after: not flagged
  CHECK(plain[PointName::pv].value == v[PointName::pv].value);
  // The frozen value stays put for as long as the fault lasts.
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  CHECK(bus.read(0)[PointName::pv].value == v[PointName::pv].value);

  plc.clear_faults();
  CHECK(test::wait_for([&] { return bus.read(0)[PointName::pv].quality == Quality::good; }, 10.0));
  CHECK(bus.stats().errors == 0);  // stale is an answer, not a failed request
  CHECK(plc.write_requests() == 0);
}

TEST_CASE("the simulated PLC refuses a loop on a Modbus bus it does not serve, naming it") {
  const std::string loop =
      "op = { register = \"holding\", address = 0, type = \"FLOAT32\" }\n"
      "pv = { register = \"holding\", address = 2, type = \"FLOAT32\" }\nsimulate = \"kano\"\n"
      "sample_period = \"1s\"\n";
  const std::string two_tcp =
      "[[bus]]\nname = \"a\"\nprotocol = \"modbus-tcp\"\ncontroller = \"tcp://127.0.0.1:1502\"\n"
      "[[bus]]\nname = \"b\"\nprotocol = \"modbus-tcp\"\ncontroller = \"tcp://127.0.0.1:1503\"\n"
      "[[loop]]\nname = \"A1\"\nbus = \"a\"\n" +
      loop + "[[loop]]\nname = \"B1\"\nbus = \"b\"\n" + loop;
  CHECK_THROWS_WITH_AS(
      SimPlc(parse_site_config(two_tcp, "two.toml"), SimPlcOptions{1.0, 0}),
      "two.toml:16: loop 'B1' is on bus 'b' (modbus-tcp, line 5); the simulated PLC serves one "
      "Modbus TCP bus, 'a' (line 1): move the loop to that bus, or serve bus 'b' with a second "
      "sim-plc from a site file of its own",
      std::invalid_argument);
  const std::string rtu =
      "[[bus]]\nname = \"r\"\nprotocol = \"modbus-rtu\"\ncontroller = \"file:///dev/ttyS9\"\n"
      "[[loop]]\nname = \"R1\"\nbus = \"r\"\n" +
      loop;
  CHECK_THROWS_WITH_AS(SimPlc(parse_site_config(rtu, "rtu.toml"), SimPlcOptions{1.0, 0}),
                       doctest::Contains("the simulated PLC serves Modbus TCP only"),
                       std::invalid_argument);
  // RTU over TCP, with no Modbus TCP bus in the file at all.
  const std::string gw =
      "[[bus]]\nname = \"g\"\ntransmission_mode = \"RTUoverTCP\"\n"
      "controller = \"tcp://127.0.0.1:4001\"\n[[loop]]\nname = \"G1\"\nbus = \"g\"\n" +
      loop;
  CHECK_THROWS_WITH_AS(SimPlc(parse_site_config(gw, "gw.toml"), SimPlcOptions{1.0, 0}),
                       doctest::Contains("(modbus-rtu-over-tcp, line 1); the simulated PLC serves "
                                         "Modbus TCP only"),
                       std::invalid_argument);
}
