// Helpers for the driver and recorder tests: a loopback port nobody listens on, site configs
// pointed at a port, and bounded waiting and reading.
#pragma once

#include <arpa/inet.h>
#include <doctest/doctest.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <functional>
#include <string>
#include <thread>

#include "valvediag/drivers/bus.hpp"
#include "valvediag/drivers/site_config.hpp"

namespace valvediag::test {

// A port on 127.0.0.1 that was free a moment ago (bound to port 0, then released).
inline int unused_port() {
  const int s = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  a.sin_port = 0;
  ::bind(s, reinterpret_cast<sockaddr*>(&a), sizeof a);
  socklen_t len = sizeof a;
  ::getsockname(s, reinterpret_cast<sockaddr*>(&a), &len);
  ::close(s);
  return ntohs(a.sin_port);
}

// The site file with its modbus-tcp controller moved to 127.0.0.1:port.
inline SiteConfig site_on_port(const std::string& path, int port) {
  SiteConfig s = load_site_config(path);
  for (auto& b : s.buses)
    if (b.kind == BusKind::modbus_tcp) {
      b.host = "127.0.0.1";
      b.port = port;
    }
  return s;
}

// Polls `done` every 10 ms for at most `limit_s`; true when it became true.
inline bool wait_for(const std::function<bool()>& done, double limit_s) {
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(limit_s);
  while (std::chrono::steady_clock::now() < end) {
    if (done()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return done();
}

// One read, its duration checked against a bound far above what it may take (no hang). Call it
// from a doctest test case.
inline LoopValues timed_read(Bus& bus, std::size_t loop) {
  const auto t0 = std::chrono::steady_clock::now();
  LoopValues v = bus.read(loop);
  CHECK(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() < 3.0);
  return v;
}

// The device behind `bus` away for 0.6 s: every read of `loop` fails at once with `where` in its
// error, no reconnection storm (backoff 50, 100, 200, 200 ... ms with reconnect_max 0.2 s), and
// the last error says `why`.
inline void check_reads_while_away(Bus& bus, std::size_t loop, const std::string& where,
                                   const std::string& why) {
  int failed = 0;
  const auto until = std::chrono::steady_clock::now() + std::chrono::milliseconds(600);
  while (std::chrono::steady_clock::now() < until) {
    const LoopValues v = timed_read(bus, loop);
    CHECK(v[PointName::op].quality == Quality::comm_error);
    CHECK(v[PointName::pv].quality == Quality::comm_error);
    CHECK(v.error.find(where) != std::string::npos);
    ++failed;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  CHECK(failed >= 3);
  const BusStats st = bus.stats();
  CHECK(st.disconnects >= 1);
  CHECK(!st.connected);
  CHECK(st.last_error.find(why) != std::string::npos);
  CHECK(st.connect_attempts <= 12);
}

}  // namespace valvediag::test
