#include "valvediag/sim/random_loop.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>
#include <stdexcept>

#include "valvediag/util/text_stats.hpp"

namespace valvediag {

namespace {

// Uniform numbers from the engine's raw bits (the standard's distributions other than the
// engines are implementation-defined): a seed gives the same loop with every standard library.
class Draw {
 public:
  Draw(std::uint64_t seed, const std::string& category, int attempt) {
    std::uint32_t h = 2166136261u;  // FNV-1a of the category: each category its own stream
    for (char c : category) h = (h ^ static_cast<unsigned char>(c)) * 16777619u;
    std::seed_seq seq{static_cast<std::uint32_t>(seed), static_cast<std::uint32_t>(seed >> 32), h,
                      static_cast<std::uint32_t>(attempt)};
    eng_.seed(seq);
  }
  double unit() { return static_cast<double>(eng_() >> 11) * 0x1.0p-53; }
  double uniform(double a, double b) { return a + (b - a) * unit(); }
  double log_uniform(double a, double b) { return std::exp(uniform(std::log(a), std::log(b))); }
  bool chance(double p) { return unit() < p; }
  int integer(int a, int b) {  // a..b inclusive
    return a + static_cast<int>(std::floor(unit() * (b - a + 1)));
  }
  double sign() { return chance(0.5) ? 1.0 : -1.0; }
  std::uint64_t bits() { return eng_(); }

 private:
  std::mt19937_64 eng_;
};

constexpr int kStartNkMax = 10;  // the base structure grid's dead time (StructureRange)

bool has(const std::vector<std::string>& v, const std::string& s) {
  return std::find(v.begin(), v.end(), s) != v.end();
}

// The sample period: the nearest "round" period to tau / n (DCS scan classes).
double round_period(double raw) {
  static const double periods[] = {0.1, 0.2, 0.5, 1.0, 2.0, 5.0, 10.0};
  double best = periods[0];
  for (double p : periods)
    if (std::abs(std::log(p / raw)) < std::abs(std::log(best / raw))) best = p;
  return best;
}

// The valve effects a hidden or modelled effect name stands for in the simulator.
struct ValveDraw {
  std::vector<ValveEffect> blocks;  // chain order: actuator-lag first, as the model's
  std::vector<TrueParameter> truth;
  std::string text;
  // Position-dependent friction: the valve positions between which the friction changes.
  double zone_lo = 0.0, zone_hi = 0.0;
};

ValveDraw friction(Draw& r, const std::string& as_effect) {
  ValveDraw v;
  const double kind = r.unit();
  if (kind < 0.6) {
    const double fs = r.log_uniform(0.8, 8.0), fd = fs * r.uniform(0.1, 0.8);
    v.blocks.push_back(HeStiction(fs, fd, r.uniform(-1.0, 1.0)));
    v.truth.push_back({as_effect, "band", fs, "% of OP"});
    v.text = "He stiction fs " + strprintf("%.2f", fs) + " fd " + strprintf("%.2f", fd);
  } else if (kind < 0.85) {
    const double S = r.log_uniform(1.0, 8.0), J = S * r.uniform(0.1, 0.8);
    v.blocks.push_back(KanoStiction(S, J));
    v.truth.push_back({as_effect, "band", S, "% of OP"});
    v.text = "Kano stiction S " + strprintf("%.2f", S) + " J " + strprintf("%.2f", J);
  } else {
    const double d = r.log_uniform(0.8, 6.0);
    v.blocks.push_back(StenmanStiction(d));
    v.truth.push_back({as_effect, "band", d, "% of OP"});
    v.text = "Stenman stiction d " + strprintf("%.2f", d);
  }
  return v;
}

// The effect, variant included, that a start model has for a drawn friction or backlash: the
// true model less the hidden effects is the valve's own model, not He's in place of Kano's.
std::string modelled_as(const ValveEffect& block) {
  const std::string variant = effect_model(block);
  return variant.empty() || variant == "he" ? effect_name(block)
                                            : effect_name(block) + ":" + variant;
}

ValveDraw backlash(Draw& r) {
  ValveDraw v;
  const double d = r.log_uniform(1.0, 6.0);
  v.blocks.push_back(Deadband(d));
  v.truth.push_back({"deadband", "band", d, "% of OP"});
  v.text = "deadband " + strprintf("%.2f", d);
  return v;
}

// The operating window the set-point programme moves the valve over, % of OP.
struct Window {
  double lo = 40.0, hi = 60.0;
};

struct Draft {
  std::vector<std::string> hidden, modelled;  // effect names
  LoopConfig loop;
  std::size_t samples = 0;
  std::vector<TrueParameter> truth;
  std::vector<std::string> text;
  double zone_lo = 0.0, zone_hi = 0.0;  // position-dependent friction (preisach)
};

std::vector<std::string> hidden_set(Draw& r, const std::string& category) {
  if (category == "none") return {};
  if (category != "pair") return {category};
  static const std::vector<std::vector<std::string>> pairs = {
      {"stiction", "disturbance"}, {"stiction", "integrator"},
      {"stiction", "delay"},       {"stiction", "order"},
      {"deadband", "delay"},       {"deadband", "integrator"},
      {"saturation", "delay"},     {"saturation", "disturbance"},
      {"characteristic", "delay"}, {"characteristic", "disturbance"},
      {"stiction", "saturation"},  {"deadband", "disturbance"},
  };
  return pairs[static_cast<std::size_t>(r.integer(0, static_cast<int>(pairs.size()) - 1))];
}

// Set-point values that ask for valve positions `targets` (held `op0` before the first move).
double setpoint_for(const ProcessSpec& p, const std::vector<ValveEffect>& valve, double op0,
                    double target) {
  // The valve's static map (a characteristic bends it; limits clip it; friction bands average out).
  auto map = [&](double u) {
    for (const auto& b : valve) {
      if (const auto* c = std::get_if<Characteristic>(&b)) {
        Characteristic m = *c;
        u = m.step(u);
      } else if (const auto* s = std::get_if<Saturation>(&b)) {
        u = std::clamp(u, s->lower(), s->upper());
      }
    }
    return u;
  };
  return p.pv0 + p.gain * (map(target) - map(op0));
}

Draft draft(Draw& r, const std::string& category) {
  Draft d;
  d.hidden = hidden_set(r, category);
  const auto hid = [&](const char* e) { return has(d.hidden, e); };
  LoopConfig& c = d.loop;

  // --- the valve: hidden effects, and the ones the start model already has -------------------
  ValveDraw valve;
  Window w;
  const double centre = r.uniform(30.0, 70.0);
  double width = r.uniform(8.0, 30.0);
  bool sat_upper = true;
  double sat_limit = 0.0;
  if (hid("stiction")) {
    valve = friction(r, "stiction");
  } else if (hid("deadband")) {
    valve = backlash(r);
  } else if (hid("preisach")) {
    // Friction that depends on the valve position: severe on one side of a position, mild on the
    // other (the paper's Example 2 valve). The start model has a two-parameter stiction.
    const double severe = r.log_uniform(3.0, 8.0), mild = severe * r.uniform(0.1, 0.35);
    const double ratio_s = r.uniform(0.2, 0.6), ratio_m = r.uniform(0.2, 0.6);
    const double p = centre, half = r.uniform(1.0, 3.0);
    const bool severe_low = r.chance(0.5);
    PositionDependentStiction::Point a{p - half, severe_low ? severe : mild,
                                       (severe_low ? severe : mild) * ratio_s};
    PositionDependentStiction::Point b{p + half, severe_low ? mild : severe,
                                       (severe_low ? mild : severe) * ratio_m};
    valve.blocks.push_back(PositionDependentStiction({a, b}));
    valve.truth.push_back({"preisach", "band", severe, "% of OP"});
    valve.truth.push_back({"preisach", "mild_band", mild, "% of OP"});
    valve.text = "position-dependent stiction fs " + strprintf("%.2f", a.fs) + " below " +
                 strprintf("%.0f %%", a.position) + ", " + strprintf("%.2f", b.fs) + " above " +
                 strprintf("%.0f %%", b.position);
    valve.zone_lo = a.position;
    valve.zone_hi = b.position;
    width = r.uniform(22.0, 40.0);
    d.modelled.push_back("stiction");
  } else if (hid("saturation")) {
    // A travel limit inside the window: the set points beyond it cannot be reached.
    sat_upper = r.chance(0.6);
    width = r.uniform(15.0, 35.0);
    const double inset = r.uniform(0.2, 0.45) * width;
    sat_limit = sat_upper ? centre + width / 2 - inset : centre - width / 2 + inset;
    valve.blocks.push_back(sat_upper ? Saturation(0.0, sat_limit) : Saturation(sat_limit, 100.0));
    valve.truth.push_back({"saturation", "limit", sat_limit, "% of OP"});
    valve.text = std::string(sat_upper ? "upper" : "lower") + " travel limit " +
                 strprintf("%.1f %%", sat_limit);
  } else if (hid("characteristic")) {
    const bool eq = r.chance(0.6);
    const double R = r.log_uniform(8.0, 50.0);
    valve.blocks.push_back(Characteristic(
        eq ? Characteristic::Kind::equal_percentage : Characteristic::Kind::quick_opening, R));
    valve.truth.push_back(
        {"characteristic", "log_rangeability", eq ? std::log(R) : -std::log(R), ""});
    valve.text =
        std::string(eq ? "equal-percentage" : "quick-opening") + " R " + strprintf("%.0f", R);
    width = r.uniform(30.0, 50.0);
  }
  // An actuator lag hidden behind a valve nonlinearity the start model has (with a linear valve
  // it commutes with the process lags: no OP/PV record can place it in the valve).
  const bool lagged = hid("actuator-lag");
  if (lagged) {
    valve = r.chance(0.7) ? friction(r, "stiction") : backlash(r);
    d.modelled.push_back(modelled_as(valve.blocks.front()));
    valve.truth.clear();
  }
  // A control may have a valve nonlinearity in its start model too.
  if (category == "none" && r.chance(0.4)) {
    valve = r.chance(0.6) ? friction(r, "stiction") : backlash(r);
    d.modelled.push_back(modelled_as(valve.blocks.front()));
    valve.truth.clear();
  }
  w.lo = std::clamp(centre - width / 2, 3.0, 90.0);
  w.hi = std::clamp(centre + width / 2, w.lo + 5.0, 97.0);

  // --- the process ------------------------------------------------------------------------------
  ProcessSpec& p = c.process;
  const double tref = r.log_uniform(8.0, 300.0);  // its dominant time constant, s
  double Ts = round_period(tref / r.log_uniform(6.0, 60.0));
  p.type = hid("integrator") ? ProcessType::integrating
           : hid("order")    ? ProcessType::second_order
           : r.chance(0.22)  ? ProcessType::integrating
           : r.chance(0.4)   ? ProcessType::second_order
                             : ProcessType::first_order;
  if (p.type == ProcessType::integrating && !hid("integrator")) d.modelled.push_back("integrator");
  const double gsign = r.chance(0.25) ? -1.0 : 1.0;
  p.pv0 = r.uniform(20.0, 80.0);
  double tau_eff = tref, theta_extra = 0.0;  // for the tuning (SIMC's half rule)
  if (p.type == ProcessType::integrating) {
    p.gain = gsign * r.log_uniform(0.002, 0.03);
    p.tau = r.chance(0.5) ? tref * r.uniform(0.05, 0.3) : 0.0;
    theta_extra = p.tau;
  } else {
    p.gain = gsign * r.log_uniform(0.3, 3.0);
    p.tau = tref;
    if (p.type == ProcessType::second_order) {
      if (hid("order")) {
        p.tau2 = tref * r.uniform(0.4, 1.0);
        p.tau3 = tref * r.uniform(0.3, 0.8);
        theta_extra = p.tau2 / 2 + p.tau3;
        tau_eff = tref + p.tau2 / 2;
      } else {
        p.tau2 = tref * r.uniform(0.05, 0.4);
        theta_extra = p.tau2 / 2;
        tau_eff = tref + p.tau2 / 2;
      }
    }
  }
  if (hid("delay")) {
    // Dead time beyond the start model's reach, up to a few minutes (or 150 samples).
    const double samples = r.log_uniform(14.0, 150.0);
    p.dead_time = std::min(samples * Ts, std::max(300.0, 14.0 * Ts));
  } else {
    p.dead_time = Ts * r.uniform(0.0, std::min(8.0, std::max(0.5, 0.5 * tref / Ts)));
  }
  if (p.dead_time / Ts > kStartNkMax - 1 && !hid("delay")) p.dead_time = (kStartNkMax - 2) * Ts;

  // --- the controller: SIMC, detuned from tight to sluggish --------------------------------------
  const double theta_eff = p.dead_time + theta_extra;
  const double tc_min = std::max(theta_eff, 2.0 * Ts);
  PiSettings& pi = c.controller;
  if (p.type == ProcessType::integrating) {
    const double tc = r.log_uniform(tc_min, std::max(3.0 * tc_min, tref));
    pi.kc = 1.0 / (p.gain * (tc + theta_eff));
    pi.ti = 4.0 * (tc + theta_eff);
  } else {
    const double tc = r.log_uniform(0.7 * tc_min, std::max(3.0 * tc_min, 2.0 * tau_eff));
    pi.kc = tau_eff / (p.gain * (tc + theta_eff));
    pi.ti = std::min(tau_eff, 4.0 * (tc + theta_eff));
  }
  pi.op_min = 0.0;
  pi.op_max = 100.0;
  pi.op0 = std::clamp(r.uniform(w.lo, w.hi), 2.0, 98.0);
  if (hid("saturation"))  // start on the reachable side of the limit
    pi.op0 = sat_upper ? std::min(pi.op0, sat_limit - 2.0) : std::max(pi.op0, sat_limit + 2.0);

  // --- record length and the set-point programme -------------------------------------------------
  d.samples = static_cast<std::size_t>(r.integer(2500, 6000));
  const double duration = static_cast<double>(d.samples) * Ts;
  const double settle = 4.0 * (std::abs(pi.ti) + theta_eff);
  const bool regulatory = r.chance(0.15) && !hid("saturation") && !hid("characteristic") &&
                          !hid("preisach") && !hid("integrator");
  c.setpoint = {{0.0, p.pv0}};
  double pv_scale = std::abs(p.gain);  // PV per % of valve, at steady state
  if (p.type == ProcessType::integrating) pv_scale = std::abs(p.gain) * std::max(tref, 20.0);
  if (!regulatory) {
    const int moves = r.integer(3, 14);
    const double spacing = std::max(duration / (moves + 1), 0.5 * settle);
    double t = r.uniform(0.02, 0.1) * duration;
    std::vector<ValveEffect> statics = valve.blocks;
    for (int k = 0; k < moves && t < duration * 0.97; ++k) {
      double target = r.uniform(w.lo, w.hi);
      if (hid("saturation")) {
        // Every other move asks for the unreachable side of the limit, the others for the
        // reachable part of the window (at least 2 % inside).
        if (k % 2 == 0)
          target = sat_upper ? r.uniform(sat_limit + 1.0, std::min(99.0, sat_limit + 15.0))
                             : r.uniform(std::max(1.0, sat_limit - 15.0), sat_limit - 1.0);
        else
          target = sat_upper ? r.uniform(std::min(w.lo, sat_limit - 4.0), sat_limit - 2.0)
                             : r.uniform(sat_limit + 2.0, std::max(w.hi, sat_limit + 4.0));
      }
      double sp;
      if (p.type == ProcessType::integrating)
        sp = p.pv0 + r.sign() * pv_scale * r.uniform(2.0, 10.0);
      else
        sp = setpoint_for(p, statics, pi.op0, target);
      if (hid("saturation") && p.type != ProcessType::integrating && k % 2 == 0)
        sp = p.pv0 + p.gain * (target - pi.op0);  // beyond the limit: PV cannot get there
      c.setpoint.push_back({t, sp});
      t += spacing * r.uniform(0.6, 1.4);
    }
  }

  // --- noise and loads
  // -----------------------------------------------------------------------------
  c.measurement_noise_std = pv_scale * r.log_uniform(0.01, 0.3);
  {
    const double load_std =
        p.type == ProcessType::integrating ? r.log_uniform(0.03, 0.3) : r.log_uniform(0.05, 0.8);
    c.disturbances.noises.push_back(
        {load_std, std::max(Ts, tref * r.log_uniform(0.3, 3.0)), DisturbanceEntry::input});
  }
  if (!hid("disturbance") && r.chance(0.35)) {
    const double size =
        r.sign() * r.uniform(0.3, 1.5) * (p.type == ProcessType::integrating ? 0.3 : 1.0);
    c.disturbances.steps.push_back({r.uniform(0.1, 0.9) * duration, size, DisturbanceEntry::input});
  }
  if (hid("disturbance")) {
    // Large slow unmeasured loads, in both parts of the record: a random walk, steps, a ramp.
    const double scale = p.type == ProcessType::integrating ? 0.4 : 1.0;
    int kinds = 0;
    if (r.chance(0.6)) {
      c.disturbances.noises.push_back(
          {scale * r.uniform(2.0, 6.0), 3.0 * duration, DisturbanceEntry::input});
      ++kinds;
    }
    if (kinds == 0 || r.chance(0.6)) {
      const int n = r.integer(2, 4);
      for (int k = 0; k < n; ++k)
        c.disturbances.steps.push_back({duration * (k + r.uniform(0.2, 0.8)) / n,
                                        scale * r.sign() * r.uniform(3.0, 10.0),
                                        DisturbanceEntry::input});
      ++kinds;
    }
    if (r.chance(0.5)) {
      const double start = r.uniform(0.05, 0.5) * duration, len = r.uniform(0.2, 0.5) * duration;
      c.disturbances.drifts.push_back({start, scale * r.sign() * r.uniform(3.0, 10.0) / len,
                                       start + len, DisturbanceEntry::input});
    }
    d.truth.push_back({"disturbance", "load", scale * 5.0, "% of OP"});
  }

  // --- the valve chain, and the effects' true figures
  // ------------------------------------------------
  c.Ts = Ts;
  if (lagged) {
    const double tau_a =
        r.log_uniform(std::max(3.0 * Ts, 0.15 * tref), std::max(4.0 * Ts, 1.0 * tref));
    valve.blocks.insert(valve.blocks.begin(), ActuatorLag(tau_a, Ts));
    d.truth.push_back({"actuator-lag", "tau", tau_a, "s"});
    d.text.push_back("actuator lag " + strprintf("%.1f s", tau_a));
  }
  c.valve = valve.blocks;
  d.truth.insert(d.truth.end(), valve.truth.begin(), valve.truth.end());
  if (!valve.text.empty()) d.text.insert(d.text.begin(), valve.text);
  d.zone_lo = valve.zone_lo;
  d.zone_hi = valve.zone_hi;
  if (hid("delay")) d.truth.push_back({"delay", "dead_time", p.dead_time, "s"});
  if (hid("order")) d.truth.push_back({"order", "extra_lags", p.tau2 + p.tau3, "s"});
  if (hid("integrator")) d.truth.push_back({"integrator", "rate_gain", p.gain, "PV/s per %"});
  d.text.insert(d.text.begin(), describe(p) + ", Ts " + strprintf("%g s", Ts));
  d.text.push_back("PI kc " + strprintf("%.3g", pi.kc) + " ti " + strprintf("%.3g s", pi.ti));
  d.text.push_back("noise " + strprintf("%.3g", c.measurement_noise_std));
  d.text.push_back(std::to_string(c.setpoint.size() - 1) + " set-point moves");
  d.text.push_back(std::to_string(d.samples) + " samples");
  return d;
}

// Canonical chain order of the effect vocabulary (model_spec.hpp): the model spec's text.
std::string spec_text(std::vector<std::string> effects) {
  static const std::vector<std::string> order = {
      "actuator-lag",   "stiction", "deadband", "preisach",   "saturation",
      "characteristic", "delay",    "order",    "integrator", "disturbance"};
  // By effect name; a variant ("stiction:kano") sorts as its effect.
  const auto rank = [](const std::string& e) {
    return std::find(order.begin(), order.end(), e.substr(0, e.find(':')));
  };
  std::sort(effects.begin(), effects.end(),
            [&rank](const std::string& a, const std::string& b) { return rank(a) < rank(b); });
  effects.erase(std::unique(effects.begin(), effects.end()), effects.end());
  std::string s;
  for (const auto& e : effects) s += (s.empty() ? "" : "+") + e;
  return s.empty() ? "linear" : s;
}

// Intervals of an activity record inside [from, to), and the samples they cover there.
struct PartActivity {
  int intervals = 0;
  std::size_t samples = 0;
};
PartActivity within(const EffectActivity& a, std::size_t from, std::size_t to) {
  PartActivity p;
  for (const auto& [b, e] : a.intervals) {
    const std::size_t lo = std::max(b, from), hi = std::min(e, to);
    if (lo >= hi) continue;
    ++p.intervals;
    p.samples += hi - lo;
  }
  return p;
}

}  // namespace

const std::vector<std::string>& random_loop_categories() {
  static const std::vector<std::string> c = {
      "stiction", "deadband", "preisach",   "saturation",  "characteristic", "actuator-lag",
      "delay",    "order",    "integrator", "disturbance", "none",           "pair"};
  return c;
}

std::string fair_case(const RandomLoop& loop, const ScenarioRun& run) {
  const std::size_t N = run.data.size();
  const auto e0 = static_cast<std::size_t>(
      std::llround(static_cast<double>(N) * (1.0 - loop.validation_fraction)));
  const std::size_t parts[2][2] = {{0, e0}, {e0, N}};
  const char* part_name[2] = {"estimation", "held-out"};
  for (const auto& h : loop.hidden) {
    const std::string block = h == "preisach" ? "stiction" : h;
    const EffectActivity* a = run.find(block);
    if (!a) return h + " never acts";
    for (int k = 0; k < 2; ++k) {
      const auto [from, to] = parts[k];
      const PartActivity p = within(*a, from, to);
      const double share = static_cast<double>(p.samples) / static_cast<double>(to - from);
      bool ok = true;
      if (h == "stiction" || h == "deadband" || h == "preisach" || h == "actuator-lag" ||
          h == "delay" || h == "order")
        ok = p.intervals >= 3 && share >= 0.02;
      else if (h == "saturation")  // reached, but not pinned there (the loop still informs)
        ok = p.intervals >= 1 && share >= 0.02 && share <= 0.7;
      else if (h == "characteristic" || h == "integrator")
        ok = share >= 0.2;
      else if (h == "disturbance")
        ok = share >= 0.3;
      if (!ok)
        return h + " acts too little in the " + part_name[k] + " part (" +
               std::to_string(p.intervals) + " intervals, " +
               strprintf("%.1f %% of it)", 100 * share);
      if (h == "preisach") {
        // The valve must cross the position where its friction changes, in both parts.
        const auto [lo, hi] = std::minmax_element(run.data.mv.begin() + static_cast<long>(from),
                                                  run.data.mv.begin() + static_cast<long>(to));
        const auto* pd = std::get_if<PositionDependentStiction>(&loop.scenario.loop.valve.back());
        if (pd && !(*lo<pd->points().front().position&& * hi> pd->points().back().position))
          return std::string("the valve stays on one side of its friction change in the ") +
                 part_name[k] + " part";
      }
    }
  }
  return "";
}

RandomLoop draw_random_loop(std::uint64_t seed, const std::string& category,
                            double validation_fraction, int max_draws) {
  if (!has(random_loop_categories(), category)) {
    std::string known;
    for (const auto& c : random_loop_categories()) known += (known.empty() ? "" : ", ") + c;
    throw std::invalid_argument("unknown random-loop category '" + category + "' (known: " + known +
                                ")");
  }
  std::string last_why;
  for (int attempt = 0; attempt < max_draws; ++attempt) {
    Draw r(seed, category, attempt);
    Draft d = draft(r, category);
    RandomLoop loop;
    loop.seed = seed;
    loop.hidden = d.hidden;
    loop.start_model = spec_text(d.modelled);
    std::vector<std::string> all = d.modelled;
    all.insert(all.end(), d.hidden.begin(), d.hidden.end());
    loop.true_model = spec_text(all);
    loop.samples = d.samples;
    loop.validation_fraction = validation_fraction;
    loop.truth = d.truth;
    loop.redraws = attempt;
    Scenario& s = loop.scenario;
    s.name = "random-" + category + "-" + std::to_string(seed);
    s.loop = d.loop;
    s.default_samples = d.samples;
    s.description = "hidden " + (d.hidden.empty() ? std::string("nothing") : spec_text(d.hidden)) +
                    " from " + loop.start_model + ": ";
    for (std::size_t i = 0; i < d.text.size(); ++i) s.description += (i ? "; " : "") + d.text[i];
    try {
      validate(s.loop);
    } catch (const std::invalid_argument& e) {
      last_why = e.what();
      continue;
    }
    loop.category = category;
    loop.noise_seed = r.bits();
    const ScenarioRun run = run_scenario_traced(s, loop.noise_seed, d.samples);
    last_why = fair_case(loop, run);
    if (last_why.empty()) return loop;
  }
  throw std::runtime_error("no fair " + category + " case from seed " + std::to_string(seed) +
                           " in " + std::to_string(max_draws) + " draws (last: " + last_why + ")");
}

LoopData simulate_random_loop(const RandomLoop& loop) {
  LoopData d = run_scenario(loop.scenario, loop.noise_seed, loop.samples);
  d.source = loop.scenario.name;
  return d;
}

}  // namespace valvediag
