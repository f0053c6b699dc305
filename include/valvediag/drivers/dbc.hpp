// A small reader for CAN database (DBC) files: the BO_ (message) and SG_ (signal) lines, which is
// all the recorder needs to locate a loop's values in CAN frames. Other DBC sections are skipped.
#pragma once

#include <cstdint>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "valvediag/drivers/value_codec.hpp"

namespace valvediag {

struct DbcSignal {
  std::string name;
  CanSignal signal;  // frame_id/extended filled from the message
  double minimum = 0.0, maximum = 0.0;
  std::string unit;
  bool multiplexed = false;  // "m3"-style multiplexed signals are read but not decodable alone
  int line = 0;
};

struct DbcMessage {
  std::uint32_t id = 0;  // without the extended flag bit
  bool extended = false;
  std::string name;
  unsigned dlc = 8;
  std::string sender;
  std::vector<DbcSignal> signals;
  int line = 0;
};

struct Dbc {
  std::vector<DbcMessage> messages;
  const DbcMessage* find_message(std::string_view name) const;
  const DbcMessage* find_message(std::uint32_t id) const;
};

// "<file>:<line>: <problem>; <what to do>".
class DbcError : public std::runtime_error {
 public:
  DbcError(const std::string& file, int line, const std::string& problem);
  int line() const { return line_; }

 private:
  int line_;
};

// Parses DBC text; `source_name` names it in messages. Throws DbcError on a malformed BO_ or SG_
// line, an SG_ before any BO_, or a signal outside its message's length.
Dbc parse_dbc(std::string_view text, const std::string& source_name);
Dbc load_dbc_file(const std::string& path);  // DbcError also when the file cannot be read

}  // namespace valvediag
