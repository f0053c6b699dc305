#include "valvediag/drivers/modbus_bus.hpp"

#include <modbus/modbus.h>
#include <poll.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <mutex>
#include <stdexcept>
#include <thread>

namespace valvediag {

std::vector<RegisterBlock> plan_requests(const LoopConfigEntry& loop) {
  constexpr int kMaxGap = 16, kMaxCount = 125;  // 125: Modbus limit for function codes 3/4
  std::vector<RegisterBlock> blocks;
  for (RegisterType reg : {RegisterType::holding, RegisterType::input}) {
    std::vector<std::pair<int, int>> spans;  // [begin, end)
    for (const auto& p : loop.points)
      if (p.present && p.reg == reg)
        spans.emplace_back(p.address, p.address + static_cast<int>(register_count(p.type)));
    std::sort(spans.begin(), spans.end());
    for (const auto& [b, e] : spans) {
      if (!blocks.empty() && blocks.back().reg == reg) {
        RegisterBlock& last = blocks.back();
        const int last_end = last.address + last.count;
        if (b - last_end <= kMaxGap && std::max(last_end, e) - last.address <= kMaxCount) {
          last.count = std::max(last_end, e) - last.address;
          continue;
        }
      }
      blocks.push_back({reg, b, e - b});
    }
  }
  return blocks;
}

namespace {
using Clock = std::chrono::steady_clock;

enum class Failure { none, exception, timeout, garbled, link };

Clock::duration seconds(double s) {
  return std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(s));
}

// When a point's raw registers last changed, for stale_after.
struct RawHistory {
  std::uint16_t regs[kMaxRegisters] = {};
  Clock::time_point since{};
  bool seen = false;
};

Failure classify(int err) {
  if (err == ETIMEDOUT) return Failure::timeout;
  if (err == EMBBADDATA || err == EMBBADCRC || err == EMBBADEXC || err == EMBMDATA ||
      err == EMBBADSLAVE || err == EMBUNKEXC)
    return Failure::garbled;
  if (err > MODBUS_ENOBASE && err < EMBXGTAR + 1) return Failure::exception;
  return Failure::link;
}
}  // namespace

struct ModbusBus::Impl {
  BusConfig cfg;
  std::vector<LoopConfigEntry> loops;
  std::vector<std::vector<RegisterBlock>> plans;
  modbus_t* ctx = nullptr;
  bool connected = false;
  bool ever_connected = false;
  Backoff backoff;
  Clock::time_point next_attempt{};
  Clock::time_point last_request{};
  // RTU: after a timeout or garbled reply, a late (rest of a) reply may still come. Modbus RTU
  // has no transaction id, so it would be taken for the answer to the next request, perhaps of
  // another loop with the same layout: until drain_until the line is read and discarded.
  bool dirty = false;
  Clock::time_point drain_until{};
  std::vector<std::array<RawHistory, kPointCount>> history;  // per loop
  mutable std::mutex stats_mutex;
  BusStats st;

  ~Impl() { close(); }

  void set_error(const std::string& e) {
    std::lock_guard lock(stats_mutex);
    st.last_error = e;
  }

  void close() {
    if (ctx) {
      modbus_close(ctx);
      modbus_free(ctx);
      ctx = nullptr;
    }
    if (connected) {
      std::lock_guard lock(stats_mutex);
      st.connected = false;
    }
    connected = false;
  }

  std::string where() const {
    return cfg.kind == BusKind::modbus_tcp
               ? cfg.host + ":" + std::to_string(cfg.port)
               : cfg.device + " @" + std::to_string(cfg.baud_rate) + " baud";
  }

  // One connection attempt; on failure the next one waits for the backoff.
  bool connect() {
    close();
    {
      std::lock_guard lock(stats_mutex);
      ++st.connect_attempts;
    }
    ctx = cfg.kind == BusKind::modbus_tcp
              ? modbus_new_tcp(cfg.host.c_str(), cfg.port)
              : modbus_new_rtu(cfg.device.c_str(), cfg.baud_rate, cfg.parity, cfg.data_bits,
                               cfg.stop_bits);
    if (!ctx) {
      fail_connect("cannot create a libmodbus context: " + std::string(modbus_strerror(errno)));
      return false;
    }
    modbus_set_error_recovery(ctx, MODBUS_ERROR_RECOVERY_NONE);
    modbus_set_slave(ctx, cfg.slave_id);
    const auto sec = static_cast<std::uint32_t>(cfg.timeout_s);
    const auto usec = static_cast<std::uint32_t>(std::lround((cfg.timeout_s - sec) * 1e6));
    modbus_set_response_timeout(ctx, sec, std::min<std::uint32_t>(usec, 999999));
    // Between two bytes of one reply: a truncated reply fails within about one more timeout
    // (libmodbus's default is 0.5 s whatever the response timeout).
    const double byte_s = std::clamp(cfg.timeout_s, 0.05, 0.5);
    modbus_set_byte_timeout(ctx, 0, static_cast<std::uint32_t>(std::lround(byte_s * 1e6)));
    if (modbus_connect(ctx) == -1) {
      const int err = errno;
      fail_connect("cannot connect to " + where() + ": " + modbus_strerror(err));
      return false;
    }
    connected = true;
    dirty = false;
    backoff.reset();
    std::lock_guard lock(stats_mutex);
    st.connected = true;
    if (ever_connected) ++st.reconnects;
    ever_connected = true;
    return true;
  }

  void fail_connect(const std::string& msg) {
    close();
    const double wait = backoff.next();
    next_attempt = Clock::now() +
                   std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(wait));
    set_error(msg);
  }

  void pause() {
    if (cfg.pause_s <= 0) return;
    std::this_thread::sleep_until(last_request + seconds(cfg.pause_s));
  }

  // RTU, before each request: discard a late reply still due (bounded by drain_until), then
  // whatever else sits in the input buffer.
  void clear_line() {
    if (cfg.kind != BusKind::modbus_rtu) return;
    if (dirty) {
      const int fd = modbus_get_socket(ctx);
      std::uint8_t junk[256];
      for (auto now = Clock::now(); fd >= 0 && now < drain_until; now = Clock::now()) {
        const auto left =
            std::chrono::duration_cast<std::chrono::milliseconds>(drain_until - now).count() + 1;
        pollfd p{fd, POLLIN, 0};
        const int rc = ::poll(&p, 1, static_cast<int>(left));
        if (rc < 0 && errno != EINTR) break;
        if (rc > 0 && ::read(fd, junk, sizeof junk) <= 0) break;  // link trouble: the request says
      }
      dirty = false;
    }
    modbus_flush(ctx);
  }

  // Reads one block; "" on success, else the problem (counted).
  std::string read_block(const RegisterBlock& b, std::uint16_t* dest) {
    const int attempts = cfg.retries + 1;
    std::string problem;
    for (int a = 0; a < attempts; ++a) {
      if (!connected) {
        if (Clock::now() < next_attempt || !connect()) return st_last_error();
      }
      pause();
      clear_line();
      int rc = b.reg == RegisterType::holding
                   ? modbus_read_registers(ctx, b.address, b.count, dest)
                   : modbus_read_input_registers(ctx, b.address, b.count, dest);
      const int err = errno;
      last_request = Clock::now();
      {
        std::lock_guard lock(stats_mutex);
        ++st.requests;
        if (rc != b.count) ++st.errors;
      }
      if (rc == b.count) return "";
      const std::string what = to_string(b.reg) + " registers " + std::to_string(b.address) + ".." +
                               std::to_string(b.address + b.count - 1) + " on " + where() + ": " +
                               (rc < 0 ? modbus_strerror(err) : "short reply");
      const Failure f = rc < 0 ? classify(err) : Failure::garbled;
      {
        std::lock_guard lock(stats_mutex);
        st.last_error = what;
        if (f == Failure::exception) ++st.exceptions;
        if (f == Failure::timeout) ++st.timeouts;
        if (f == Failure::garbled) ++st.garbled;
        if (f == Failure::link) ++st.disconnects;
      }
      // An exception is a definite answer from the device: retrying would not change it.
      if (f == Failure::exception) return what;
      problem = what;
      if (f == Failure::link || cfg.kind == BusKind::modbus_tcp) {
        // Link lost, or a late/garbled reply may still be in the stream: a clean connection,
        // the first attempt at once.
        close();
        next_attempt = Clock::now();
      } else {
        dirty = true;
        drain_until = Clock::now() + seconds(cfg.timeout_s);
      }
    }
    return problem;
  }

  std::string st_last_error() {
    std::lock_guard lock(stats_mutex);
    return "not connected: " + st.last_error;
  }
};

ModbusBus::ModbusBus(BusConfig config, std::vector<LoopConfigEntry> loops)
    : impl_(std::make_unique<Impl>()) {
  if (config.kind == BusKind::socketcan)
    throw std::invalid_argument("bus '" + config.name + "' is not a Modbus bus");
  impl_->backoff = Backoff(config.reconnect_max_s);
  impl_->cfg = std::move(config);
  impl_->loops = std::move(loops);
  for (const auto& l : impl_->loops) impl_->plans.push_back(plan_requests(l));
  impl_->history.resize(impl_->loops.size());
}

ModbusBus::~ModbusBus() = default;

const std::string& ModbusBus::name() const {
  return impl_->cfg.name;
}

LoopValues ModbusBus::read(std::size_t loop) {
  Impl& m = *impl_;
  LoopValues out;
  if (loop >= m.loops.size()) {
    out.error = "no loop " + std::to_string(loop) + " on bus " + m.cfg.name;
    return out;
  }
  const LoopConfigEntry& l = m.loops[loop];
  for (std::size_t i = 0; i < kPointCount; ++i)
    if (!l.points[i].present) out.points[i].quality = Quality::good;  // absent: NaN, not an error
  std::uint16_t regs[125];
  for (const RegisterBlock& b : m.plans[loop]) {
    const std::string problem = m.read_block(b, regs);
    for (std::size_t i = 0; i < kPointCount; ++i) {
      const PointConfig& p = l.points[i];
      if (!p.present || p.reg != b.reg || p.address < b.address ||
          p.address + static_cast<int>(register_count(p.type)) > b.address + b.count)
        continue;
      if (!problem.empty()) {
        out.points[i] = {std::numeric_limits<double>::quiet_NaN(), Quality::comm_error};
        continue;
      }
      const std::span<const std::uint16_t> span(regs + (p.address - b.address),
                                                register_count(p.type));
      const double v = decode_registers(span, p.type, p.order, p.scale, p.offset);
      out.points[i] = {v, std::isfinite(v) ? Quality::good : Quality::invalid};
      if (!std::isfinite(v) && out.error.empty())
        out.error = l.name + "." + to_string(static_cast<PointName>(i)) + ": the device sent " +
                    "a value that is not a number";
      if (p.stale_after_s > 0) {
        // Frozen registers: the PLC answers but no longer updates the value.
        RawHistory& h = m.history[loop][i];
        const auto now = Clock::now();
        if (!h.seen || !std::equal(span.begin(), span.end(), h.regs)) {
          std::copy(span.begin(), span.end(), h.regs);
          h.since = now;
          h.seen = true;
        }
        const double same_s = std::chrono::duration<double>(now - h.since).count();
        if (same_s > p.stale_after_s && out.points[i].quality == Quality::good) {
          out.points[i].quality = Quality::stale;
          if (out.error.empty()) {
            char b2[128];
            std::snprintf(b2, sizeof b2, "unchanged for %.1f s (stale_after %g s)", same_s,
                          p.stale_after_s);
            out.error = l.name + "." + to_string(static_cast<PointName>(i)) + ": " +
                        to_string(p.reg) + " register(s) " + std::to_string(p.address) + ".." +
                        std::to_string(p.address + static_cast<int>(span.size()) - 1) + " " + b2 +
                        "; the PLC may have stopped updating them";
          }
        }
      }
    }
    if (!problem.empty() && out.error.empty()) out.error = problem;
  }
  return out;
}

BusStats ModbusBus::stats() const {
  std::lock_guard lock(impl_->stats_mutex);
  return impl_->st;
}

}  // namespace valvediag
