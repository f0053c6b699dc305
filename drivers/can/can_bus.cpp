#include "valvediag/drivers/can_bus.hpp"

#include <linux/can.h>
#include <linux/can/raw.h>
#include <net/if.h>
#include <poll.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <mutex>
#include <thread>

namespace valvediag {

namespace {
using Clock = std::chrono::steady_clock;

CanFrame from_linux(const can_frame& f) {
  CanFrame c;
  c.extended = (f.can_id & CAN_EFF_FLAG) != 0;
  c.id = f.can_id & (c.extended ? CAN_EFF_MASK : CAN_SFF_MASK);
  c.dlc = std::min<std::uint8_t>(f.can_dlc, 8);
  std::memcpy(c.data, f.data, 8);
  return c;
}
}  // namespace

FdCanTransport::FdCanTransport(int fd, bool own) : fd_(fd), own_(own) {}
FdCanTransport::~FdCanTransport() {
  if (own_ && fd_ >= 0) ::close(fd_);
}

std::optional<CanFrame> FdCanTransport::receive(double timeout_s) {
  pollfd p{fd_, POLLIN, 0};
  const int rc = ::poll(&p, 1, static_cast<int>(std::lround(timeout_s * 1000)));
  if (rc < 0) {
    if (errno == EINTR) return std::nullopt;
    throw std::runtime_error(std::string("CAN receive failed: ") + std::strerror(errno));
  }
  if (rc == 0) return std::nullopt;
  can_frame f{};
  const ssize_t n = ::read(fd_, &f, sizeof f);
  if (n == 0) throw std::runtime_error("CAN transport closed by the peer");
  if (n < 0) {
    if (errno == EINTR || errno == EAGAIN) return std::nullopt;
    throw std::runtime_error(std::string("CAN receive failed: ") + std::strerror(errno));
  }
  if (static_cast<std::size_t>(n) != sizeof f)
    throw std::runtime_error("CAN transport delivered " + std::to_string(n) +
                             " bytes, not a struct can_frame (" + std::to_string(sizeof f) + ")");
  if (f.can_id & (CAN_ERR_FLAG | CAN_RTR_FLAG)) return std::nullopt;  // no data in these
  return from_linux(f);
}

namespace {
// A connected, receive-only SOCK_SEQPACKET socket to the simulated PLC at `path`.
int connect_frame_socket(const std::string& path) {
  const std::string start =
      "; start the simulated PLC first: valvediag sim-plc --config SITE "
      "--can-socket " +
      path;
  sockaddr_un a{};
  if (path.empty() || path.size() >= sizeof a.sun_path)
    throw std::runtime_error("CAN socket path '" + path + "' is empty or longer than " +
                             std::to_string(sizeof a.sun_path - 1) + " bytes; choose another");
  struct stat st {};
  if (::stat(path.c_str(), &st) == 0 && !S_ISSOCK(st.st_mode))
    throw std::runtime_error("CAN socket '" + path +
                             "' exists but is not a socket; check interface = \"unix:" + path +
                             "\"");
  const int s = ::socket(AF_UNIX, SOCK_SEQPACKET | SOCK_CLOEXEC, 0);
  if (s < 0)
    throw std::runtime_error(std::string("cannot create a Unix socket: ") + std::strerror(errno));
  a.sun_family = AF_UNIX;
  std::memcpy(a.sun_path, path.c_str(), path.size());
  if (::connect(s, reinterpret_cast<sockaddr*>(&a), sizeof a) < 0) {
    const int err = errno;
    ::close(s);
    if (err == ENOENT) throw std::runtime_error("CAN socket '" + path + "' does not exist" + start);
    if (err == ECONNREFUSED)
      throw std::runtime_error("nobody listens on CAN socket '" + path +
                               "' (left behind by a stopped simulated PLC?)" + start);
    if (err == EPROTOTYPE)
      throw std::runtime_error("'" + path +
                               "' is not a SOCK_SEQPACKET socket of the simulated PLC" + start);
    throw std::runtime_error("cannot connect to CAN socket '" + path + "': " + std::strerror(err));
  }
  ::shutdown(s, SHUT_WR);  // read only, enforced by the kernel
  return s;
}
}  // namespace

UnixCanTransport::UnixCanTransport(std::string path) : path_(std::move(path)) {
  reopen();
}
UnixCanTransport::~UnixCanTransport() = default;

void UnixCanTransport::reopen() {
  fd_.reset();
  fd_ = std::make_unique<FdCanTransport>(connect_frame_socket(path_), true);
}

std::optional<CanFrame> UnixCanTransport::receive(double timeout_s) {
  if (!fd_) throw std::runtime_error("CAN socket '" + path_ + "' is not connected");
  try {
    return fd_->receive(timeout_s);
  } catch (const std::runtime_error& e) {
    fd_.reset();
    throw std::runtime_error("CAN socket '" + path_ + "': " + e.what() +
                             " (the simulated PLC stopped?)");
  }
}

std::unique_ptr<CanTransport> open_socketcan(const std::string& interface) {
  const int s = ::socket(PF_CAN, SOCK_RAW, CAN_RAW);
  if (s < 0)
    throw std::runtime_error(
        "SocketCAN is not available on this machine: socket(PF_CAN, SOCK_RAW, CAN_RAW) failed: " +
        std::string(std::strerror(errno)) +
        ". The kernel needs CAN support (modprobe can_raw; a virtual bus: ip link add dev vcan0 "
        "type vcan); or record the loops over Modbus");
  ifreq ifr{};
  if (interface.empty() || interface.size() >= sizeof ifr.ifr_name) {
    ::close(s);
    throw std::runtime_error("CAN interface name '" + interface + "' is invalid");
  }
  std::memcpy(ifr.ifr_name, interface.c_str(), interface.size());
  if (::ioctl(s, SIOCGIFINDEX, &ifr) < 0) {
    const int err = errno;
    ::close(s);
    throw std::runtime_error("CAN interface '" + interface + "' not found (" + std::strerror(err) +
                             "); check `ip link show " + interface + "`");
  }
  sockaddr_can addr{};
  addr.can_family = AF_CAN;
  addr.can_ifindex = ifr.ifr_ifindex;
  if (::bind(s, reinterpret_cast<sockaddr*>(&addr), sizeof addr) < 0) {
    const int err = errno;
    ::close(s);
    throw std::runtime_error("cannot bind to CAN interface '" + interface +
                             "': " + std::strerror(err));
  }
  return std::make_unique<FdCanTransport>(s, true);
}

std::optional<CanFrame> parse_candump_line(std::string_view line) {
  while (!line.empty() && (line.back() == '\r' || line.back() == ' ')) line.remove_suffix(1);
  while (!line.empty() && line.front() == ' ') line.remove_prefix(1);
  if (line.empty() || line.front() == '#') return std::nullopt;
  // "(timestamp) interface id#data"
  if (line.front() != '(') throw std::invalid_argument("expected '(timestamp)' at the start");
  const auto close = line.find(')');
  if (close == std::string_view::npos) throw std::invalid_argument("unterminated '(timestamp'");
  line.remove_prefix(close + 1);
  while (!line.empty() && line.front() == ' ') line.remove_prefix(1);
  const auto sp = line.find(' ');
  if (sp == std::string_view::npos || sp == 0)
    throw std::invalid_argument("expected the interface name and 'id#data'");
  line.remove_prefix(sp + 1);
  while (!line.empty() && line.front() == ' ') line.remove_prefix(1);
  const auto hash = line.find('#');
  if (hash == std::string_view::npos) throw std::invalid_argument("expected 'id#data'");
  const std::string_view id = line.substr(0, hash);
  std::string_view data = line.substr(hash + 1);
  if (id.empty() || (id.size() != 3 && id.size() != 8))
    throw std::invalid_argument("CAN id must have 3 (standard) or 8 (extended) hex digits");
  CanFrame f;
  const auto r = std::from_chars(id.data(), id.data() + id.size(), f.id, 16);
  if (r.ec != std::errc() || r.ptr != id.data() + id.size())
    throw std::invalid_argument("CAN id '" + std::string(id) + "' is not hexadecimal");
  f.extended = id.size() == 8;
  if (f.extended ? f.id > CAN_EFF_MASK : f.id > CAN_SFF_MASK)
    throw std::invalid_argument("CAN id out of range");
  if (!data.empty() && (data.front() == 'R' || data.front() == '#'))
    return std::nullopt;  // remote frame or CAN FD: carries no classic data
  if (data.size() % 2 != 0 || data.size() > 16)
    throw std::invalid_argument("data must be 0..8 bytes as pairs of hex digits");
  f.dlc = static_cast<std::uint8_t>(data.size() / 2);
  for (std::size_t i = 0; i < f.dlc; ++i) {
    unsigned v = 0;
    const auto d = std::from_chars(data.data() + 2 * i, data.data() + 2 * i + 2, v, 16);
    if (d.ec != std::errc() || d.ptr != data.data() + 2 * i + 2)
      throw std::invalid_argument("data byte '" + std::string(data.substr(2 * i, 2)) +
                                  "' is not hexadecimal");
    f.data[i] = static_cast<std::uint8_t>(v);
  }
  return f;
}

CandumpReplay::CandumpReplay(std::string_view log, const std::string& source_name) {
  int line_no = 0;
  while (!log.empty()) {
    const auto nl = log.find('\n');
    const std::string_view line = log.substr(0, nl);
    log.remove_prefix(nl == std::string_view::npos ? log.size() : nl + 1);
    ++line_no;
    try {
      if (auto f = parse_candump_line(line)) frames_.push_back(*f);
    } catch (const std::invalid_argument& e) {
      throw std::invalid_argument(source_name + ":" + std::to_string(line_no) + ": " + e.what() +
                                  "; lines look like '(1436509052.249713) can0 123#DEADBEEF'");
    }
  }
}

std::optional<CanFrame> CandumpReplay::receive(double timeout_s) {
  if (next_ < frames_.size()) return frames_[next_++];
  std::this_thread::sleep_for(std::chrono::duration<double>(std::min(timeout_s, 0.05)));
  return std::nullopt;
}

CanDecoder::CanDecoder(std::vector<LoopConfigEntry> loops)
    : loops_(std::move(loops)), slots_(loops_.size()) {}

std::size_t CanDecoder::apply(const CanFrame& frame, Clock::time_point now) {
  std::size_t n = 0;
  for (std::size_t l = 0; l < loops_.size(); ++l)
    for (std::size_t i = 0; i < kPointCount; ++i) {
      const PointConfig& p = loops_[l].points[i];
      if (!p.present || p.can.frame_id != frame.id || p.can.extended != frame.extended) continue;
      Slot& s = slots_[l][i];
      double v = 0.0;
      try {
        v = decode_can_signal(p.can, std::span<const std::uint8_t>(frame.data, frame.dlc));
      } catch (const std::invalid_argument&) {
        continue;  // a frame shorter than the signal: not this value
      }
      // The decoded value is a function of the signal's raw bits: equal values, equal bits.
      if (!s.seen || v != s.value) s.changed = now;
      s.value = v;
      s.when = now;
      s.seen = true;
      ++n;
    }
  return n;
}

LoopValues CanDecoder::values(std::size_t loop, Clock::time_point now) const {
  LoopValues out;
  if (loop >= loops_.size()) {
    out.error = "no loop " + std::to_string(loop);
    return out;
  }
  const auto& l = loops_[loop];
  const auto max_age = std::chrono::duration<double>(2.0 * l.sample_period_s);
  for (std::size_t i = 0; i < kPointCount; ++i) {
    const PointConfig& p = l.points[i];
    const Slot& s = slots_[loop][i];
    if (!p.present) {
      out.points[i].quality = Quality::good;
      continue;
    }
    if (!s.seen) {
      if (out.error.empty())
        out.error = l.name + "." + to_string(static_cast<PointName>(i)) + ": no frame with id 0x" +
                    [&] {
                      char b[16];
                      std::snprintf(b, sizeof b, "%X", p.can.frame_id);
                      return std::string(b);
                    }() +
                    " received yet";
      continue;
    }
    const bool fresh = now - s.when <= max_age;
    const double same_s = std::chrono::duration<double>(now - s.changed).count();
    const bool frozen = p.stale_after_s > 0 && same_s > p.stale_after_s;
    out.points[i] = {s.value, fresh && !frozen ? Quality::good : Quality::stale};
    if (out.error.empty() && !fresh)
      out.error = l.name + "." + to_string(static_cast<PointName>(i)) + ": frame stopped coming";
    if (out.error.empty() && frozen) {
      char b[96];
      std::snprintf(b, sizeof b, "unchanged for %.1f s (stale_after %g s)", same_s,
                    p.stale_after_s);
      out.error = l.name + "." + to_string(static_cast<PointName>(i)) + ": " + b +
                  "; the PLC may have stopped updating it";
    }
  }
  return out;
}

struct CanBus::Impl {
  BusConfig cfg;
  std::unique_ptr<CanTransport> transport;
  mutable std::mutex mutex;
  CanDecoder decoder;
  BusStats st;
  std::uint64_t frames = 0;
  std::atomic<bool> running{true};
  std::thread receiver;

  Impl(BusConfig c, std::vector<LoopConfigEntry> loops, std::unique_ptr<CanTransport> t)
      : cfg(std::move(c)), transport(std::move(t)), decoder(std::move(loops)) {}

  void receive_loop() {
    Backoff backoff(1.0);
    while (running) {
      std::optional<CanFrame> f;
      try {
        f = transport->receive(0.05);
      } catch (const std::exception& e) {
        {
          std::lock_guard lock(mutex);
          st.connected = false;
          ++st.errors;
          ++st.disconnects;
          st.last_error = e.what();
        }
        // Meanwhile the values age into stale; a transport that cannot reopen stays broken.
        if (!transport->can_reopen() || !reopen(backoff)) return;
        continue;
      }
      if (!f) continue;
      std::lock_guard lock(mutex);
      ++frames;
      decoder.apply(*f, Clock::now());
    }
  }

  // Reopens with backoff until it works (true) or the bus is closed (false).
  bool reopen(Backoff& backoff) {
    while (running) {
      const auto until = Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                            std::chrono::duration<double>(backoff.next()));
      while (running && Clock::now() < until)  // short slices: the destructor is prompt
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
      if (!running) break;
      std::lock_guard lock(mutex);
      ++st.connect_attempts;
      try {
        transport->reopen();
      } catch (const std::exception& e) {
        st.last_error = e.what();
        continue;
      }
      st.connected = true;
      ++st.reconnects;
      backoff.reset();
      return true;
    }
    return false;
  }
};

CanBus::CanBus(BusConfig config, std::vector<LoopConfigEntry> loops,
               std::unique_ptr<CanTransport> transport)
    : impl_(std::make_unique<Impl>(std::move(config), std::move(loops), std::move(transport))) {
  impl_->st.connected = true;
  impl_->receiver = std::thread([this] { impl_->receive_loop(); });
}

CanBus::~CanBus() {
  impl_->running = false;
  if (impl_->receiver.joinable()) impl_->receiver.join();
}

const std::string& CanBus::name() const {
  return impl_->cfg.name;
}

LoopValues CanBus::read(std::size_t loop) {
  std::lock_guard lock(impl_->mutex);
  ++impl_->st.requests;  // a read of the latest values; nothing goes on the bus
  LoopValues v = impl_->decoder.values(loop, Clock::now());
  if (!v.error.empty()) ++impl_->st.errors;
  if (!impl_->st.connected && v.error.empty()) v.error = impl_->st.last_error;
  return v;
}

BusStats CanBus::stats() const {
  std::lock_guard lock(impl_->mutex);
  return impl_->st;
}

std::uint64_t CanBus::frames() const {
  std::lock_guard lock(impl_->mutex);
  return impl_->frames;
}

}  // namespace valvediag
