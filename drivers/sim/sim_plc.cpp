// The simulated PLC: one simulation thread steps the loops on a monotonic clock, writes their
// values into the register map and their CAN frames to the frame sockets (accepting CAN clients
// between steps); one server thread answers Modbus TCP requests from that map (under one mutex,
// so the values of one request always come from the same step).
#include "valvediag/drivers/sim_plc.hpp"

#include <arpa/inet.h>
#include <linux/can.h>
#include <modbus/modbus.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <map>
#include <mutex>
#include <stdexcept>
#include <thread>

#include "valvediag/sim/scenarios.hpp"

namespace valvediag {

namespace {
using Clock = std::chrono::steady_clock;

Clock::duration seconds(double s) {
  return std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(s));
}

bool is_write(int fc) {
  return fc == 5 || fc == 6 || fc == 15 || fc == 16 || fc == 22 || fc == 23;
}

struct ServedLoop {
  const LoopConfigEntry* cfg;
  const BusConfig* bus;
  bool can;
  std::unique_ptr<LoopSimulator> sim;
  double period_real_s;  // Ts / speed
  std::uint64_t steps = 0;
  LoopSample last{};
  std::array<double, kPointCount> held{};  // the values last served, kept by a freeze fault
};

// A Unix SOCK_SEQPACKET socket serving the frames of one CAN bus to every connected client.
struct CanEndpoint {
  const BusConfig* bus;
  std::string path;
  int listen_fd = -1;
  std::vector<int> clients;
};

// Listens on `path`, replacing a socket file left by a stopped server (never a live one, nor
// a file that is not a socket).
int listen_frame_socket(const std::string& path) {
  sockaddr_un a{};
  if (path.empty() || path.size() >= sizeof a.sun_path)
    throw std::runtime_error("CAN socket path '" + path + "' is empty or longer than " +
                             std::to_string(sizeof a.sun_path - 1) + " bytes; choose another");
  a.sun_family = AF_UNIX;
  std::memcpy(a.sun_path, path.c_str(), path.size());
  struct stat st {};
  if (::lstat(path.c_str(), &st) == 0) {
    if (!S_ISSOCK(st.st_mode))
      throw std::runtime_error("cannot serve CAN frames on '" + path +
                               "': it exists and is not a socket; remove it or choose another "
                               "path");
    const int probe = ::socket(AF_UNIX, SOCK_SEQPACKET | SOCK_CLOEXEC, 0);
    const bool live =
        probe >= 0 && ::connect(probe, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0;
    if (probe >= 0) ::close(probe);
    if (live)
      throw std::runtime_error("another simulated PLC serves CAN frames on '" + path +
                               "'; stop it or choose another path");
    ::unlink(path.c_str());  // left behind by a server that did not stop cleanly
  }
  const int s = ::socket(AF_UNIX, SOCK_SEQPACKET | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
  if (s < 0)
    throw std::runtime_error(std::string("cannot create a Unix socket: ") + std::strerror(errno));
  if (::bind(s, reinterpret_cast<sockaddr*>(&a), sizeof a) < 0 || ::listen(s, 16) < 0) {
    const int err = errno;
    ::close(s);
    throw std::runtime_error("cannot serve CAN frames on '" + path + "': " + std::strerror(err) +
                             "; check that its directory exists and is writable");
  }
  return s;
}

struct ActiveFault {
  FaultConfig f;
  Clock::time_point origin;
  std::uint64_t matches = 0;
};
}  // namespace

struct SimPlc::Impl {
  SiteConfig site;
  SimPlcOptions opt;
  const BusConfig* bus = nullptr;
  std::vector<ServedLoop> loops;
  int port = -1;

  mutable std::mutex map_mutex;  // registers, latest samples, CAN fd and endpoints
  modbus_mapping_t* map = nullptr;
  int can_fd = -1;
  std::vector<CanEndpoint> can_eps;
  std::atomic<std::uint64_t> can_accepted{0}, can_from_clients{0};

  std::mutex fault_mutex;
  std::vector<ActiveFault> faults;
  Clock::time_point started{};

  std::atomic<bool> running{false};
  std::atomic<double> restart_request{-1.0};  // down time requested by restart(), < 0: none
  std::array<std::atomic<std::uint64_t>, 256> counts{};
  std::atomic<std::uint64_t> accepted{0};
  std::thread sim_thread, server_thread;

  modbus_t* ctx = nullptr;
  int listen_fd = -1;
  std::vector<int> clients;

  ~Impl() {
    if (map) modbus_mapping_free(map);
  }

  void write_point(const PointConfig& p, double v) {
    if (!p.present) return;
    std::uint16_t* tab =
        p.reg == RegisterType::holding ? map->tab_registers : map->tab_input_registers;
    std::uint16_t regs[kMaxRegisters] = {};
    encode_registers(v, p.type, p.order, p.scale, p.offset, regs);
    for (std::size_t i = 0; i < register_count(p.type); ++i) tab[p.address + i] = regs[i];
  }

  // Points of loop `l` held by an active freeze fault: those whose registers cover the fault's
  // address (of its register type); every point, CAN signals too, when it names neither.
  std::array<bool, kPointCount> frozen(const ServedLoop& l) {
    std::array<bool, kPointCount> out{};
    std::lock_guard lock(fault_mutex);
    const auto now = Clock::now();
    for (const auto& a : faults) {
      if (a.f.kind != FaultKind::freeze) continue;
      const double t = std::chrono::duration<double>(now - a.origin).count();
      if (t < a.f.start_s || t >= a.f.start_s + a.f.duration_s) continue;
      for (std::size_t i = 0; i < kPointCount; ++i) {
        const PointConfig& p = l.cfg->points[i];
        if (!p.present) continue;
        if (l.can) {
          out[i] = out[i] || (!a.f.address && !a.f.reg);
          continue;
        }
        const int end = p.address + static_cast<int>(register_count(p.type));
        const bool reg_ok = !a.f.reg || *a.f.reg == p.reg;
        const bool addr_ok = !a.f.address || (*a.f.address >= p.address && *a.f.address < end);
        out[i] = out[i] || (reg_ok && addr_ok);
      }
    }
    return out;
  }

  void publish(ServedLoop& l, const LoopSample& s) {
    const std::array<bool, kPointCount> hold = frozen(l);
    double values[kPointCount] = {s.op, s.pv, s.sp, s.mv, 1.0 /* mode: auto */};
    for (std::size_t i = 0; i < kPointCount; ++i) {
      if (hold[i] && l.steps > 0) values[i] = l.held[i];
      l.held[i] = values[i];
    }
    std::lock_guard lock(map_mutex);
    l.last = s;
    ++l.steps;
    if (!l.can) {
      for (std::size_t i = 0; i < kPointCount; ++i) write_point(l.cfg->points[i], values[i]);
      return;
    }
    // One frame per frame id, carrying every signal of this loop that lives in it.
    std::map<std::uint32_t, can_frame> frames;
    for (std::size_t i = 0; i < kPointCount; ++i) {
      const PointConfig& p = l.cfg->points[i];
      if (!p.present) continue;
      auto [it, fresh] = frames.try_emplace(p.can.frame_id);
      can_frame& f = it->second;
      if (fresh) {
        std::memset(&f, 0, sizeof f);
        f.can_id = p.can.frame_id | (p.can.extended ? CAN_EFF_FLAG : 0u);
        f.can_dlc = 8;
      }
      encode_can_signal(p.can, values[i], std::span<std::uint8_t>(f.data, 8));
    }
    if (can_fd >= 0)
      for (const auto& [id, f] : frames)
        if (::send(can_fd, &f, sizeof f, MSG_NOSIGNAL | MSG_DONTWAIT) < 0) break;  // reader gone
    for (auto& ep : can_eps) {
      if (ep.bus != l.bus) continue;
      std::vector<int> keep;
      for (int c : ep.clients) {
        bool alive = true;
        for (const auto& [id, f] : frames)
          if (::send(c, &f, sizeof f, MSG_NOSIGNAL | MSG_DONTWAIT) < 0) {
            // A full buffer (a slow client) loses this step's frames, as a real bus would.
            alive = errno == EAGAIN || errno == EWOULDBLOCK || errno == ENOBUFS;
            break;
          }
        if (alive)
          keep.push_back(c);
        else
          ::close(c);
      }
      ep.clients = std::move(keep);
    }
  }

  // New CAN clients, and a check that none of them sends anything (they only read).
  void serve_can_clients() {
    std::lock_guard lock(map_mutex);
    for (auto& ep : can_eps) {
      if (ep.listen_fd < 0) continue;
      for (int c; (c = ::accept4(ep.listen_fd, nullptr, nullptr, SOCK_CLOEXEC)) >= 0;) {
        ep.clients.push_back(c);
        ++can_accepted;
      }
      for (int c : ep.clients) {
        char buf[64];
        const ssize_t n = ::recv(c, buf, sizeof buf, MSG_DONTWAIT);
        if (n > 0) can_from_clients += static_cast<std::uint64_t>(n);
      }
    }
  }

  void open_can_sockets() {
    std::lock_guard lock(map_mutex);
    for (auto& ep : can_eps)
      if (!ep.path.empty() && ep.listen_fd < 0) ep.listen_fd = listen_frame_socket(ep.path);
  }

  void close_can_sockets() {
    std::lock_guard lock(map_mutex);
    for (auto& ep : can_eps) {
      for (int c : ep.clients) ::close(c);
      ep.clients.clear();
      if (ep.listen_fd >= 0) {
        ::close(ep.listen_fd);
        ::unlink(ep.path.c_str());
      }
      ep.listen_fd = -1;
    }
  }

  void simulate() {
    const auto t0 = started;
    while (running) {
      Clock::time_point next = Clock::time_point::max();
      serve_can_clients();
      for (auto& l : loops) {
        const auto due = t0 + seconds(static_cast<double>(l.steps) * l.period_real_s);
        if (due <= Clock::now()) {
          publish(l, l.sim->step());
          next = Clock::now();  // look again at once: more may be due
        } else {
          next = std::min(next, due);
        }
      }
      // Short sleeps so stop() is prompt at any speed.
      std::this_thread::sleep_until(std::min(next, Clock::now() + std::chrono::milliseconds(50)));
    }
  }

  void listen() {
    ctx = modbus_new_tcp("127.0.0.1", port);
    if (!ctx) throw std::runtime_error("cannot create the libmodbus server context");
    modbus_set_indication_timeout(ctx, 1, 0);  // a half-sent request never stalls the server
    listen_fd = modbus_tcp_listen(ctx, 16);
    if (listen_fd < 0) {
      const int err = errno;
      modbus_free(ctx);
      ctx = nullptr;
      throw std::runtime_error("cannot listen on 127.0.0.1:" + std::to_string(port) + ": " +
                               std::strerror(err) +
                               "; choose another port (--port 0 picks a free one)");
    }
    sockaddr_in a{};
    socklen_t len = sizeof a;
    if (getsockname(listen_fd, reinterpret_cast<sockaddr*>(&a), &len) == 0)
      port = ntohs(a.sin_port);
  }

  void close_all() {
    for (int c : clients) ::close(c);
    clients.clear();
    if (listen_fd >= 0) ::close(listen_fd);
    listen_fd = -1;
    if (ctx) modbus_free(ctx);
    ctx = nullptr;
  }

  // The first active fault matching this request, counting matches for `every`.
  std::optional<FaultConfig> fault_for(int fc, int address, int count) {
    std::lock_guard lock(fault_mutex);
    const auto now = Clock::now();
    for (auto& a : faults) {
      if (a.f.kind == FaultKind::freeze) continue;  // acts on the simulation, not on requests
      const double t = std::chrono::duration<double>(now - a.origin).count();
      if (t < a.f.start_s || t >= a.f.start_s + a.f.duration_s) continue;
      if (a.f.reg) {
        if ((*a.f.reg == RegisterType::holding && fc != 3) ||
            (*a.f.reg == RegisterType::input && fc != 4))
          continue;
      }
      if (a.f.address && !(*a.f.address >= address && *a.f.address < address + count)) continue;
      if (a.matches++ % static_cast<std::uint64_t>(a.f.every) != 0) continue;
      return a.f;
    }
    return std::nullopt;
  }

  void send_garbled(int fd, const std::uint8_t* q, int count) {
    // A well-framed TCP reply whose byte count disagrees with the request: the client must
    // reject it as bad data rather than decode it.
    std::uint8_t r[260];
    const int n = std::min(count, 120);
    const int bytes = 2 * n + 2;  // two bytes more than asked for
    r[0] = q[0];
    r[1] = q[1];
    r[2] = 0;
    r[3] = 0;
    r[4] = static_cast<std::uint8_t>((3 + bytes) >> 8);
    r[5] = static_cast<std::uint8_t>((3 + bytes) & 0xff);
    r[6] = q[6];
    r[7] = q[7];
    r[8] = static_cast<std::uint8_t>(bytes);
    for (int i = 0; i < bytes; ++i) r[9 + i] = static_cast<std::uint8_t>(0xA5 ^ i);
    (void)::send(fd, r, static_cast<std::size_t>(9 + bytes), MSG_NOSIGNAL);
  }

  // Answers one request; false when the connection is to be closed.
  bool answer(int fd, const std::uint8_t* q, int len) {
    const int hl = modbus_get_header_length(ctx);
    const int fc = q[hl];
    ++counts[static_cast<std::size_t>(fc)];
    if (is_write(fc)) {
      modbus_reply_exception(ctx, q, MODBUS_EXCEPTION_ILLEGAL_FUNCTION);
      return true;
    }
    const int address = len >= hl + 3 ? (q[hl + 1] << 8) | q[hl + 2] : 0;
    const int count = len >= hl + 5 ? (q[hl + 3] << 8) | q[hl + 4] : 0;
    if (const auto f = fault_for(fc, address, count)) {
      switch (f->kind) {
        case FaultKind::delay:
          std::this_thread::sleep_for(seconds(f->delay_s));
          break;
        case FaultKind::timeout:
          return true;  // no reply at all
        case FaultKind::exception:
          modbus_reply_exception(ctx, q, static_cast<unsigned>(f->exception_code));
          return true;
        case FaultKind::drop:
          return false;
        case FaultKind::restart:
          restart_request = f->down_s;
          return false;
        case FaultKind::garble:
          send_garbled(fd, q, count);
          return true;
        case FaultKind::freeze:
          break;  // not returned by fault_for
      }
    }
    std::lock_guard lock(map_mutex);
    modbus_reply(ctx, q, len, map);
    return true;
  }

  void serve() {
    std::uint8_t query[MODBUS_TCP_MAX_ADU_LENGTH];
    while (running) {
      if (const double down = restart_request.exchange(-1.0); down >= 0) {
        close_all();
        const auto back = Clock::now() + seconds(down);
        while (running && Clock::now() < back)
          std::this_thread::sleep_for(std::chrono::milliseconds(10));
        if (!running) break;
        for (int attempt = 0;; ++attempt) {  // the port may linger briefly after close
          try {
            listen();
            break;
          } catch (const std::runtime_error&) {
            if (attempt >= 100 || !running) return;
            std::this_thread::sleep_for(std::chrono::milliseconds(20));
          }
        }
      }
      std::vector<pollfd> fds;
      fds.push_back({listen_fd, POLLIN, 0});
      for (int c : clients) fds.push_back({c, POLLIN, 0});
      if (::poll(fds.data(), fds.size(), 20) <= 0) continue;
      std::vector<int> keep;
      if (fds[0].revents & POLLIN) {
        int s = listen_fd;
        const int c = modbus_tcp_accept(ctx, &s);
        if (c >= 0) {
          keep.push_back(c);
          ++accepted;
        }
      }
      for (std::size_t i = 1; i < fds.size(); ++i) {
        const int c = fds[i].fd;
        bool ok = true;
        if (fds[i].revents & (POLLIN | POLLHUP | POLLERR)) {
          modbus_set_socket(ctx, c);
          const int rc = modbus_receive(ctx, query);
          ok = rc > 0 ? answer(c, query, rc) : rc == 0;  // 0: not for this unit, ignored
        }
        if (ok)
          keep.push_back(c);  // on a restart request, close_all() closes it next round
        else
          ::close(c);
      }
      clients = std::move(keep);
    }
    close_all();
  }
};

SimPlc::SimPlc(SiteConfig site, SimPlcOptions options) : impl_(std::make_unique<Impl>()) {
  Impl& m = *impl_;
  m.site = std::move(site);
  m.opt = options;
  if (!(options.speed > 0) || options.speed > 1e4)
    throw std::invalid_argument("--speed must lie in (0, 10000]");
  for (const auto& b : m.site.buses)
    if (b.kind == BusKind::modbus_tcp) {
      m.bus = &b;
      break;
    }
  int max_holding = 0, max_input = 0;
  const std::string where = m.site.file + ":";
  for (const auto& l : m.site.loops) {
    const BusConfig* b = m.site.find_bus(l.bus);
    const bool can = b->kind == BusKind::socketcan;
    if (b != m.bus && !can) {
      // Refused rather than left out: a recorder on this site would wait for it forever.
      const std::string why = b->kind != BusKind::modbus_tcp || !m.bus
                                  ? "the simulated PLC serves Modbus TCP only"
                                  : "the simulated PLC serves one Modbus TCP bus, '" + m.bus->name +
                                        "' (line " + std::to_string(m.bus->line) + ")";
      throw std::invalid_argument(where + std::to_string(l.line) + ": loop '" + l.name +
                                  "' is on bus '" + b->name + "' (" + to_string(b->kind) +
                                  ", line " + std::to_string(b->line) + "); " + why +
                                  ": move the loop to that bus, or serve bus '" + b->name +
                                  "' with a second sim-plc from a site file of its own");
    }
    if (l.simulate.empty())
      throw std::invalid_argument(m.site.file + ":" + std::to_string(l.line) + ": loop '" + l.name +
                                  "' has no simulate key; give it a scenario, e.g. simulate = "
                                  "\"paper-ex1\"");
    Scenario s;
    try {
      s = l.simulate.find(".toml") != std::string::npos ? load_scenario_file(l.simulate)
                                                        : scenario_by_name(l.simulate);
    } catch (const std::exception& e) {
      throw std::invalid_argument(m.site.file + ":" + std::to_string(l.line) + ": loop '" + l.name +
                                  "': " + e.what());
    }
    ServedLoop sl{&l, b, can, std::make_unique<LoopSimulator>(s.loop, l.seed),
                  s.loop.Ts / options.speed};
    sl.sim->keep_trace(false);  // it steps for as long as the PLC runs
    if (can && std::none_of(m.can_eps.begin(), m.can_eps.end(),
                            [b](const CanEndpoint& e) { return e.bus == b; }))
      m.can_eps.push_back({b, can_unix_path(*b), -1, {}});
    m.loops.push_back(std::move(sl));
    if (!can)
      for (const auto& p : l.points) {
        if (!p.present) continue;
        int& mx = p.reg == RegisterType::holding ? max_holding : max_input;
        mx = std::max(mx, p.address + static_cast<int>(register_count(p.type)));
      }
  }
  if (m.loops.empty())
    throw std::invalid_argument(m.site.file +
                                ": no loop to simulate on a modbus-tcp or socketcan bus");
  if (m.bus && m.bus->host != "127.0.0.1" && m.bus->host != "localhost")
    throw std::invalid_argument(m.site.file + ":" + std::to_string(m.bus->line) +
                                ": the simulated PLC serves on 127.0.0.1 only; set controller = "
                                "\"tcp://127.0.0.1:PORT\"");
  if (!options.can_socket.empty()) {
    if (m.can_eps.size() != 1) {
      std::string names;
      for (const auto& e : m.can_eps) names += (names.empty() ? "" : ", ") + e.bus->name;
      throw std::invalid_argument(
          m.site.file + ": a CAN socket path serves the frames of one socketcan bus; this site " +
          "has " + std::to_string(m.can_eps.size()) + " with loops" +
          (names.empty() ? "" : " (" + names + ")") +
          (m.can_eps.empty() ? "" : ": give each its interface = \"unix:PATH\" instead"));
    }
    m.can_eps[0].path = options.can_socket;
  }
  m.port = options.port >= 0 ? options.port : (m.bus ? m.bus->port : 0);
  m.map = modbus_mapping_new(0, 0, std::max(max_holding, 1), std::max(max_input, 1));
  if (!m.map) throw std::runtime_error("cannot allocate the register map");
  for (const auto& f : m.site.faults) m.faults.push_back({f, Clock::time_point{}, 0});
}

SimPlc::~SimPlc() {
  stop();
}

void SimPlc::start() {
  Impl& m = *impl_;
  if (m.running) return;
  m.open_can_sockets();
  if (m.bus) {
    try {
      m.listen();
    } catch (...) {
      m.close_can_sockets();
      throw;
    }
  }
  m.started = Clock::now();
  {
    std::lock_guard lock(m.fault_mutex);
    for (auto& f : m.faults)
      if (f.origin == Clock::time_point{}) f.origin = m.started;
  }
  // Values exist before the first request: step 0 is published here, before the server thread
  // can answer (from the simulation thread a first request could read the zeroed map).
  for (auto& l : m.loops)
    if (l.steps == 0) m.publish(l, l.sim->step());
  m.running = true;
  m.sim_thread = std::thread([&m] { m.simulate(); });
  if (m.bus) m.server_thread = std::thread([&m] { m.serve(); });
}

void SimPlc::stop() {
  Impl& m = *impl_;
  m.running = false;
  if (m.sim_thread.joinable()) m.sim_thread.join();
  if (m.server_thread.joinable()) m.server_thread.join();
  m.close_all();
  m.close_can_sockets();
}

int SimPlc::port() const {
  return impl_->port;
}

std::chrono::steady_clock::time_point SimPlc::started() const {
  return impl_->started;
}

void SimPlc::attach_can(int fd) {
  std::lock_guard lock(impl_->map_mutex);
  impl_->can_fd = fd;
}

void SimPlc::add_fault(FaultConfig fault) {
  std::lock_guard lock(impl_->fault_mutex);
  impl_->faults.push_back({fault, Clock::now(), 0});
}

void SimPlc::clear_faults() {
  std::lock_guard lock(impl_->fault_mutex);
  impl_->faults.clear();
}

void SimPlc::restart(double down_s) {
  impl_->restart_request = std::max(0.0, down_s);
}

std::array<std::uint64_t, 256> SimPlc::function_counts() const {
  std::array<std::uint64_t, 256> out{};
  for (std::size_t i = 0; i < 256; ++i) out[i] = impl_->counts[i].load();
  return out;
}

std::uint64_t SimPlc::write_requests() const {
  std::uint64_t n = 0;
  for (int fc : {5, 6, 15, 16, 22, 23}) n += impl_->counts[static_cast<std::size_t>(fc)].load();
  return n;
}

std::vector<std::string> SimPlc::can_sockets() const {
  std::lock_guard lock(impl_->map_mutex);
  std::vector<std::string> out;
  for (const auto& e : impl_->can_eps)
    if (e.listen_fd >= 0) out.push_back(e.path);
  return out;
}

std::uint64_t SimPlc::can_clients() const {
  return impl_->can_accepted.load();
}

std::uint64_t SimPlc::can_bytes_from_clients() const {
  return impl_->can_from_clients.load();
}

std::uint64_t SimPlc::connections() const {
  return impl_->accepted.load();
}

std::vector<std::uint64_t> SimPlc::steps() const {
  std::lock_guard lock(impl_->map_mutex);
  std::vector<std::uint64_t> out;
  for (const auto& l : impl_->loops) out.push_back(l.steps);
  return out;
}

std::vector<LoopSample> SimPlc::latest() const {
  std::lock_guard lock(impl_->map_mutex);
  std::vector<LoopSample> out;
  for (const auto& l : impl_->loops) out.push_back(l.last);
  return out;
}

}  // namespace valvediag
