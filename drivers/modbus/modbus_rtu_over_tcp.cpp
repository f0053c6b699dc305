#include "valvediag/drivers/modbus_rtu_over_tcp.hpp"

#include <netdb.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <array>
#include <cerrno>
#include <chrono>
#include <cstdio>
#include <system_error>

namespace valvediag {

std::uint16_t modbus_crc16(std::span<const std::uint8_t> bytes) {
  std::uint16_t crc = 0xFFFF;
  for (std::uint8_t byte : bytes) {
    crc ^= byte;
    for (int k = 0; k < 8; ++k)
      crc = (crc & 1) ? static_cast<std::uint16_t>((crc >> 1) ^ 0xA001)
                      : static_cast<std::uint16_t>(crc >> 1);
  }
  return crc;
}

namespace {
using Clock = std::chrono::steady_clock;

// The longest reply: unit, function code, byte count, at most 255 data bytes, CRC. Every byte is
// read into this buffer and no further: an oversized reply cannot grow it.
constexpr std::size_t kMaxReply = 5 + 255;

std::string errno_text(int err) {
  return std::error_code(err, std::generic_category()).message();
}

std::string seconds_text(double s) {
  char b[32];
  std::snprintf(b, sizeof b, "%g s", s);
  return b;
}

// Waits for `events` on fd until `deadline`: 1 ready, 0 timed out, -1 error (errno set).
int wait_until(int fd, short events, Clock::time_point deadline) {
  for (;;) {
    const auto left = std::chrono::ceil<std::chrono::milliseconds>(deadline - Clock::now()).count();
    if (left <= 0) return 0;
    pollfd p{fd, events, 0};
    const int rc = ::poll(&p, 1, static_cast<int>(std::min<long long>(left, 60'000)));
    if (rc > 0) return 1;
    if (rc < 0 && errno != EINTR) return -1;
  }
}

// The standard names of the exception codes (as libmodbus words them for the other transports).
std::string exception_text(int code) {
  switch (code) {
    case 1:
      return "Illegal function";
    case 2:
      return "Illegal data address";
    case 3:
      return "Illegal data value";
    case 4:
      return "Slave device or server failure";
    case 5:
      return "Acknowledge";
    case 6:
      return "Slave device or server is busy";
    case 8:
      return "Memory parity error";
    case 10:
      return "Gateway path unavailable";
    case 11:
      return "Gateway target device failed to respond: check slave_id and the gateway's serial "
             "settings";
  }
  return "unknown exception code";
}

class RtuOverTcpTransport final : public ModbusTransport {
 public:
  explicit RtuOverTcpTransport(BusConfig cfg) : cfg_(std::move(cfg)) {}
  ~RtuOverTcpTransport() override { close(); }

  std::string where() const override {
    return cfg_.host + ":" + std::to_string(cfg_.port) + " (RTU over TCP)";
  }

  std::string connect() override {
    close();
    const auto deadline = Clock::now() + seconds(cfg_.timeout_s);
    std::string host = cfg_.host;  // "[::1]" as written in a URL
    if (host.size() > 2 && host.front() == '[' && host.back() == ']')
      host = host.substr(1, host.size() - 2);
    addrinfo hints{};
    hints.ai_family = AF_UNSPEC;
    hints.ai_socktype = SOCK_STREAM;
    hints.ai_flags = AI_NUMERICSERV;
    addrinfo* found = nullptr;
    const std::string port = std::to_string(cfg_.port);
    if (const int rc = ::getaddrinfo(host.c_str(), port.c_str(), &hints, &found); rc != 0)
      return "cannot connect to " + where() + ": cannot resolve '" + host +
             "': " + ::gai_strerror(rc);
    std::string why = "no address";
    for (const addrinfo* a = found; a && fd_ < 0; a = a->ai_next) {
      const int fd =
          ::socket(a->ai_family, a->ai_socktype | SOCK_NONBLOCK | SOCK_CLOEXEC, a->ai_protocol);
      if (fd < 0) {
        why = errno_text(errno);
        continue;
      }
      int err = ::connect(fd, a->ai_addr, a->ai_addrlen) == 0 ? 0 : errno;
      if (err == EINPROGRESS) {
        const int w = wait_until(fd, POLLOUT, deadline);
        socklen_t len = sizeof err;
        if (w > 0)
          ::getsockopt(fd, SOL_SOCKET, SO_ERROR, &err, &len);
        else
          err = w == 0 ? ETIMEDOUT : errno;
      }
      if (err == 0) {
        fd_ = fd;
      } else {
        why = err == ETIMEDOUT ? "no connection within " + seconds_text(cfg_.timeout_s)
                               : errno_text(err);
        ::close(fd);
      }
    }
    ::freeaddrinfo(found);
    if (fd_ < 0) return "cannot connect to " + where() + ": " + why;
    // A request is one small segment: send it now, not after the previous reply's ACK.
    const int one = 1;
    ::setsockopt(fd_, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
    return "";
  }

  void close() override {
    if (fd_ >= 0) ::close(fd_);
    fd_ = -1;
  }

  ModbusFailure read(const RegisterBlock& b, std::uint16_t* dest, std::string& error) override {
    // The read function codes, and no other: this transport builds no write request.
    const std::uint8_t fc = b.reg == RegisterType::holding ? 3 : 4;
    const auto unit = static_cast<std::uint8_t>(cfg_.slave_id);
    if (b.count < 1 || b.count > 125 || b.address < 0 || b.address + b.count > 65536) {
      error = "cannot read " + std::to_string(b.count) + " registers from " +
              std::to_string(b.address) + " in one request";
      return ModbusFailure::garbled;
    }
    if (!discard_unasked(error)) return ModbusFailure::link;

    std::array<std::uint8_t, 8> q{unit,
                                  fc,
                                  static_cast<std::uint8_t>(b.address >> 8),
                                  static_cast<std::uint8_t>(b.address & 0xff),
                                  static_cast<std::uint8_t>(b.count >> 8),
                                  static_cast<std::uint8_t>(b.count & 0xff)};
    const std::uint16_t qcrc = modbus_crc16(std::span(q).first(6));
    q[6] = static_cast<std::uint8_t>(qcrc & 0xff);
    q[7] = static_cast<std::uint8_t>(qcrc >> 8);
    const auto deadline = Clock::now() + seconds(cfg_.timeout_s);
    for (std::size_t sent = 0; sent < q.size();) {
      const ssize_t n = ::send(fd_, q.data() + sent, q.size() - sent, MSG_NOSIGNAL);
      if (n > 0) {
        sent += static_cast<std::size_t>(n);
        continue;
      }
      if (n < 0 && errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR) {
        error = "cannot send the request: " + errno_text(errno);
        return ModbusFailure::link;
      }
      const int w = wait_until(fd_, POLLOUT, deadline);
      if (w == 0) {
        error = "timed out: the request could not be sent within " + timeout_text();
        return ModbusFailure::timeout;
      }
      if (w < 0) {
        error = "cannot send the request: " + errno_text(errno);
        return ModbusFailure::link;
      }
    }

    // The frame's length is known from its function code (2 bytes) or its byte count (3 bytes);
    // read exactly that, so that nothing after it is taken for part of it.
    std::array<std::uint8_t, kMaxReply> r{};
    std::size_t got = 0, need = 2;
    while (got < need) {
      const int w = wait_until(fd_, POLLIN, deadline);
      if (w == 0) {
        error = got == 0 ? "timed out: no reply within " + timeout_text()
                         : "timed out: the reply stopped after " + std::to_string(got) + " of " +
                               std::to_string(need) + " bytes (truncated)";
        return ModbusFailure::timeout;
      }
      const ssize_t n = w < 0 ? -1 : ::recv(fd_, r.data() + got, need - got, 0);
      if (n == 0) {
        error = "connection closed by the peer" +
                (got == 0 ? std::string(" before the reply")
                          : " after " + std::to_string(got) + " bytes of the reply");
        return ModbusFailure::link;
      }
      if (n < 0) {
        if (errno == EAGAIN || errno == EWOULDBLOCK || errno == EINTR) continue;
        error = errno_text(errno);
        return ModbusFailure::link;
      }
      got += static_cast<std::size_t>(n);
      if (need == 2 && got == 2) {
        if ((r[1] & 0x7f) != fc) {
          error = "reply with function code " + std::to_string(r[1]) +
                  " to a request with function code " + std::to_string(fc);
          return ModbusFailure::garbled;
        }
        need = (r[1] & 0x80) ? 5 : 3;  // exception: code and CRC
      } else if (need == 3 && got == 3) {
        need = 5 + std::size_t{r[2]};  // at most kMaxReply
      }
    }

    const std::uint16_t crc = modbus_crc16(std::span(r).first(need - 2));
    const auto sent_crc = static_cast<std::uint16_t>(r[need - 2] | (r[need - 1] << 8));
    if (crc != sent_crc) {
      char b2[96];
      std::snprintf(b2, sizeof b2, "invalid CRC in the reply (0x%04X, computed 0x%04X)", sent_crc,
                    crc);
      error = b2;
      return ModbusFailure::garbled;
    }
    if (r[0] != unit) {
      error = "reply from unit " + std::to_string(r[0]) + " to a request to unit " +
              std::to_string(unit) + " (slave_id)";
      return ModbusFailure::garbled;
    }
    if (r[1] & 0x80) {
      error = "exception " + std::to_string(r[2]) + ": " + exception_text(r[2]);
      return ModbusFailure::exception;
    }
    if (r[2] != 2 * b.count) {
      error = "reply with " + std::to_string(r[2]) + " data bytes to a request for " +
              std::to_string(b.count) + " registers (" + std::to_string(2 * b.count) + " bytes)";
      return ModbusFailure::garbled;
    }
    for (int i = 0; i < b.count; ++i)
      dest[i] = static_cast<std::uint16_t>((r[3 + 2 * i] << 8) | r[4 + 2 * i]);
    return ModbusFailure::none;
  }

  bool reconnect_after_bad_reply() const override { return true; }

 private:
  static Clock::duration seconds(double s) {
    return std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(s));
  }
  std::string timeout_text() const { return seconds_text(cfg_.timeout_s); }

  // Bytes nobody asked for (trailing junk after a reply, another master's traffic on a shared
  // gateway) would shift the next reply: dropped, at most a few kilobytes without waiting. False
  // with `error` set when the peer has closed the connection (a gateway's idle timeout).
  bool discard_unasked(std::string& error) {
    std::uint8_t junk[256];
    for (int i = 0; i < 16; ++i) {
      const ssize_t n = ::recv(fd_, junk, sizeof junk, MSG_DONTWAIT);
      if (n > 0) continue;
      if (n == 0) {
        error = "connection closed by the peer";
        return false;
      }
      if (errno == EAGAIN || errno == EWOULDBLOCK) return true;
      if (errno == EINTR) continue;
      error = errno_text(errno);
      return false;
    }
    return true;
  }

  const BusConfig cfg_;
  int fd_ = -1;
};

}  // namespace

std::unique_ptr<ModbusTransport> make_rtu_over_tcp_transport(const BusConfig& bus) {
  return std::make_unique<RtuOverTcpTransport>(bus);
}

}  // namespace valvediag
