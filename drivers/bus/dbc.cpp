// DBC reader: BO_ and SG_ lines only (the rest of a DBC file describes nodes, comments and
// attributes the recorder does not need).
#include "valvediag/drivers/dbc.hpp"

#include <cctype>
#include <charconv>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>

namespace valvediag {

DbcError::DbcError(const std::string& file, int line, const std::string& problem)
    : std::runtime_error(file + ":" + std::to_string(line) + ": " + problem), line_(line) {}

const DbcMessage* Dbc::find_message(std::string_view name) const {
  for (const auto& m : messages)
    if (m.name == name) return &m;
  return nullptr;
}

const DbcMessage* Dbc::find_message(std::uint32_t id) const {
  for (const auto& m : messages)
    if (m.id == id) return &m;
  return nullptr;
}

namespace {

// A cursor over one line; every failure names what was expected.
class Cursor {
 public:
  Cursor(std::string_view s, const std::string& file, int line) : s_(s), file_(file), line_(line) {}

  void skip_space() {
    while (!s_.empty() && (s_.front() == ' ' || s_.front() == '\t' || s_.front() == '\r'))
      s_.remove_prefix(1);
  }
  bool at_end() {
    skip_space();
    return s_.empty();
  }
  bool accept(char c) {
    skip_space();
    if (!s_.empty() && s_.front() == c) {
      s_.remove_prefix(1);
      return true;
    }
    return false;
  }
  void expect(char c, const char* what) {
    if (!accept(c)) fail(std::string("expected '") + c + "' " + what);
  }
  std::string_view word() {
    skip_space();
    std::size_t n = 0;
    while (n < s_.size() && (std::isalnum(static_cast<unsigned char>(s_[n])) || s_[n] == '_')) ++n;
    const auto w = s_.substr(0, n);
    s_.remove_prefix(n);
    return w;
  }
  double number(const char* what) {
    skip_space();
    double v = 0;
    const char* b = s_.data();
    const char* e = b + s_.size();
    if (b != e && *b == '+') ++b;  // from_chars rejects a leading '+'
    const auto r = std::from_chars(b, e, v);
    if (r.ec != std::errc() || !std::isfinite(v))
      fail(std::string("expected a number for ") + what);
    s_.remove_prefix(static_cast<std::size_t>(r.ptr - s_.data()));
    return v;
  }
  std::uint64_t unsigned_int(const char* what) {
    skip_space();
    std::uint64_t v = 0;
    const auto r = std::from_chars(s_.data(), s_.data() + s_.size(), v);
    if (r.ec != std::errc()) fail(std::string("expected an unsigned integer for ") + what);
    s_.remove_prefix(static_cast<std::size_t>(r.ptr - s_.data()));
    return v;
  }
  std::string quoted(const char* what) {
    skip_space();
    if (s_.empty() || s_.front() != '"') fail(std::string("expected a quoted ") + what);
    const auto end = s_.find('"', 1);
    if (end == std::string_view::npos) fail(std::string("unterminated quoted ") + what);
    std::string q(s_.substr(1, end - 1));
    s_.remove_prefix(end + 1);
    return q;
  }
  char next_char() {
    skip_space();
    if (s_.empty()) return '\0';
    const char c = s_.front();
    s_.remove_prefix(1);
    return c;
  }
  [[noreturn]] void fail(const std::string& problem) const {
    throw DbcError(file_, line_,
                   problem +
                       "; the line should read like 'BO_ 291 VALVE1: 8 PLC' or ' SG_ OP : "
                       "0|16@1+ (0.01,0) [0|100] \"%\" RECORDER'");
  }

 private:
  std::string_view s_;
  const std::string& file_;
  int line_;
};

}  // namespace

Dbc parse_dbc(std::string_view text, const std::string& source_name) {
  Dbc dbc;
  int line_no = 0;
  while (!text.empty()) {
    const auto nl = text.find('\n');
    std::string_view line = text.substr(0, nl);
    text.remove_prefix(nl == std::string_view::npos ? text.size() : nl + 1);
    ++line_no;
    Cursor c(line, source_name, line_no);
    c.skip_space();
    const auto keyword = c.word();
    if (keyword == "BO_") {
      DbcMessage m;
      m.line = line_no;
      const std::uint64_t raw_id = c.unsigned_int("the message id");
      if (raw_id > 0xFFFFFFFFull) c.fail("message id out of range");
      m.extended = (raw_id & 0x80000000ull) != 0;  // DBC marks 29-bit ids with bit 31
      m.id = static_cast<std::uint32_t>(raw_id & 0x7FFFFFFFull);
      if (m.extended ? m.id > 0x1FFFFFFFu : m.id > 0x7FFu)
        c.fail("message id " + std::to_string(m.id) + " is too large");
      m.name = std::string(c.word());
      if (m.name.empty()) c.fail("expected the message name after the id");
      c.expect(':', "after the message name");
      const std::uint64_t dlc = c.unsigned_int("the message length");
      if (dlc > 64) c.fail("message length " + std::to_string(dlc) + " is above 64 bytes");
      m.dlc = static_cast<unsigned>(dlc);
      m.sender = std::string(c.word());
      for (const auto& other : dbc.messages)
        if (other.name == m.name)
          c.fail("message '" + m.name + "' is defined twice (first on line " +
                 std::to_string(other.line) + ")");
      dbc.messages.push_back(std::move(m));
    } else if (keyword == "SG_") {
      if (dbc.messages.empty()) c.fail("signal before any BO_ message line");
      DbcMessage& m = dbc.messages.back();
      DbcSignal s;
      s.line = line_no;
      s.name = std::string(c.word());
      if (s.name.empty()) c.fail("expected the signal name after SG_");
      const auto mux = c.word();  // "M" (multiplexor) or "m<N>" (multiplexed), or nothing
      if (!mux.empty()) s.multiplexed = mux.front() == 'm';
      c.expect(':', "after the signal name");
      const std::uint64_t start = c.unsigned_int("the start bit");
      c.expect('|', "between start bit and length");
      const std::uint64_t length = c.unsigned_int("the length");
      c.expect('@', "before the byte order");
      const char order = c.next_char();
      if (order != '0' && order != '1') c.fail("byte order must be @0 (Motorola) or @1 (Intel)");
      const char sign = c.next_char();
      if (sign != '+' && sign != '-') c.fail("signedness must be '+' or '-'");
      c.expect('(', "before factor,offset");
      s.signal.factor = c.number("the factor");
      c.expect(',', "between factor and offset");
      s.signal.offset = c.number("the offset");
      c.expect(')', "after factor,offset");
      c.expect('[', "before min|max");
      s.minimum = c.number("the minimum");
      c.expect('|', "between minimum and maximum");
      s.maximum = c.number("the maximum");
      c.expect(']', "after min|max");
      s.unit = c.quoted("unit");
      if (start > 511 || length > 64) c.fail("start bit or length out of range");
      s.signal.start_bit = static_cast<unsigned>(start);
      s.signal.length = static_cast<unsigned>(length);
      s.signal.motorola = order == '0';
      s.signal.is_signed = sign == '-';
      s.signal.frame_id = m.id;
      s.signal.extended = m.extended;
      if (const std::string bad = check_can_signal(s.signal, m.dlc); !bad.empty())
        c.fail("signal '" + s.name + "' of message '" + m.name + "': " + bad);
      for (const auto& other : m.signals)
        if (other.name == s.name) c.fail("signal '" + s.name + "' appears twice in " + m.name);
      m.signals.push_back(std::move(s));
    }
  }
  return dbc;
}

Dbc load_dbc_file(const std::string& path) {
  // Regular files only: a device such as /dev/zero would never end.
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec) ||
      std::filesystem::file_size(path, ec) > (64u << 20))
    throw DbcError(path, 0,
                   "not a readable DBC file (missing, not a regular file, or over 64 MB); "
                   "check the path (relative paths are taken from the site config's "
                   "directory)");
  std::ifstream f(path, std::ios::binary);
  if (!f)
    throw DbcError(path, 0,
                   "cannot open the DBC file; check the path (relative paths are "
                   "taken from the site config's directory)");
  std::stringstream ss;
  ss << f.rdbuf();
  return parse_dbc(ss.str(), path);
}

}  // namespace valvediag
