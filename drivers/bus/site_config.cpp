// Site configuration reader (toml++). Each table is read through a Table helper that knows its
// name and line, rejects unknown keys (a typo must not silently become a default) and turns every
// problem into a SiteConfigError at the right line.
#include "valvediag/drivers/site_config.hpp"

#include <toml++/toml.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>

#include "valvediag/drivers/dbc.hpp"
#include "valvediag/io/file_position.hpp"

namespace valvediag {

std::string to_string(BusKind k) {
  switch (k) {
    case BusKind::modbus_tcp:
      return "modbus-tcp";
    case BusKind::modbus_rtu:
      return "modbus-rtu";
    case BusKind::socketcan:
      return "socketcan";
    case BusKind::modbus_rtu_over_tcp:
      return "modbus-rtu-over-tcp";
  }
  return "?";
}
std::string to_string(RegisterType r) {
  return r == RegisterType::holding ? "holding" : "input";
}
std::string to_string(PointName p) {
  static const char* const names[] = {"op", "pv", "sp", "mv", "mode"};
  return names[static_cast<std::size_t>(p)];
}
std::string to_string(FaultKind k) {
  static const char* const names[] = {"delay",   "timeout", "exception", "drop",
                                      "restart", "garble",  "freeze"};
  return names[static_cast<std::size_t>(k)];
}
std::optional<FaultKind> parse_fault_kind(std::string_view s) {
  for (int i = 0; i <= static_cast<int>(FaultKind::freeze); ++i)
    if (to_string(static_cast<FaultKind>(i)) == s) return static_cast<FaultKind>(i);
  return std::nullopt;
}

std::string can_unix_path(const BusConfig& bus) {
  if (bus.kind != BusKind::socketcan || bus.interface.rfind("unix:", 0) != 0) return "";
  return bus.interface.substr(5);
}

const BusConfig* SiteConfig::find_bus(std::string_view name) const {
  for (const auto& b : buses)
    if (b.name == name) return &b;
  return nullptr;
}
const LoopConfigEntry* SiteConfig::find_loop(std::string_view name) const {
  for (const auto& l : loops)
    if (l.name == name) return &l;
  return nullptr;
}

SiteConfigError::SiteConfigError(std::string file, int line, int column, std::string key,
                                 std::string problem)
    : std::runtime_error(file_position_message(file, line, column, key, problem)),
      file_(std::move(file)),
      line_(line),
      key_(std::move(key)) {}

std::optional<double> parse_duration(std::string_view s) {
  while (!s.empty() && s.front() == ' ') s.remove_prefix(1);
  while (!s.empty() && s.back() == ' ') s.remove_suffix(1);
  if (s.empty()) return std::nullopt;
  double unit = 1.0;
  std::string_view num = s;
  auto ends = [&](std::string_view suf) {
    return s.size() > suf.size() && s.substr(s.size() - suf.size()) == suf;
  };
  if (ends("ms")) {
    unit = 1e-3;
    num = s.substr(0, s.size() - 2);
  } else if (ends("us")) {
    unit = 1e-6;
    num = s.substr(0, s.size() - 2);
  } else if (ends("s")) {
    num = s.substr(0, s.size() - 1);
  } else if (ends("m")) {
    unit = 60.0;
    num = s.substr(0, s.size() - 1);
  } else if (ends("h")) {
    unit = 3600.0;
    num = s.substr(0, s.size() - 1);
  }
  if (num.empty() || num.front() == '+' || num.front() == '-') return std::nullopt;
  for (char c : num)
    if (!(std::isdigit(static_cast<unsigned char>(c)) || c == '.')) return std::nullopt;
  try {
    std::size_t pos = 0;
    const double v = std::stod(std::string(num), &pos);
    if (pos != num.size() || !std::isfinite(v)) return std::nullopt;
    return v * unit;
  } catch (const std::exception&) {
    return std::nullopt;
  }
}

namespace {

const char* kind_of(const toml::node& n) {
  switch (n.type()) {
    case toml::node_type::string:
      return "a string";
    case toml::node_type::integer:
      return "an integer";
    case toml::node_type::floating_point:
      return "a number";
    case toml::node_type::boolean:
      return "a boolean";
    case toml::node_type::array:
      return "an array";
    case toml::node_type::table:
      return "a table";
    default:
      return "a date/time";
  }
}

std::string seconds_text(double s) {
  char b[32];
  std::snprintf(b, sizeof b, "%g s", s);
  return b;
}

// A key as it appears in messages: control characters (a NUL in a quoted key) made visible.
std::string visible(std::string_view s) {
  std::string out(s);
  for (char& c : out)
    if (static_cast<unsigned char>(c) < 0x20 || c == 0x7f) c = '?';
  return out;
}

class Table {
 public:
  Table(const std::string& file, const toml::table& t, std::string name)
      : file_(file), t_(t), name_(std::move(name)) {}

  const std::string& name() const { return name_; }
  int line() const { return static_cast<int>(t_.source().begin.line); }
  std::string path(std::string_view key) const { return name_ + "." + std::string(key); }
  bool has(std::string_view key) const { return t_.get(key) != nullptr; }

  [[noreturn]] void fail(std::string_view key, const std::string& problem) const {
    const toml::node* n = t_.get(key);
    const auto& src = n ? n->source() : t_.source();
    throw SiteConfigError(file_, static_cast<int>(src.begin.line),
                          static_cast<int>(src.begin.column), path(key), problem);
  }
  [[noreturn]] void fail_table(const std::string& problem) const {
    throw SiteConfigError(file_, line(), static_cast<int>(t_.source().begin.column), name_,
                          problem);
  }

  void allow_only(std::initializer_list<std::string_view> allowed) const {
    for (auto&& [key, node] : t_) {
      bool ok = false;
      for (auto a : allowed) ok = ok || a == key.str();
      if (ok) continue;
      std::string list;
      for (auto a : allowed) list += (list.empty() ? "" : ", ") + std::string(a);
      throw SiteConfigError(file_, static_cast<int>(key.source().begin.line),
                            static_cast<int>(key.source().begin.column), path(visible(key.str())),
                            "unknown key; remove it or use one of: " + list);
    }
  }

  std::string string(std::string_view key, const std::string& def, bool required = false) const {
    const toml::node* n = t_.get(key);
    if (!n) {
      if (required)
        fail_table("missing key '" + std::string(key) + "'; add " + std::string(key) +
                   " = \"...\"");
      return def;
    }
    if (!n->is_string()) fail(key, std::string("must be a string, got ") + kind_of(*n));
    const std::string& v = n->as_string()->get();
    // A NUL would cut the name or path short wherever it reaches C (file names, SQLite, logs).
    if (v.find('\0') != std::string::npos) fail(key, "holds a NUL character (\\u0000); remove it");
    return v;
  }
  double number(std::string_view key, double def) const {
    const toml::node* n = t_.get(key);
    if (!n) return def;
    double v = 0;
    if (n->is_integer())
      v = static_cast<double>(n->as_integer()->get());
    else if (n->is_floating_point())
      v = n->as_floating_point()->get();
    else
      fail(key, std::string("must be a number, got ") + kind_of(*n));
    if (!std::isfinite(v)) fail(key, "must be a finite number");
    return v;
  }
  std::int64_t integer(std::string_view key, std::int64_t def, std::int64_t lo, std::int64_t hi,
                       bool required = false) const {
    const toml::node* n = t_.get(key);
    if (!n) {
      if (required) fail_table("missing key '" + std::string(key) + "'");
      return def;
    }
    if (!n->is_integer()) fail(key, std::string("must be an integer, got ") + kind_of(*n));
    const std::int64_t v = n->as_integer()->get();
    if (v < lo || v > hi)
      fail(key,
           std::to_string(v) + " is outside " + std::to_string(lo) + ".." + std::to_string(hi));
    return v;
  }
  bool boolean(std::string_view key, bool def) const {
    const toml::node* n = t_.get(key);
    if (!n) return def;
    if (!n->is_boolean()) fail(key, std::string("must be true or false, got ") + kind_of(*n));
    return n->as_boolean()->get();
  }
  // A duration: "500ms", "2s", "10m" or a number of seconds, within [lo, hi] seconds.
  double duration(std::string_view key, double def, double lo, double hi,
                  const char* required_example = nullptr) const {
    const toml::node* n = t_.get(key);
    if (!n && required_example)
      fail_table("missing key '" + std::string(key) + "'; add " + std::string(key) + " = " +
                 required_example);
    if (!n) return def;
    std::optional<double> v;
    if (n->is_string())
      v = parse_duration(n->as_string()->get());
    else if (n->is_integer())
      v = static_cast<double>(n->as_integer()->get());
    else if (n->is_floating_point())
      v = n->as_floating_point()->get();
    if (!v || !std::isfinite(*v))
      fail(key, "must be a duration like \"500ms\", \"2s\", \"10m\" or a number of seconds");
    if (*v < lo || *v > hi)
      fail(key, "duration " + std::to_string(*v) + " s is outside " + std::to_string(lo) + ".." +
                    std::to_string(hi) + " s");
    return *v;
  }
  // stale_after: a duration longer than `period_s`, or "off" (0).
  double stale_after(double def, double period_s) const {
    const toml::node* n = t_.get("stale_after");
    if (!n) return def;
    if (n->is_string() && n->as_string()->get() == "off") return 0.0;
    const double v = duration("stale_after", 0.0, 0.0, 1e7);
    if (!(v > period_s))
      fail("stale_after", "must be longer than the sample period (" + seconds_text(period_s) +
                              "), else a value read twice in a row is flagged; give e.g. "
                              "\"30s\", or \"off\"");
    return v;
  }
  const toml::node* get(std::string_view key) const { return t_.get(key); }

 private:
  const std::string& file_;
  const toml::table& t_;
  std::string name_;
};

std::string resolve(const std::string& base_dir, const std::string& p) {
  if (p.empty() || base_dir.empty() || std::filesystem::path(p).is_absolute()) return p;
  return (std::filesystem::path(base_dir) / p).lexically_normal().string();
}

// Equal but for ASCII case (names are ASCII: valid_name).
bool same_but_case(std::string_view a, std::string_view b) {
  if (a.size() != b.size() || a == b) return false;
  for (std::size_t i = 0; i < a.size(); ++i)
    if (std::tolower(static_cast<unsigned char>(a[i])) !=
        std::tolower(static_cast<unsigned char>(b[i])))
      return false;
  return true;
}

bool valid_name(const std::string& s) {
  if (s.empty() || s.size() > 64) return false;
  for (char c : s)
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-' || c == '.'))
      return false;
  return true;
}

// The bus's protocol, from `protocol` or from Telegraf's `transmission_mode` (with the
// controller's scheme for its "auto"), so that a bus pasted from Telegraf's Modbus input reads as
// is; when both are given they must agree.
BusKind read_protocol(const Table& t) {
  const char* const protocols = "modbus-tcp, modbus-rtu, modbus-rtu-over-tcp or socketcan";
  std::optional<BusKind> kind;
  if (t.has("protocol") || !t.has("transmission_mode")) {
    const std::string protocol = t.string("protocol", "", true);
    for (BusKind k : {BusKind::modbus_tcp, BusKind::modbus_rtu, BusKind::modbus_rtu_over_tcp,
                      BusKind::socketcan})
      if (protocol == to_string(k)) kind = k;
    if (!kind) t.fail("protocol", "'" + protocol + "' is not a protocol; use " + protocols);
  }
  if (!t.has("transmission_mode")) return *kind;
  if (kind == BusKind::socketcan)
    t.fail("transmission_mode", "only applies to Modbus buses; remove it");
  const std::string mode = t.string("transmission_mode", "");
  std::optional<BusKind> from_mode;
  if (mode == "TCP")
    from_mode = BusKind::modbus_tcp;
  else if (mode == "RTU")
    from_mode = BusKind::modbus_rtu;
  else if (mode == "RTUoverTCP")
    from_mode = BusKind::modbus_rtu_over_tcp;
  else if (mode == "auto")  // Telegraf's default: by the controller's scheme
    from_mode = t.string("controller", "").rfind("file://", 0) == 0 ? BusKind::modbus_rtu
                                                                    : BusKind::modbus_tcp;
  else if (mode == "ASCII" || mode == "ASCIIoverTCP")
    t.fail("transmission_mode",
           "Modbus ASCII is not supported; use \"TCP\", \"RTUoverTCP\" or \"RTU\"");
  else
    t.fail("transmission_mode", "'" + mode +
                                    "' must be \"TCP\", \"RTUoverTCP\", \"RTU\" or \"auto\" "
                                    "(Telegraf's spellings, case as shown), or remove it and give "
                                    "protocol = \"...\"");
  if (kind && *kind != *from_mode)
    t.fail("transmission_mode", "\"" + mode + "\" means protocol \"" + to_string(*from_mode) +
                                    "\", but protocol is \"" + to_string(*kind) +
                                    "\"; keep one of the two");
  return *from_mode;
}

BusConfig read_bus(const Table& t, const std::string& base_dir) {
  t.allow_only({"name", "protocol", "transmission_mode", "controller", "slave_id", "timeout",
                "retries", "pause_between_requests", "reconnect_max", "baud_rate", "parity",
                "data_bits", "stop_bits", "interface", "dbc"});
  BusConfig b;
  b.line = t.line();
  b.name = t.string("name", "", true);
  if (!valid_name(b.name))
    t.fail("name", "'" + b.name + "' is not a valid name; use letters, digits, '_', '-', '.'");
  b.kind = read_protocol(t);
  const bool modbus = b.kind != BusKind::socketcan;
  const bool over_tcp = b.kind == BusKind::modbus_tcp || b.kind == BusKind::modbus_rtu_over_tcp;
  auto only_for = [&](std::initializer_list<std::string_view> keys, bool ok, const char* what) {
    for (auto k : keys)
      if (!ok && t.has(k)) t.fail(k, std::string("only applies to ") + what + " buses; remove it");
  };
  only_for(
      {"controller", "slave_id", "timeout", "retries", "pause_between_requests", "reconnect_max"},
      modbus, "Modbus");
  for (auto k : {"baud_rate", "parity", "data_bits", "stop_bits"})
    if (b.kind == BusKind::modbus_rtu_over_tcp && t.has(k))
      t.fail(k, "does not apply to RTU over TCP: the gateway sets its serial line; remove it");
  only_for({"baud_rate", "parity", "data_bits", "stop_bits"}, b.kind == BusKind::modbus_rtu,
           "Modbus RTU");
  only_for({"interface", "dbc"}, !modbus, "socketcan");
  if (modbus) {
    const std::string ctl = t.string("controller", "", true);
    if (over_tcp) {
      // tcp://host:port as in Telegraf; only loopback is ever contacted by the tests.
      if (ctl.rfind("tcp://", 0) != 0)
        t.fail("controller",
               "'" + ctl + "' must look like \"tcp://192.168.0.10:502\"" +
                   (b.kind == BusKind::modbus_rtu_over_tcp
                        ? " (RTU over TCP goes to the gateway's TCP port; a serial line on this "
                          "machine is protocol = \"modbus-rtu\")"
                        : ""));
      const std::string hp = ctl.substr(6);
      const auto colon = hp.rfind(':');
      b.host = colon == std::string::npos ? hp : hp.substr(0, colon);
      if (b.host.empty()) t.fail("controller", "no host in '" + ctl + "'");
      if (colon != std::string::npos) {
        const std::string port = hp.substr(colon + 1);
        int p = -1;
        try {
          std::size_t pos = 0;
          p = std::stoi(port, &pos);
          if (pos != port.size()) p = -1;
        } catch (const std::exception&) {
        }
        // Port 0 is no server's port: a connect to it can only fail, on every poll.
        if (p < 1 || p > 65535)
          t.fail("controller",
                 "port '" + port + "' is not 1..65535 (" +
                     (b.kind == BusKind::modbus_tcp
                          ? "Modbus TCP is usually 502; for a free port of the simulated PLC "
                            "use sim-plc --port 0)"
                          : "the port the gateway serves its serial line on, e.g. 4001)"));
        b.port = p;
      }
    } else {
      if (ctl.rfind("file://", 0) != 0)
        t.fail("controller",
               "'" + ctl + "' must look like \"file:///dev/ttyUSB0\"" +
                   (ctl.rfind("tcp://", 0) == 0 ? " (for a gateway on the network write protocol = "
                                                  "\"modbus-rtu-over-tcp\" or \"modbus-tcp\")"
                                                : ""));
      b.device = ctl.substr(7);
      if (b.device.empty()) t.fail("controller", "no serial device in '" + ctl + "'");
      b.baud_rate = static_cast<int>(t.integer("baud_rate", 19200, 50, 4000000));
      const std::string parity = t.string("parity", "N");
      if (parity != "N" && parity != "E" && parity != "O")
        t.fail("parity", "'" + parity + "' must be \"N\", \"E\" or \"O\"");
      b.parity = parity[0];
      b.data_bits = static_cast<int>(t.integer("data_bits", 8, 5, 8));
      b.stop_bits = static_cast<int>(t.integer("stop_bits", 1, 1, 2));
    }
    b.slave_id = static_cast<int>(t.integer("slave_id", 1, 0, 247));
    b.timeout_s = t.duration("timeout", 0.5, 0.001, 60.0);
    b.retries = static_cast<int>(t.integer("retries", 1, 0, 10));
    b.pause_s = t.duration("pause_between_requests", 0.0, 0.0, 10.0);
    b.reconnect_max_s = t.duration("reconnect_max", 1.0, 0.01, 600.0);
  } else {
    b.interface = t.string("interface", "", true);
    if (b.interface.rfind("unix:", 0) == 0) {
      // The simulated PLC's frame socket: a path, relative to this file like dbc.
      const std::string path = resolve(base_dir, b.interface.substr(5));
      if (path.empty())
        t.fail("interface", "no socket path in 'unix:'; write interface = \"unix:/tmp/can0.sock\"");
      if (path.size() > 107)  // sockaddr_un::sun_path holds 108 bytes with the terminator
        t.fail("interface", "socket path '" + path + "' is " + std::to_string(path.size()) +
                                " bytes; a Unix socket path has at most 107: choose a shorter one");
      b.interface = "unix:" + path;
    } else if (b.interface.empty() || b.interface.size() > 15) {
      t.fail("interface", "'" + b.interface +
                              "' is not a CAN interface name (1..15 characters, e.g. \"can0\"), "
                              "nor \"unix:PATH\" (the simulated PLC's socket)");
    }
    b.dbc = resolve(base_dir, t.string("dbc", ""));
  }
  return b;
}

PointConfig read_modbus_point(const Table& t) {
  t.allow_only(
      {"register", "address", "type", "data_type", "byte_order", "scale", "offset", "stale_after"});
  PointConfig p;
  p.present = true;
  p.line = t.line();
  const std::string reg = t.string("register", "holding");
  if (reg == "holding")
    p.reg = RegisterType::holding;
  else if (reg == "input")
    p.reg = RegisterType::input;
  else
    t.fail("register", "'" + reg + "' must be \"holding\" or \"input\" (coils are not values)");
  // `data_type` is Telegraf's name for `type`: a point pasted from its Modbus input reads as is.
  if (t.has("type") && t.has("data_type"))
    t.fail("data_type", "and `type` both give the point's type: keep one");
  const char* type_key = t.has("data_type") ? "data_type" : "type";
  const std::string type = t.string(type_key, "", true);
  const auto dt = parse_data_type(type);
  if (!dt)
    t.fail(
        type_key,
        "'" + type + "' must be INT16, UINT16, INT32, UINT32, FLOAT32, INT64, UINT64 or FLOAT64");
  p.type = *dt;
  p.address = static_cast<int>(
      t.integer("address", 0, 0, 65536 - static_cast<std::int64_t>(register_count(p.type)), true));
  const std::string order = t.string("byte_order", "ABCD");
  const auto bo = parse_byte_order(order);
  if (!bo)
    t.fail("byte_order", "'" + order +
                             "' must be ABCD, CDAB, BADC or DCBA (or AB, BA; or for 64-bit types "
                             "ABCDEFGH, GHEFCDAB, BADCFEHG, HGFEDCBA)");
  p.order = *bo;
  // The order's length must fit the type: a 32-bit order on one register (or the reverse)
  // usually means the type is wrong, and one register of a 32-bit value is a wrong number.
  // A 64-bit value also takes a 4-letter order (its registers in order or reversed, each one's
  // bytes in order or swapped), as Telegraf applies one byte_order to every width.
  if (t.has("byte_order")) {
    const std::size_t regs = register_count(p.type);
    const std::string want =
        to_string(ByteOrder::abcd, p.type) + ", " + to_string(ByteOrder::cdab, p.type) + ", " +
        to_string(ByteOrder::badc, p.type) + " or " + to_string(ByteOrder::dcba, p.type);
    const std::string what =
        "'" + order + "' orders the " + std::to_string(order.size()) + " bytes of " +
        (order.size() == 2 ? std::string("one register")
                           : "a " + std::to_string(order.size() * 8) + "-bit value") +
        ", but " + type;
    if (regs == 1 && order.size() != 2)
      t.fail("byte_order", what + " is one register: write \"AB\" or \"BA\", or give the " +
                               std::to_string(order.size() * 8) + "-bit type the registers hold");
    if (regs == 2 && order.size() != 4) t.fail("byte_order", what + " spans two: write " + want);
    if (regs == 4 && order.size() == 2)
      t.fail("byte_order", what + " spans four: write " + want + " (or ABCD, CDAB, BADC, DCBA)");
  }
  p.scale = t.number("scale", 1.0);
  if (p.scale == 0.0) t.fail("scale", "must not be 0");
  p.offset = t.number("offset", 0.0);
  return p;
}

PointConfig read_can_point(const Table& t, const Dbc* dbc, const BusConfig& bus) {
  t.allow_only({"message", "signal", "frame_id", "extended", "start_bit", "length", "byte_order",
                "signed", "factor", "offset", "stale_after"});
  PointConfig p;
  p.present = true;
  p.line = t.line();
  if (t.has("message") || t.has("signal")) {
    p.message = t.string("message", "", true);
    p.signal = t.string("signal", "", true);
    for (auto k : {"frame_id", "start_bit", "length", "byte_order", "signed", "factor", "offset"})
      if (t.has(k)) t.fail(k, "give either message/signal (from the DBC) or the signal's fields");
    if (!dbc)
      t.fail("message", "bus '" + bus.name + "' has no dbc file; add dbc = \"file.dbc\" to it");
    const DbcMessage* m = dbc->find_message(p.message);
    if (!m) t.fail("message", "no message '" + p.message + "' in " + bus.dbc);
    for (const auto& s : m->signals)
      if (s.name == p.signal) {
        if (s.multiplexed)
          t.fail("signal",
                 "'" + p.signal + "' is multiplexed; multiplexed signals are not supported");
        p.can = s.signal;
        return p;
      }
    t.fail("signal", "no signal '" + p.signal + "' in message '" + p.message + "' of " + bus.dbc);
  }
  p.can.frame_id = static_cast<std::uint32_t>(t.integer("frame_id", 0, 0, 0x1FFFFFFF, true));
  p.can.extended = t.boolean("extended", p.can.frame_id > 0x7FF);
  p.can.start_bit = static_cast<unsigned>(t.integer("start_bit", 0, 0, 63, true));
  p.can.length = static_cast<unsigned>(t.integer("length", 16, 1, 64, true));
  const std::string order = t.string("byte_order", "intel");
  if (order != "intel" && order != "motorola")
    t.fail("byte_order", "'" + order + "' must be \"intel\" (DBC @1) or \"motorola\" (DBC @0)");
  p.can.motorola = order == "motorola";
  p.can.is_signed = t.boolean("signed", false);
  p.can.factor = t.number("factor", 1.0);
  p.can.offset = t.number("offset", 0.0);
  if (const std::string bad = check_can_signal(p.can); !bad.empty()) t.fail_table(bad);
  return p;
}

LoopConfigEntry read_loop(const Table& t, const SiteConfig& site,
                          const std::vector<std::optional<Dbc>>& dbcs,
                          const std::string& base_dir) {
  t.allow_only({"name", "bus", "sample_period", "op_range", "op", "pv", "sp", "mv", "mode",
                "simulate", "seed", "stale_after"});
  LoopConfigEntry l;
  l.line = t.line();
  l.name = t.string("name", "", true);
  if (!valid_name(l.name))
    t.fail("name", "'" + l.name + "' is not a valid loop name; use letters, digits, '_', '-', '.'");
  l.bus = t.string("bus", "", true);
  const BusConfig* bus = site.find_bus(l.bus);
  if (!bus) {
    std::string names;
    for (const auto& b : site.buses) names += (names.empty() ? "" : ", ") + b.name;
    t.fail("bus", "no bus named '" + l.bus + "'; define it in a [[bus]] table (known: " +
                      (names.empty() ? "none" : names) + ")");
  }
  // Required: the polling period sets every time stamp of the recording, so a forgotten line
  // must not quietly become 1 s. All shipped configs give it.
  l.sample_period_s = t.duration("sample_period", 1.0, 0.001, 3600.0,
                                 "\"1s\" (how often the recorder polls this loop)");
  if (const toml::node* r = t.get("op_range")) {
    const toml::array* a = r->as_array();
    if (!a || a->size() != 2 || !a->get(0)->is_number() || !a->get(1)->is_number())
      t.fail("op_range", "must be [min, max] in %, e.g. [0, 100]");
    l.op_min = a->get(0)->value<double>().value_or(0.0);
    l.op_max = a->get(1)->value<double>().value_or(0.0);
    if (!(l.op_min < l.op_max)) t.fail("op_range", "min must be below max");
  }
  l.simulate = t.string("simulate", "");
  if (!l.simulate.empty() && l.simulate.find(".toml") != std::string::npos)
    l.simulate = resolve(base_dir, l.simulate);
  l.seed = static_cast<std::uint64_t>(t.integer("seed", 1, 0, INT64_MAX));
  l.stale_after_s = t.stale_after(0.0, l.sample_period_s);
  const std::size_t bus_index = static_cast<std::size_t>(bus - site.buses.data());
  for (std::size_t i = 0; i < kPointCount; ++i) {
    const std::string key = to_string(static_cast<PointName>(i));
    const toml::node* n = t.get(key);
    if (!n) {
      if (i <= 1)
        t.fail_table("missing " + key + "; every loop needs op and pv, e.g. " + key +
                     " = { register = \"holding\", address = 0, type = \"FLOAT32\" }");
      continue;
    }
    if (!n->is_table())
      t.fail(key,
             "must be a table like { register = \"holding\", address = 0, type = \"FLOAT32\" }");
    const Table pt(site.file, *n->as_table(), t.name() + "." + key);
    l.points[i] = bus->kind == BusKind::socketcan
                      ? read_can_point(pt, dbcs[bus_index] ? &*dbcs[bus_index] : nullptr, *bus)
                      : read_modbus_point(pt);
    // The loop's stale_after covers the values a running plant keeps moving (op, pv, mv); a set
    // point or a mode is constant for hours on purpose, so it is checked only when asked for.
    const bool moving = i <= 1 || static_cast<PointName>(i) == PointName::mv;
    l.points[i].stale_after_s = pt.stale_after(moving ? l.stale_after_s : 0.0, l.sample_period_s);
  }
  // Overlapping registers are a typo (two values cannot share a register).
  if (bus->kind != BusKind::socketcan)
    for (std::size_t i = 0; i < kPointCount; ++i)
      for (std::size_t j = i + 1; j < kPointCount; ++j) {
        const auto &a = l.points[i], &b = l.points[j];
        if (!a.present || !b.present || a.reg != b.reg) continue;
        const int a_end = a.address + static_cast<int>(register_count(a.type));
        const int b_end = b.address + static_cast<int>(register_count(b.type));
        if (a.address < b_end && b.address < a_end)
          t.fail(to_string(static_cast<PointName>(j)),
                 "overlaps " + to_string(static_cast<PointName>(i)) + " at " + to_string(a.reg) +
                     " register " + std::to_string(std::max(a.address, b.address)) +
                     "; give each value its own registers");
      }
  return l;
}

FaultConfig read_fault(const Table& t) {
  t.allow_only({"kind", "register", "address", "start", "duration", "every", "delay",
                "exception_code", "down"});
  FaultConfig f;
  f.line = t.line();
  const std::string kind = t.string("kind", "", true);
  const auto k = parse_fault_kind(kind);
  if (!k)
    t.fail("kind",
           "'" + kind + "' must be delay, timeout, exception, drop, restart, garble or freeze");
  f.kind = *k;
  if (t.has("address")) f.address = static_cast<int>(t.integer("address", 0, 0, 65535));
  if (t.has("register")) {
    const std::string reg = t.string("register", "");
    if (reg != "holding" && reg != "input") t.fail("register", "must be \"holding\" or \"input\"");
    f.reg = reg == "holding" ? RegisterType::holding : RegisterType::input;
  }
  f.start_s = t.duration("start", 0.0, 0.0, 1e9);
  f.duration_s = t.duration("duration", 1e300, 0.0, 1e300);
  f.every = static_cast<int>(t.integer("every", 1, 1, 1000000));
  f.delay_s = t.duration("delay", 0.2, 0.0, 60.0);
  f.exception_code = static_cast<int>(t.integer("exception_code", 4, 1, 11));
  f.down_s = t.duration("down", 1.0, 0.0, 600.0);
  return f;
}

// The array of tables `key`, each as a Table named "key[i]".
template <class F>
void each_table(const std::string& file, const toml::table& root, const char* key, F&& f) {
  const toml::node* n = root.get(key);
  if (!n) return;
  const toml::array* a = n->as_array();
  if (!a)
    throw SiteConfigError(file, static_cast<int>(n->source().begin.line), 0, key,
                          std::string("must be an array of tables: write [[") + key + "]]");
  for (std::size_t i = 0; i < a->size(); ++i) {
    const toml::node* e = a->get(i);
    if (!e->is_table())
      throw SiteConfigError(file, static_cast<int>(e->source().begin.line), 0, key,
                            std::string("each entry must be a table: write [[") + key + "]]");
    f(Table(file, *e->as_table(), std::string(key) + "[" + std::to_string(i) + "]"));
  }
}

}  // namespace

SiteConfig parse_site_config(std::string_view text, const std::string& source_name,
                             const std::string& base_dir) {
  SiteConfig site;
  site.file = source_name;
  toml::table root;
  try {
    root = toml::parse(text, source_name);
  } catch (const toml::parse_error& e) {
    throw SiteConfigError(source_name, static_cast<int>(e.source().begin.line),
                          static_cast<int>(e.source().begin.column), "",
                          std::string(e.description()) + "; fix the TOML syntax");
  }
  for (auto&& [key, node] : root) {
    const auto k = key.str();
    if (k != "bus" && k != "loop" && k != "fault")
      throw SiteConfigError(
          source_name, static_cast<int>(key.source().begin.line),
          static_cast<int>(key.source().begin.column), visible(k),
          "unknown key; a site file holds [[bus]], [[loop]] and [[fault]] tables");
  }
  std::vector<std::optional<Dbc>> dbcs;
  each_table(source_name, root, "bus", [&](const Table& t) {
    BusConfig b = read_bus(t, base_dir);
    if (site.find_bus(b.name))
      t.fail("name", "bus '" + b.name + "' is defined twice; give each bus its own name");
    for (const auto& o : site.buses)
      if (same_but_case(o.name, b.name))
        t.fail("name", "bus '" + b.name + "' differs from bus '" + o.name + "' (line " +
                           std::to_string(o.line) +
                           ") only in upper and lower case; give the buses distinct names");
    std::optional<Dbc> dbc;
    if (!b.dbc.empty()) {
      try {
        dbc = load_dbc_file(b.dbc);
      } catch (const DbcError& e) {
        t.fail("dbc", e.what());
      }
    }
    site.buses.push_back(std::move(b));
    dbcs.push_back(std::move(dbc));
  });
  each_table(source_name, root, "loop", [&](const Table& t) {
    LoopConfigEntry l = read_loop(t, site, dbcs, base_dir);
    if (site.find_loop(l.name))
      t.fail("name", "loop '" + l.name + "' is defined twice; loop names must be unique");
    // FIC101 and fic101 would share a file name on a case-insensitive disk and be mistaken
    // for each other by anyone reading the results.
    for (const auto& o : site.loops)
      if (same_but_case(o.name, l.name))
        t.fail("name", "loop '" + l.name + "' differs from loop '" + o.name + "' (line " +
                           std::to_string(o.line) +
                           ") only in upper and lower case; give the loops distinct names");
    site.loops.push_back(std::move(l));
  });
  each_table(source_name, root, "fault",
             [&](const Table& t) { site.faults.push_back(read_fault(t)); });
  if (site.loops.empty())
    throw SiteConfigError(
        source_name, 0, 0, "",
        "no [[loop]] table; a site needs at least one loop (see configs/site.toml)");
  return site;
}

SiteConfig load_site_config(const std::string& path) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec))
    throw SiteConfigError(path, 0, 0, "", "not a readable file; check the path");
  std::ifstream f(path, std::ios::binary);
  if (!f) throw SiteConfigError(path, 0, 0, "", "cannot open the site config; check the path");
  std::stringstream ss;
  ss << f.rdbuf();
  return parse_site_config(ss.str(), path, std::filesystem::path(path).parent_path().string());
}

}  // namespace valvediag
