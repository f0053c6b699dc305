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

#include "valvediag/drivers/modbus_rtu_over_tcp.hpp"

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

Clock::duration seconds(double s) {
  return std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(s));
}

// When a point's raw registers last changed, for stale_after.
struct RawHistory {
  std::uint16_t regs[kMaxRegisters] = {};
  Clock::time_point since{};
  bool seen = false;
};

ModbusFailure classify(int err) {
  if (err == ETIMEDOUT) return ModbusFailure::timeout;
  if (err == EMBBADDATA || err == EMBBADCRC || err == EMBBADEXC || err == EMBMDATA ||
      err == EMBBADSLAVE || err == EMBUNKEXC)
    return ModbusFailure::garbled;
  if (err > MODBUS_ENOBASE && err < EMBXGTAR + 1) return ModbusFailure::exception;
  return ModbusFailure::link;
}

// Modbus TCP and RTU (serial) on libmodbus.
class LibmodbusTransport final : public ModbusTransport {
 public:
  explicit LibmodbusTransport(BusConfig cfg) : cfg_(std::move(cfg)) {}
  ~LibmodbusTransport() override { close(); }

  std::string where() const override {
    return cfg_.kind == BusKind::modbus_tcp
               ? cfg_.host + ":" + std::to_string(cfg_.port)
               : cfg_.device + " @" + std::to_string(cfg_.baud_rate) + " baud";
  }

  std::string connect() override {
    close();
    ctx_ = cfg_.kind == BusKind::modbus_tcp
               ? modbus_new_tcp(cfg_.host.c_str(), cfg_.port)
               : modbus_new_rtu(cfg_.device.c_str(), cfg_.baud_rate, cfg_.parity, cfg_.data_bits,
                                cfg_.stop_bits);
    if (!ctx_) return "cannot create a libmodbus context: " + std::string(modbus_strerror(errno));
    modbus_set_error_recovery(ctx_, MODBUS_ERROR_RECOVERY_NONE);
    modbus_set_slave(ctx_, cfg_.slave_id);
    const auto sec = static_cast<std::uint32_t>(cfg_.timeout_s);
    const auto usec = static_cast<std::uint32_t>(std::lround((cfg_.timeout_s - sec) * 1e6));
    modbus_set_response_timeout(ctx_, sec, std::min<std::uint32_t>(usec, 999999));
    // Between two bytes of one reply: a truncated reply fails within about one more timeout
    // (libmodbus's default is 0.5 s whatever the response timeout).
    const double byte_s = std::clamp(cfg_.timeout_s, 0.05, 0.5);
    modbus_set_byte_timeout(ctx_, 0, static_cast<std::uint32_t>(std::lround(byte_s * 1e6)));
    if (modbus_connect(ctx_) == -1) {
      const int err = errno;
      close();
      return "cannot connect to " + where() + ": " + modbus_strerror(err);
    }
    dirty_ = false;
    return "";
  }

  void close() override {
    if (!ctx_) return;
    modbus_close(ctx_);
    modbus_free(ctx_);
    ctx_ = nullptr;
  }

  ModbusFailure read(const RegisterBlock& b, std::uint16_t* dest, std::string& error) override {
    clear_line();
    const int rc = b.reg == RegisterType::holding
                       ? modbus_read_registers(ctx_, b.address, b.count, dest)
                       : modbus_read_input_registers(ctx_, b.address, b.count, dest);
    const int err = errno;
    if (rc == b.count) return ModbusFailure::none;
    error = rc < 0 ? modbus_strerror(err) : "short reply";
    const ModbusFailure f = rc < 0 ? classify(err) : ModbusFailure::garbled;
    if (rtu() && (f == ModbusFailure::timeout || f == ModbusFailure::garbled)) {
      dirty_ = true;
      drain_until_ = Clock::now() + seconds(cfg_.timeout_s);
    }
    return f;
  }

  bool reconnect_after_bad_reply() const override { return !rtu(); }

 private:
  bool rtu() const { return cfg_.kind == BusKind::modbus_rtu; }

  // RTU, before each request: discard a late reply still due (bounded by drain_until_), then
  // whatever else sits in the input buffer.
  void clear_line() {
    if (!rtu()) return;
    if (dirty_) {
      const int fd = modbus_get_socket(ctx_);
      std::uint8_t junk[256];
      for (auto now = Clock::now(); fd >= 0 && now < drain_until_; now = Clock::now()) {
        const auto left =
            std::chrono::duration_cast<std::chrono::milliseconds>(drain_until_ - now).count() + 1;
        pollfd p{fd, POLLIN, 0};
        const int rc = ::poll(&p, 1, static_cast<int>(left));
        if (rc < 0 && errno != EINTR) break;
        if (rc > 0 && ::read(fd, junk, sizeof junk) <= 0) break;  // link trouble: the request says
      }
      dirty_ = false;
    }
    modbus_flush(ctx_);
  }

  const BusConfig cfg_;
  modbus_t* ctx_ = nullptr;
  // RTU: after a timeout or garbled reply, a late (rest of a) reply may still come. Modbus RTU
  // has no transaction id, so it would be taken for the answer to the next request, perhaps of
  // another loop with the same layout: until drain_until_ the line is read and discarded.
  bool dirty_ = false;
  Clock::time_point drain_until_{};
};
}  // namespace

struct ModbusBus::Impl {
  BusConfig cfg;
  std::vector<LoopConfigEntry> loops;
  std::vector<std::vector<RegisterBlock>> plans;
  std::unique_ptr<ModbusTransport> wire;
  bool connected = false;
  bool ever_connected = false;
  Backoff backoff;
  Clock::time_point next_attempt{};
  Clock::time_point last_request{};
  std::vector<std::array<RawHistory, kPointCount>> history;  // per loop
  mutable std::mutex stats_mutex;
  BusStats st;

  ~Impl() { close(); }

  void set_error(const std::string& e) {
    std::lock_guard lock(stats_mutex);
    st.last_error = e;
  }

  void close() {
    if (wire) wire->close();
    if (connected) {
      std::lock_guard lock(stats_mutex);
      st.connected = false;
    }
    connected = false;
  }

  // One connection attempt; on failure the next one waits for the backoff.
  bool connect() {
    close();
    {
      std::lock_guard lock(stats_mutex);
      ++st.connect_attempts;
    }
    if (const std::string err = wire->connect(); !err.empty()) {
      fail_connect(err);
      return false;
    }
    connected = true;
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

  // Reads one block; "" on success, else the problem (counted).
  std::string read_block(const RegisterBlock& b, std::uint16_t* dest) {
    const int attempts = cfg.retries + 1;
    std::string problem;
    for (int a = 0; a < attempts; ++a) {
      if (!connected) {
        if (Clock::now() < next_attempt || !connect()) return st_last_error();
      }
      pause();
      std::string why;
      const ModbusFailure f = wire->read(b, dest, why);
      last_request = Clock::now();
      {
        std::lock_guard lock(stats_mutex);
        ++st.requests;
        if (f != ModbusFailure::none) ++st.errors;
      }
      if (f == ModbusFailure::none) return "";
      const std::string what = to_string(b.reg) + " registers " + std::to_string(b.address) + ".." +
                               std::to_string(b.address + b.count - 1) + " on " + wire->where() +
                               ": " + why;
      {
        std::lock_guard lock(stats_mutex);
        st.last_error = what;
        if (f == ModbusFailure::exception) ++st.exceptions;
        if (f == ModbusFailure::timeout) ++st.timeouts;
        if (f == ModbusFailure::garbled) ++st.garbled;
        if (f == ModbusFailure::link) ++st.disconnects;
      }
      // An exception is a definite answer from the device: retrying would not change it.
      if (f == ModbusFailure::exception) return what;
      problem = what;
      if (f == ModbusFailure::link || wire->reconnect_after_bad_reply()) {
        // Link lost, or a late/garbled reply may still be in the stream: a clean connection,
        // the first attempt at once.
        close();
        next_attempt = Clock::now();
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
  if (impl_->cfg.kind == BusKind::modbus_rtu_over_tcp)
    impl_->wire = make_rtu_over_tcp_transport(impl_->cfg);
  else
    impl_->wire = std::make_unique<LibmodbusTransport>(impl_->cfg);
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
