// Scenario files: TOML read with toml++ (keys documented in configs/scenarios/paper-ex1.toml).
// Every error names the file, the line and column toml++ recorded, the key, and what to change.
#include <toml++/toml.h>

#include <charconv>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <sstream>
#include <string>
#include <vector>

#include "valvediag/io/file_position.hpp"
#include "valvediag/sim/scenarios.hpp"

namespace valvediag {

ScenarioFileError::ScenarioFileError(std::string file, int line, int column, std::string key,
                                     std::string problem)
    : std::runtime_error(file_position_message(file, line, column, key, problem)),
      file_(std::move(file)),
      line_(line),
      column_(column),
      key_(std::move(key)) {}

namespace {

const char* type_name(const toml::node& n) {
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
    case toml::node_type::date:
    case toml::node_type::time:
    case toml::node_type::date_time:
      return "a date/time";
    case toml::node_type::none:
      break;
  }
  return "nothing";
}

// One TOML table being read: knows its name for messages ("controller", "valve[2]", "" for the
// top level) and turns every problem into a ScenarioFileError at the right line.
class Section {
 public:
  Section(const std::string& file, const toml::table& table, std::string name)
      : file_(file), table_(table), name_(std::move(name)) {}

  std::string path(std::string_view key) const {
    return name_.empty() ? std::string(key) : name_ + "." + std::string(key);
  }
  const std::string& name() const { return name_; }
  const toml::table& table() const { return table_; }

  [[noreturn]] void fail_at(const toml::source_region& where, const std::string& key,
                            const std::string& problem) const {
    throw ScenarioFileError(file_, static_cast<int>(where.begin.line),
                            static_cast<int>(where.begin.column), key, problem);
  }
  // At the key if it is present, else at the table's header.
  [[noreturn]] void fail(std::string_view key, const std::string& problem) const {
    const toml::node* n = table_.get(key);
    fail_at(n ? n->source() : table_.source(), path(key), problem);
  }
  [[noreturn]] void fail_table(const std::string& problem) const {
    fail_at(table_.source(), name_, problem);
  }

  // Rejects keys outside `allowed` (typos would otherwise be silently ignored).
  void allow_only(const std::vector<std::string>& allowed) const {
    for (auto&& [key, node] : table_) {
      bool ok = false;
      for (const auto& a : allowed) ok = ok || a == key.str();
      if (!ok) {
        std::string list;
        for (const auto& a : allowed) list += (list.empty() ? "" : ", ") + a;
        fail_at(key.source(), path(key.str()),
                "unknown key" + std::string(name_.empty() ? "" : " in " + where()) +
                    "; remove it or use one of: " + list);
      }
    }
  }

  bool has(std::string_view key) const { return table_.get(key) != nullptr; }

  double number(std::string_view key) const {
    const toml::node* n = table_.get(key);
    if (!n) fail(key, "missing; add `" + std::string(key) + " = <number>` to " + where());
    return as_number(key, *n);
  }
  double number(std::string_view key, double fallback) const {
    const toml::node* n = table_.get(key);
    return n ? as_number(key, *n) : fallback;
  }
  std::int64_t integer(std::string_view key, std::int64_t fallback) const {
    const toml::node* n = table_.get(key);
    if (!n) return fallback;
    if (!n->is_integer()) {
      fail(key, std::string("expected an integer, found ") + type_name(*n) + "; write e.g. `" +
                    std::string(key) + " = 3000`");
    }
    return *n->value<std::int64_t>();
  }
  std::string string(std::string_view key) const {
    const toml::node* n = table_.get(key);
    if (!n) fail(key, "missing; add `" + std::string(key) + " = \"...\"` to " + where());
    return as_string(key, *n);
  }
  std::string string(std::string_view key, const std::string& fallback) const {
    const toml::node* n = table_.get(key);
    return n ? as_string(key, *n) : fallback;
  }
  std::vector<double> numbers(std::string_view key) const {
    const toml::node* n = table_.get(key);
    if (!n) fail(key, "missing; add `" + std::string(key) + " = [<number>, ...]` to " + where());
    const toml::array* a = n->as_array();
    if (!a) {
      fail(key, std::string("expected an array of numbers, found ") + type_name(*n) +
                    "; write e.g. `" + std::string(key) + " = [1.0, 2.0]`");
    }
    std::vector<double> v;
    for (const toml::node& e : *a) {
      if (!e.is_number()) {
        fail_at(e.source(), path(key),
                std::string("array element is ") + type_name(e) + ", expected a number");
      }
      v.push_back(*e.value<double>());
    }
    return v;
  }
  const toml::table& subtable(std::string_view key) const {
    const toml::node* n = table_.get(key);
    if (!n) fail(key, "missing; add a [" + std::string(key) + "] table");
    if (!n->is_table()) {
      fail(key, std::string("expected a table, found ") + type_name(*n) + "; write it as [" +
                    std::string(key) + "]");
    }
    return *n->as_table();
  }
  // [[key]] entries; none when the key is absent.
  std::vector<const toml::table*> table_array(std::string_view key) const {
    std::vector<const toml::table*> v;
    const toml::node* n = table_.get(key);
    if (!n) return v;
    const toml::array* a = n->as_array();
    if (!a || !a->is_array_of_tables()) {
      fail(key, std::string("expected [[") + std::string(key) + "]] tables, found " +
                    type_name(*n) + "; write each entry as a [[" + std::string(key) + "]] table");
    }
    for (const toml::node& e : *a) v.push_back(e.as_table());
    return v;
  }

 private:
  std::string where() const { return name_.empty() ? "the top level" : "[" + name_ + "]"; }
  double as_number(std::string_view key, const toml::node& n) const {
    if (!n.is_number()) {
      fail(key, std::string("expected a number, found ") + type_name(n) + "; write e.g. `" +
                    std::string(key) + " = 1.5`");
    }
    return *n.value<double>();
  }
  std::string as_string(std::string_view key, const toml::node& n) const {
    if (!n.is_string()) {
      fail(key, std::string("expected a string, found ") + type_name(n) + "; write e.g. `" +
                    std::string(key) + " = \"...\"`");
    }
    return *n.value<std::string>();
  }

  const std::string& file_;
  const toml::table& table_;
  std::string name_;
};

PiSettings read_controller(const Section& s, double Ts) {
  s.allow_only({"kc", "ti", "op_min", "op_max", "op0"});
  PiSettings p;
  p.kc = s.number("kc");
  p.ti = s.number("ti");
  if (!(p.ti > 0.0)) s.fail("ti", "integral time must be > 0 s");
  p.op_min = s.number("op_min", 0.0);
  p.op_max = s.number("op_max", 100.0);
  p.op0 = s.number("op0", 50.0);
  if (!(p.op_min < p.op_max)) s.fail("op_max", "must be greater than op_min");
  if (!(p.op0 >= p.op_min && p.op0 <= p.op_max)) s.fail("op0", "must lie in [op_min, op_max]");
  try {
    PiController check(p, Ts);
  } catch (const std::invalid_argument& e) {
    s.fail_table(std::string(e.what()) + "; fix the values in [controller]");
  }
  return p;
}

ProcessSpec read_process(const Section& s, double Ts) {
  ProcessSpec p;
  const std::string type = s.string("type");
  try {
    p.type = process_type_from_string(type);
  } catch (const std::invalid_argument& e) {
    s.fail("type", e.what());
  }
  p.gain = s.number("gain");
  p.dead_time = s.number("dead_time", 0.0);
  p.pv0 = s.number("pv0", 0.0);
  if (!(p.dead_time >= 0.0)) s.fail("dead_time", "must be >= 0 s");
  switch (p.type) {
    case ProcessType::first_order:
      s.allow_only({"type", "gain", "tau", "dead_time", "pv0"});
      p.tau = s.number("tau");
      if (!(p.tau > 0.0)) s.fail("tau", "time constant must be > 0 s");
      break;
    case ProcessType::second_order:
      s.allow_only({"type", "gain", "tau", "tau2", "tau3", "wn", "zeta", "dead_time", "pv0"});
      if (s.has("wn")) {
        if (s.has("tau") || s.has("tau2") || s.has("tau3")) {
          s.fail("wn", "give either wn and zeta or tau and tau2 (and tau3), not both");
        }
        p.wn = s.number("wn");
        p.zeta = s.number("zeta");
        if (!(p.wn > 0.0)) s.fail("wn", "natural frequency must be > 0 rad/s");
        if (!(p.zeta >= 0.0)) s.fail("zeta", "damping must be >= 0");
        p.tau = 0.0;
      } else {
        p.tau = s.number("tau");
        p.tau2 = s.number("tau2");
        if (!(p.tau > 0.0)) s.fail("tau", "time constant must be > 0 s");
        if (!(p.tau2 > 0.0)) s.fail("tau2", "time constant must be > 0 s");
        p.tau3 = s.number("tau3", 0.0);
        if (!(p.tau3 >= 0.0)) s.fail("tau3", "time constant must be >= 0 s (0: no third lag)");
      }
      break;
    case ProcessType::integrating:
      s.allow_only({"type", "gain", "tau", "dead_time", "pv0"});
      p.tau = s.number("tau", 0.0);
      if (!(p.tau >= 0.0)) s.fail("tau", "lag must be >= 0 s (0: none)");
      break;
  }
  try {
    DiscreteProcess check(p, Ts);
  } catch (const std::invalid_argument& e) {
    s.fail_table(std::string(e.what()) + "; fix the values in [process]");
  }
  return p;
}

ValveEffect read_valve(const Section& s, double Ts) {
  const std::string effect = s.string("effect");
  // Constructors check the parameters; their messages become errors at this table.
  try {
    if (effect == "stiction") {
      const std::string model = s.string("model");
      if (model == "he") {
        s.allow_only({"effect", "model", "fs", "fd"});
        return HeStiction(s.number("fs"), s.number("fd"));
      }
      if (model == "kano" || model == "choudhury") {
        s.allow_only({"effect", "model", "s", "j"});
        const double S = s.number("s"), J = s.number("j");
        if (model == "kano") return KanoStiction(S, J);
        return ChoudhuryStiction(S, J);
      }
      if (model == "stenman") {
        s.allow_only({"effect", "model", "d"});
        return StenmanStiction(s.number("d"));
      }
      if (model == "position-dependent") {
        s.allow_only({"effect", "model", "position", "fs", "fd"});
        const auto x = s.numbers("position"), fs = s.numbers("fs"), fd = s.numbers("fd");
        if (fs.size() != x.size() || fd.size() != x.size()) {
          s.fail("fs", "position, fs and fd must have the same number of elements");
        }
        std::vector<PositionDependentStiction::Point> pts;
        for (std::size_t i = 0; i < x.size(); ++i) pts.push_back({x[i], fs[i], fd[i]});
        return PositionDependentStiction(std::move(pts));
      }
      s.fail("model", "unknown stiction model '" + model +
                          "'; use one of: he, kano, choudhury, stenman, position-dependent");
    }
    if (effect == "deadband") {
      s.allow_only({"effect", "d"});
      return Deadband(s.number("d"));
    }
    if (effect == "saturation") {
      s.allow_only({"effect", "lower", "upper"});
      return Saturation(s.number("lower"), s.number("upper"));
    }
    if (effect == "characteristic") {
      s.allow_only({"effect", "model", "rangeability"});
      const std::string model = s.string("model");
      Characteristic::Kind kind{};
      try {
        kind = characteristic_kind_from_string(model);
      } catch (const std::invalid_argument& e) {
        s.fail("model", e.what());
      }
      return Characteristic(kind, kind == Characteristic::Kind::linear
                                      ? s.number("rangeability", 0.0)
                                      : s.number("rangeability"));
    }
    if (effect == "actuator-lag") {
      s.allow_only({"effect", "tau"});
      return ActuatorLag(s.number("tau"), Ts);
    }
    if (effect == "preisach") {
      s.allow_only({"effect", "umin", "umax", "levels", "weights", "offset", "he_fs", "he_fd"});
      PreisachGrid g;
      g.umin = s.number("umin", 0.0);
      g.umax = s.number("umax", 100.0);
      const std::int64_t L = s.integer("levels", 0);
      if (L < 1 || L > 1000) s.fail("levels", "give the discretization level L, 1..1000");
      g.L = static_cast<int>(L);
      if (!(g.umax > g.umin)) s.fail("umax", "must be greater than umin");
      if (s.has("weights")) {
        if (s.has("he_fs") || s.has("he_fd")) {
          s.fail("weights", "give either weights (and offset) or he_fs and he_fd, not both");
        }
        auto mu = s.numbers("weights");
        if (static_cast<int>(mu.size()) != g.relay_count()) {
          s.fail("weights", "expected L(L+1)/2 = " + std::to_string(g.relay_count()) +
                                " weights for levels = " + std::to_string(g.L) + ", found " +
                                std::to_string(mu.size()));
        }
        return PreisachValve(g, std::move(mu), s.number("offset", 0.0));
      }
      if (s.has("offset")) s.fail("offset", "offset goes with weights; remove it or add weights");
      const PreisachWeights w = he_stiction_weights(g, s.number("he_fs"), s.number("he_fd"));
      return PreisachValve(g, w.mu, w.offset);
    }
  } catch (const std::invalid_argument& e) {
    s.fail_table(std::string(e.what()) + "; fix the values in this [[valve]] table");
  }
  s.fail("effect", "unknown effect '" + effect +
                       "'; use one of: stiction, deadband, saturation, characteristic, "
                       "actuator-lag, preisach");
}

DisturbanceEntry read_entry(const Section& s) {
  const std::string e = s.string("entry", "output");
  if (e == "output") return DisturbanceEntry::output;
  if (e == "input") return DisturbanceEntry::input;
  s.fail("entry", "unknown entry '" + e +
                      "'; use \"output\" (added to PV) or \"input\" (added "
                      "to the valve position)");
}

void read_disturbance(const Section& s, Disturbances& d) {
  const std::string type = s.string("type");
  if (type == "step") {
    s.allow_only({"type", "time", "size", "entry"});
    d.steps.push_back({s.number("time"), s.number("size"), read_entry(s)});
  } else if (type == "drift") {
    s.allow_only({"type", "start", "slope", "stop", "entry"});
    DriftDisturbance r;
    r.start = s.number("start");
    r.slope = s.number("slope");
    r.stop = s.number("stop", std::numeric_limits<double>::infinity());
    if (!(r.stop >= r.start)) s.fail("stop", "must be >= start");
    r.entry = read_entry(s);
    d.drifts.push_back(r);
  } else if (type == "filtered-noise") {
    s.allow_only({"type", "std", "tau", "entry"});
    NoiseDisturbance n;
    n.std = s.number("std");
    n.tau = s.number("tau");
    if (!(n.std >= 0.0)) s.fail("std", "standard deviation must be >= 0");
    if (!(n.tau > 0.0)) s.fail("tau", "filter time constant must be > 0 s");
    n.entry = read_entry(s);
    d.noises.push_back(n);
  } else {
    s.fail("type",
           "unknown disturbance type '" + type + "'; use one of: step, drift, filtered-noise");
  }
}

Scenario read_scenario(const toml::table& root_table, const std::string& file) {
  const Section root(file, root_table, "");
  root.allow_only({"name", "description", "sample_period", "samples", "controller", "process",
                   "valve", "noise", "setpoint", "disturbance"});
  Scenario sc;
  sc.name = root.string("name", std::filesystem::path(file).stem().string());
  sc.description = root.string("description", "");
  LoopConfig& c = sc.loop;
  c.Ts = root.number("sample_period");
  if (!(c.Ts > 0.0 && std::isfinite(c.Ts))) {
    root.fail("sample_period", "must be a sample period > 0 s");
  }
  const std::int64_t n = root.integer("samples", 3000);
  if (n < 1) root.fail("samples", "must be >= 1");
  sc.default_samples = static_cast<std::size_t>(n);

  c.controller = read_controller(Section(file, root.subtable("controller"), "controller"), c.Ts);
  c.process = read_process(Section(file, root.subtable("process"), "process"), c.Ts);

  const auto valves = root.table_array("valve");
  for (std::size_t i = 0; i < valves.size(); ++i) {
    c.valve.push_back(
        read_valve(Section(file, *valves[i], "valve[" + std::to_string(i + 1) + "]"), c.Ts));
  }
  if (root.has("noise")) {
    const Section s(file, root.subtable("noise"), "noise");
    s.allow_only({"measurement_std"});
    c.measurement_noise_std = s.number("measurement_std", 0.0);
    if (!(c.measurement_noise_std >= 0.0)) s.fail("measurement_std", "must be >= 0");
  }
  const auto sps = root.table_array("setpoint");
  for (std::size_t i = 0; i < sps.size(); ++i) {
    const Section s(file, *sps[i], "setpoint[" + std::to_string(i + 1) + "]");
    s.allow_only({"time", "value"});
    const SetpointStep step{s.number("time"), s.number("value")};
    if (!c.setpoint.empty() && step.time < c.setpoint.back().time) {
      s.fail("time",
             "set-point steps must be in time order (this one is earlier than the one "
             "before)");
    }
    c.setpoint.push_back(step);
  }
  const auto dist = root.table_array("disturbance");
  for (std::size_t i = 0; i < dist.size(); ++i) {
    read_disturbance(Section(file, *dist[i], "disturbance[" + std::to_string(i + 1) + "]"),
                     c.disturbances);
  }
  try {
    validate(c);
  } catch (const std::invalid_argument& e) {
    throw ScenarioFileError(file, 0, 0, "", e.what());
  }
  return sc;
}

// ---------------------------------------------------------------------------------------------
// Writing.

std::string num(double v) {
  char buf[64];
  const auto r = std::to_chars(buf, buf + sizeof buf, v);  // shortest round-trip form
  return std::string(buf, r.ptr);
}

std::string quoted(const std::string& s) {
  std::string q = "\"";
  for (char ch : s) {
    const auto c = static_cast<unsigned char>(ch);
    if (ch == '"' || ch == '\\') {
      q += '\\';
      q += ch;
    } else if (c < 0x20 || c == 0x7f) {
      char esc[8];
      std::snprintf(esc, sizeof esc, "\\u%04x", c);
      q += esc;
    } else {
      q += ch;
    }
  }
  return q + "\"";
}

std::string array(const std::vector<double>& v) {
  std::string s = "[";
  for (std::size_t i = 0; i < v.size(); ++i) {
    if (i > 0) s += (i % 8 == 0) ? ",\n  " : ", ";
    s += num(v[i]);
  }
  return s + "]";
}

}  // namespace

Scenario parse_scenario_toml(std::string_view text, const std::string& source_name) {
  toml::table root;
  try {
    root = toml::parse(text, source_name);
  } catch (const toml::parse_error& e) {
    throw ScenarioFileError(source_name, static_cast<int>(e.source().begin.line),
                            static_cast<int>(e.source().begin.column), "",
                            std::string(e.description()) + "; fix the TOML syntax there");
  }
  return read_scenario(root, source_name);
}

Scenario load_scenario_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    throw ScenarioFileError(path, 0, 0, "",
                            "cannot open the file; check the path (scenario files live in "
                            "configs/scenarios/)");
  }
  std::ostringstream text;
  text << in.rdbuf();
  return parse_scenario_toml(text.str(), path);
}

std::string scenario_to_toml(const Scenario& sc) {
  std::ostringstream o;
  const LoopConfig& c = sc.loop;
  o << "name = " << quoted(sc.name) << "\n";
  o << "description = " << quoted(sc.description) << "\n";
  o << "sample_period = " << num(c.Ts) << "\n";
  o << "samples = " << sc.default_samples << "\n\n";

  o << "[controller]\n";
  o << "kc = " << num(c.controller.kc) << "\nti = " << num(c.controller.ti)
    << "\nop_min = " << num(c.controller.op_min) << "\nop_max = " << num(c.controller.op_max)
    << "\nop0 = " << num(c.controller.op0) << "\n\n";

  const ProcessSpec& p = c.process;
  o << "[process]\ntype = " << quoted(to_string(p.type)) << "\ngain = " << num(p.gain) << "\n";
  switch (p.type) {
    case ProcessType::first_order:
      o << "tau = " << num(p.tau) << "\n";
      break;
    case ProcessType::second_order:
      if (p.wn > 0.0) {
        o << "wn = " << num(p.wn) << "\nzeta = " << num(p.zeta) << "\n";
      } else {
        o << "tau = " << num(p.tau) << "\ntau2 = " << num(p.tau2) << "\n";
        if (p.tau3 > 0.0) o << "tau3 = " << num(p.tau3) << "\n";
      }
      break;
    case ProcessType::integrating:
      o << "tau = " << num(p.tau) << "\n";
      break;
  }
  o << "dead_time = " << num(p.dead_time) << "\npv0 = " << num(p.pv0) << "\n";

  for (const ValveEffect& e : c.valve) {
    o << "\n[[valve]]\neffect = " << quoted(effect_name(e)) << "\n";
    const std::string model = effect_model(e);
    if (!model.empty()) o << "model = " << quoted(model) << "\n";
    if (const auto* b = std::get_if<HeStiction>(&e)) {
      o << "fs = " << num(b->fs()) << "\nfd = " << num(b->fd()) << "\n";
    } else if (const auto* k = std::get_if<KanoStiction>(&e)) {
      o << "s = " << num(k->S()) << "\nj = " << num(k->J()) << "\n";
    } else if (const auto* ch = std::get_if<ChoudhuryStiction>(&e)) {
      o << "s = " << num(ch->S()) << "\nj = " << num(ch->J()) << "\n";
    } else if (const auto* st = std::get_if<StenmanStiction>(&e)) {
      o << "d = " << num(st->d()) << "\n";
    } else if (const auto* pd = std::get_if<PositionDependentStiction>(&e)) {
      std::vector<double> x, fs, fd;
      for (const auto& pt : pd->points()) {
        x.push_back(pt.position);
        fs.push_back(pt.fs);
        fd.push_back(pt.fd);
      }
      o << "position = " << array(x) << "\nfs = " << array(fs) << "\nfd = " << array(fd) << "\n";
    } else if (const auto* db = std::get_if<Deadband>(&e)) {
      o << "d = " << num(db->d()) << "\n";
    } else if (const auto* sat = std::get_if<Saturation>(&e)) {
      o << "lower = " << num(sat->lower()) << "\nupper = " << num(sat->upper()) << "\n";
    } else if (const auto* cha = std::get_if<Characteristic>(&e)) {
      if (cha->kind() != Characteristic::Kind::linear) {
        o << "rangeability = " << num(cha->rangeability()) << "\n";
      }
    } else if (const auto* lag = std::get_if<ActuatorLag>(&e)) {
      o << "tau = " << num(lag->tau()) << "\n";
    } else if (const auto* pv = std::get_if<PreisachValve>(&e)) {
      const auto& g = pv->model().grid();
      o << "umin = " << num(g.umin) << "\numax = " << num(g.umax) << "\nlevels = " << g.L
        << "\noffset = " << num(pv->model().offset())
        << "\nweights = " << array(pv->model().weights()) << "\n";
    }
  }

  o << "\n[noise]\nmeasurement_std = " << num(c.measurement_noise_std) << "\n";
  for (const auto& s : c.setpoint) {
    o << "\n[[setpoint]]\ntime = " << num(s.time) << "\nvalue = " << num(s.value) << "\n";
  }
  for (const auto& s : c.disturbances.steps) {
    o << "\n[[disturbance]]\ntype = \"step\"\ntime = " << num(s.time) << "\nsize = " << num(s.size)
      << "\nentry = " << quoted(to_string(s.entry)) << "\n";
  }
  for (const auto& r : c.disturbances.drifts) {
    o << "\n[[disturbance]]\ntype = \"drift\"\nstart = " << num(r.start)
      << "\nslope = " << num(r.slope) << "\n";
    if (std::isfinite(r.stop)) o << "stop = " << num(r.stop) << "\n";
    o << "entry = " << quoted(to_string(r.entry)) << "\n";
  }
  for (const auto& n : c.disturbances.noises) {
    o << "\n[[disturbance]]\ntype = \"filtered-noise\"\nstd = " << num(n.std)
      << "\ntau = " << num(n.tau) << "\nentry = " << quoted(to_string(n.entry)) << "\n";
  }
  return o.str();
}

}  // namespace valvediag
