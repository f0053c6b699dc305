// SocketCAN and frame-level CAN transports. Receiving only: no transport here has a send, so
// nothing built on them can put a frame on the bus. The decoding path (frames -> loop values) is
// the same for a real SocketCAN socket, a socketpair carrying struct can_frame (the test mock),
// the simulated PLC's Unix socket (interface = "unix:PATH") and a candump log replay.
#pragma once

#include <chrono>
#include <cstdint>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "valvediag/drivers/bus.hpp"

namespace valvediag {

struct CanFrame {
  std::uint32_t id = 0;
  bool extended = false;
  std::uint8_t dlc = 0;
  std::uint8_t data[8] = {0, 0, 0, 0, 0, 0, 0, 0};
};

class CanTransport {
 public:
  virtual ~CanTransport() = default;
  // The next frame within `timeout_s`; nullopt on timeout. Throws std::runtime_error when the
  // transport is broken (the peer closed, a read error).
  virtual std::optional<CanFrame> receive(double timeout_s) = 0;
  // Whether reopen() can bring a broken transport back (the bus then retries with backoff).
  virtual bool can_reopen() const { return false; }
  // One attempt to re-establish a broken transport; throws std::runtime_error saying why not.
  virtual void reopen() {}
};

// Reads struct can_frame records from a file descriptor: a SocketCAN raw socket or one end of a
// socketpair (the frame-level mock). Takes ownership of `fd` when `own` is set.
class FdCanTransport final : public CanTransport {
 public:
  FdCanTransport(int fd, bool own);
  ~FdCanTransport() override;
  std::optional<CanFrame> receive(double timeout_s) override;

 private:
  int fd_;
  bool own_;
};

// The simulated PLC's frame socket (`valvediag sim-plc --can-socket PATH`; interface =
// "unix:PATH" in the site): a Unix SOCK_SEQPACKET connection carrying one struct can_frame per
// message. Its sending side is shut down as soon as it connects, so not a byte can go back.
// Connects in the constructor (throws std::runtime_error naming the path and what to do), and
// reconnects through reopen() when the simulated PLC restarts.
class UnixCanTransport final : public CanTransport {
 public:
  explicit UnixCanTransport(std::string path);
  ~UnixCanTransport() override;
  std::optional<CanFrame> receive(double timeout_s) override;
  bool can_reopen() const override { return true; }
  void reopen() override;
  const std::string& path() const { return path_; }

 private:
  std::string path_;
  std::unique_ptr<FdCanTransport> fd_;
};

// Opens a raw SocketCAN socket on `interface` (receive only). Throws std::runtime_error with
// what to do when the kernel has no CAN support or the interface does not exist.
std::unique_ptr<CanTransport> open_socketcan(const std::string& interface);

// One candump log line "(1436509052.249713) can0 123#DEADBEEF" (also extended ids of 8 hex
// digits and remote frames "123#R"); nullopt for blank/comment lines; throws
// std::invalid_argument naming what is wrong otherwise.
std::optional<CanFrame> parse_candump_line(std::string_view line);
// Replays a candump log frame by frame (as fast as it is read); then reports timeouts.
class CandumpReplay final : public CanTransport {
 public:
  // Throws std::invalid_argument "<source>:<line>: ..." on a malformed line.
  CandumpReplay(std::string_view log, const std::string& source_name);
  std::optional<CanFrame> receive(double timeout_s) override;
  std::size_t size() const { return frames_.size(); }

 private:
  std::vector<CanFrame> frames_;
  std::size_t next_ = 0;
};

// Frames -> latest values of the loops' signals, with their age. Not thread-safe by itself.
class CanDecoder {
 public:
  explicit CanDecoder(std::vector<LoopConfigEntry> loops);
  // Updates every signal carried by this frame; returns how many it updated.
  std::size_t apply(const CanFrame& frame, std::chrono::steady_clock::time_point now);
  // Values of loop `loop` at `now`: good when its frame came within twice the loop's sample
  // period, stale when older or when the signal's value has not changed for longer than its
  // stale_after, comm_error when never received.
  LoopValues values(std::size_t loop, std::chrono::steady_clock::time_point now) const;
  std::size_t loop_count() const { return loops_.size(); }

 private:
  struct Slot {
    double value = 0.0;
    std::chrono::steady_clock::time_point when{};     // last frame
    std::chrono::steady_clock::time_point changed{};  // last change of the value
    bool seen = false;
  };
  std::vector<LoopConfigEntry> loops_;
  std::vector<std::array<Slot, kPointCount>> slots_;
};

// The bus: a receiver thread feeds the decoder; read() returns the latest values.
class CanBus final : public Bus {
 public:
  CanBus(BusConfig config, std::vector<LoopConfigEntry> loops,
         std::unique_ptr<CanTransport> transport);
  ~CanBus() override;
  const std::string& name() const override;
  LoopValues read(std::size_t loop) override;
  BusStats stats() const override;
  std::uint64_t frames() const;  // frames received

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace valvediag
