// The one small interface every field-bus driver implements (Modbus TCP/RTU/RTU over TCP,
// SocketCAN, the simulated plant). It only reads: there is no write in it, so nothing built on it
// can move a valve.
#pragma once

#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <string>

#include "valvediag/drivers/site_config.hpp"

namespace valvediag {

// Quality of one recorded value.
//   good:       read at this tick
//   stale:      the bus answered, but the value is old: CAN frames that stopped coming, or a
//               raw value unchanged for longer than the point's stale_after (a frozen PLC)
//   comm_error: the request failed (timeout, exception, garbled reply, link down)
//   missed:     the recorder could not poll at this tick (it fell behind); no request was made
//   invalid:    the device sent a value that is not a number (float NaN or infinity)
enum class Quality : std::uint8_t { good = 0, stale = 1, comm_error = 2, missed = 3, invalid = 4 };
std::string to_string(Quality q);

struct PointValue {
  double value = std::numeric_limits<double>::quiet_NaN();
  Quality quality = Quality::comm_error;
};

struct LoopValues {
  std::array<PointValue, kPointCount> points;  // indexed by PointName; absent points stay NaN
  std::string error;                           // first problem of this read, "" when all good
  PointValue& operator[](PointName p) { return points[static_cast<std::size_t>(p)]; }
  const PointValue& operator[](PointName p) const { return points[static_cast<std::size_t>(p)]; }
};

// Counters every driver keeps; read by the status line and the tests.
struct BusStats {
  std::uint64_t requests = 0;     // requests sent (reads only)
  std::uint64_t errors = 0;       // failed requests of any kind
  std::uint64_t timeouts = 0;     // no reply in time
  std::uint64_t exceptions = 0;   // Modbus exception responses
  std::uint64_t garbled = 0;      // replies that did not parse (bad CRC/length/header)
  std::uint64_t disconnects = 0;  // link lost
  std::uint64_t reconnects = 0;   // link re-established after a loss
  std::uint64_t connect_attempts = 0;
  bool connected = false;
  std::string last_error;
};

class Bus {
 public:
  virtual ~Bus() = default;
  virtual const std::string& name() const = 0;
  // Reads the current values of the bus's loop number `loop` (its position in the loop list the
  // driver was built with). Never throws for communication problems: they come back as value
  // qualities with `error` set. Blocks at most about (retries + 1) x timeout per request (twice
  // that on Modbus RTU after a failure: the line is cleared of a late reply first). Reconnects
  // by itself with backoff; while the link is down it returns comm_error at once.
  virtual LoopValues read(std::size_t loop) = 0;
  virtual BusStats stats() const = 0;
};

// Exponential backoff for reconnection attempts: 50 ms, 100 ms, ... capped at `max_s`.
class Backoff {
 public:
  explicit Backoff(double max_s = 1.0, double first_s = 0.05) : max_(max_s), first_(first_s) {}
  double next() {  // seconds to wait before the next attempt
    const double d = current_ == 0.0 ? first_ : std::min(max_, current_ * 2.0);
    current_ = d;
    return d;
  }
  void reset() { current_ = 0.0; }

 private:
  double max_, first_, current_ = 0.0;
};

}  // namespace valvediag
