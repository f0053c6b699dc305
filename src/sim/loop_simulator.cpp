#include "valvediag/sim/loop_simulator.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>
#include <variant>

namespace valvediag {
namespace {

bool finite(double v) {
  return std::isfinite(v);
}

// Streams of the simulator's random numbers: one engine each, all from the one seed.
constexpr std::uint32_t kMeasurementStream = 1;
constexpr std::uint32_t kFirstDisturbanceStream = 100;

std::mt19937_64 make_engine(std::uint64_t seed, std::uint32_t stream) {
  // seed_seq's mixing is specified by the standard, so the engines are the same everywhere.
  std::seed_seq seq{static_cast<std::uint32_t>(seed), static_cast<std::uint32_t>(seed >> 32),
                    stream};
  return std::mt19937_64(seq);
}

// Tolerance on event times, so that an event at t = k Ts is not missed by rounding in k * Ts.
double time_slack(double Ts) {
  return 1e-6 * Ts;
}

}  // namespace

// ---------------------------------------------------------------------------------------------
PiController::PiController(const PiSettings& settings, double Ts) : settings_(settings), Ts_(Ts) {
  if (!finite(Ts) || Ts <= 0.0) throw std::invalid_argument("controller: needs Ts > 0");
  if (!finite(settings.kc)) throw std::invalid_argument("controller: kc must be finite");
  if (!finite(settings.ti) || settings.ti <= 0.0) {
    throw std::invalid_argument("controller: needs ti > 0");
  }
  if (!finite(settings.op_min) || !finite(settings.op_max) || settings.op_min >= settings.op_max) {
    throw std::invalid_argument("controller: needs op_min < op_max");
  }
  if (!finite(settings.op0) || settings.op0 < settings.op_min || settings.op0 > settings.op_max) {
    throw std::invalid_argument("controller: needs op_min <= op0 <= op_max");
  }
  reset(settings.op0);
}

void PiController::reset(double op0) {
  u_ = std::clamp(op0, settings_.op_min, settings_.op_max);
  e_prev_ = 0.0;
  first_ = true;
}

double PiController::step(double sp, double pv) {
  const double e = sp - pv;
  if (first_) {
    e_prev_ = e;  // the loop was at rest: no proportional kick from the first error
    first_ = false;
  }
  const double du = settings_.kc * ((e - e_prev_) + Ts_ / settings_.ti * e);
  u_ = std::clamp(u_ + du, settings_.op_min, settings_.op_max);
  e_prev_ = e;
  return u_;
}

std::string to_string(DisturbanceEntry entry) {
  return entry == DisturbanceEntry::output ? "output" : "input";
}

// ---------------------------------------------------------------------------------------------
void validate(const LoopConfig& c) {
  if (!finite(c.Ts) || c.Ts <= 0.0) throw std::invalid_argument("loop: needs Ts > 0");
  PiController check_pi(c.controller, c.Ts);
  DiscreteProcess check_process(c.process, c.Ts);
  for (const auto& e : c.valve) {
    if (const auto* lag = std::get_if<ActuatorLag>(&e)) {
      if (std::abs(lag->sample_period() - c.Ts) > 1e-12 * c.Ts) {
        throw std::invalid_argument(
            "actuator-lag was built for Ts = " + std::to_string(lag->sample_period()) +
            " s but the loop runs at Ts = " + std::to_string(c.Ts) + " s");
      }
    }
  }
  if (!finite(c.measurement_noise_std) || c.measurement_noise_std < 0.0) {
    throw std::invalid_argument("noise: needs measurement_noise_std >= 0");
  }
  for (const auto& s : c.disturbances.steps) {
    if (!finite(s.time) || !finite(s.size)) {
      throw std::invalid_argument("step disturbance: time and size must be finite");
    }
  }
  for (const auto& d : c.disturbances.drifts) {
    if (!finite(d.start) || !finite(d.slope) || std::isnan(d.stop) || d.stop < d.start) {
      throw std::invalid_argument("drift disturbance: needs finite start and slope, stop >= start");
    }
  }
  for (const auto& n : c.disturbances.noises) {
    if (!finite(n.std) || n.std < 0.0 || !finite(n.tau) || n.tau <= 0.0) {
      throw std::invalid_argument("filtered-noise disturbance: needs std >= 0 and tau > 0");
    }
  }
  for (std::size_t i = 0; i < c.setpoint.size(); ++i) {
    if (!finite(c.setpoint[i].time) || !finite(c.setpoint[i].value)) {
      throw std::invalid_argument("setpoint: times and values must be finite");
    }
    if (i > 0 && c.setpoint[i].time < c.setpoint[i - 1].time) {
      throw std::invalid_argument("setpoint: step times must not decrease");
    }
  }
}

// ---------------------------------------------------------------------------------------------
LoopSimulator::LoopSimulator(LoopConfig config, std::uint64_t seed)
    : config_((validate(config), std::move(config))),
      pi_(config_.controller, config_.Ts),
      valve_(config_.valve),
      process_(config_.process, config_.Ts),
      load_process_(config_.process, config_.Ts) {
  reset(seed);
}

void LoopSimulator::reset(std::uint64_t seed) {
  k_ = 0;
  // At rest: OP at op0, the valve at the position op0 gives, the process in steady state there.
  pi_.reset(config_.controller.op0);
  const double x_rest = valve_.reset(config_.controller.op0);
  process_.reset(x_rest);
  load_process_.reset(0.0);
  x_rest_ = x_rest;
  trace_ = Trace{};
  trace_.block_in.assign(config_.valve.size(), {});
  trace_.block_out.assign(config_.valve.size(), {});

  measurement_engine_ = make_engine(seed, kMeasurementStream);
  normal_.reset();
  const std::size_t n = config_.disturbances.noises.size();
  noise_engines_.clear();
  noise_normals_.assign(n, std::normal_distribution<double>(0.0, 1.0));
  noise_state_.assign(n, 0.0);
  for (std::size_t i = 0; i < n; ++i) {
    noise_engines_.push_back(
        make_engine(seed, kFirstDisturbanceStream + static_cast<std::uint32_t>(i)));
    // Start from the stationary distribution, so the run has no start-up transient.
    noise_state_[i] = config_.disturbances.noises[i].std * noise_normals_[i](noise_engines_[i]);
  }
}

double LoopSimulator::setpoint_at(double t) const {
  double sp = config_.process.pv0;
  const double slack = time_slack(config_.Ts);
  for (const auto& s : config_.setpoint) {
    if (s.time > t + slack) break;
    sp = s.value;
  }
  return sp;
}

double LoopSimulator::deterministic_disturbance(double t, DisturbanceEntry entry) const {
  const double slack = time_slack(config_.Ts);
  double d = 0.0;
  for (const auto& s : config_.disturbances.steps) {
    if (s.entry == entry && t + slack >= s.time) d += s.size;
  }
  for (const auto& r : config_.disturbances.drifts) {
    if (r.entry == entry && t > r.start) d += r.slope * (std::min(t, r.stop) - r.start);
  }
  return d;
}

LoopSample LoopSimulator::step() {
  const double t = static_cast<double>(k_) * config_.Ts;
  double d_out = deterministic_disturbance(t, DisturbanceEntry::output);
  double d_in = deterministic_disturbance(t, DisturbanceEntry::input);
  for (std::size_t i = 0; i < noise_state_.size(); ++i) {
    (config_.disturbances.noises[i].entry == DisturbanceEntry::output ? d_out : d_in) +=
        noise_state_[i];
  }

  const double sp = setpoint_at(t);
  const double y = process_.output() + d_out;
  const double ym = y + config_.measurement_noise_std * normal_(measurement_engine_);
  const double u = pi_.step(sp, ym);
  double x = u;
  for (std::size_t i = 0; i < valve_.effects().size(); ++i) {
    if (keep_trace_) trace_.block_in[i].push_back(x);
    x = std::visit([x](auto& block) { return block.step(x); }, valve_.effects()[i]);
    if (keep_trace_) trace_.block_out[i].push_back(x);
  }
  if (keep_trace_) {
    trace_.load_pv.push_back(d_out + load_process_.output() - config_.process.pv0);
    // The process is linear: its output less the input loads' response is the valve's alone.
    trace_.valve_pv.push_back(y - trace_.load_pv.back());
    trace_.x.push_back(x);
    trace_.process_in.push_back(x + d_in);
  }
  process_.advance(x + d_in);
  load_process_.advance(d_in);

  for (std::size_t i = 0; i < noise_state_.size(); ++i) {
    const auto& n = config_.disturbances.noises[i];
    const double a = std::exp(-config_.Ts / n.tau);
    noise_state_[i] =
        a * noise_state_[i] + n.std * std::sqrt(1.0 - a * a) * noise_normals_[i](noise_engines_[i]);
  }
  ++k_;
  return {t, sp, u, ym, x};
}

LoopData LoopSimulator::run(std::size_t samples, const std::string& source) {
  LoopData d;
  d.source = source;
  d.t.reserve(samples);
  d.sp.reserve(samples);
  d.op.reserve(samples);
  d.pv.reserve(samples);
  d.mv.reserve(samples);
  for (std::size_t k = 0; k < samples; ++k) {
    const LoopSample s = step();
    d.t.push_back(s.t);
    d.sp.push_back(s.sp);
    d.op.push_back(s.op);
    d.pv.push_back(s.pv);
    d.mv.push_back(s.mv);
  }
  return d;
}

bool EffectActivity::overlaps(std::size_t begin, std::size_t end) const {
  for (const auto& [b, e] : intervals)
    if (b < end && begin < e) return true;
  return false;
}

namespace {

// Flags -> intervals, gaps shorter than `gap` samples bridged.
EffectActivity make_activity(std::string effect, std::string detail, const std::vector<char>& on,
                             std::size_t gap = 5) {
  EffectActivity a{std::move(effect), std::move(detail), {}, 0};
  const std::size_t n = on.size();
  for (std::size_t k = 0; k < n;) {
    if (!on[k]) {
      ++k;
      continue;
    }
    std::size_t e = k;
    while (e < n && on[e]) ++e;
    if (!a.intervals.empty() && k - a.intervals.back().second < gap) {
      a.intervals.back().second = e;
    } else {
      a.intervals.emplace_back(k, e);
    }
    k = e;
  }
  for (const auto& [b, e] : a.intervals) a.samples += e - b;
  return a;
}

// Samples within `span` after a move of x larger than `move` (compared over `span` samples).
std::vector<char> after_moves(const std::vector<double>& x, std::size_t span, double move) {
  std::vector<char> on(x.size(), 0);
  span = std::max<std::size_t>(span, 1);
  for (std::size_t k = span; k < x.size(); ++k) on[k] = std::abs(x[k] - x[k - span]) > move;
  return on;
}

}  // namespace

std::vector<EffectActivity> LoopSimulator::activity(double move) const {
  std::vector<EffectActivity> out;
  const std::size_t n = trace_.x.size();
  for (std::size_t i = 0; i < config_.valve.size(); ++i) {
    const auto& in = trace_.block_in[i];
    const auto& o = trace_.block_out[i];
    const ValveEffect& block = config_.valve[i];
    const std::string name = effect_name(block);
    std::vector<char> on(n, 0);
    std::string detail;
    if (name == "saturation") {
      detail = "the travel limits clamp the valve";
      for (std::size_t k = 0; k < n; ++k) on[k] = std::abs(o[k] - in[k]) > 1e-9;
    } else if (name == "characteristic") {
      detail = "the map's local slope differs from its mean slope by more than 20 %";
      ValveEffect probe = block;
      auto map = [&probe](double v) {
        return std::visit([v](auto& b) { return b.step(v); }, probe);
      };
      std::vector<double> slope(n);
      double mean = 0.0;
      for (std::size_t k = 0; k < n; ++k) {
        slope[k] = map(in[k] + 0.5) - map(in[k] - 0.5);
        mean += slope[k] / static_cast<double>(n);
      }
      for (std::size_t k = 0; k < n; ++k) on[k] = std::abs(slope[k] - mean) > 0.2 * mean;
    } else if (name == "actuator-lag") {
      detail = "the valve lags OP by more than the move threshold";
      for (std::size_t k = 0; k < n; ++k) on[k] = std::abs(o[k] - in[k]) > move;
    } else {
      detail = "stuck: OP moves while the valve stays put";
      for (std::size_t k = 1; k < n; ++k)
        on[k] = std::abs(in[k] - in[k - 1]) > 1e-9 && std::abs(o[k] - o[k - 1]) <= 1e-9;
    }
    out.push_back(make_activity(name, detail, on));
  }
  const ProcessSpec& p = config_.process;
  const std::size_t delay = static_cast<std::size_t>(std::llround(p.dead_time / config_.Ts));
  if (delay > 0)
    out.push_back(make_activity("delay", "the dead time hides a valve move from the process",
                                after_moves(trace_.x, delay, move)));
  if (p.type == ProcessType::second_order) {
    const double extra = p.wn > 0.0 ? 2.0 / p.wn : p.tau2 + p.tau3;
    out.push_back(make_activity(
        "order", "settling of the extra lags after a valve move",
        after_moves(trace_.x, static_cast<std::size_t>(std::llround(extra / config_.Ts)), move)));
  }
  if (p.type == ProcessType::integrating) {
    std::vector<char> on(n, 0);
    for (std::size_t k = 0; k < n; ++k) on[k] = std::abs(trace_.process_in[k] - x_rest_) > move;
    out.push_back(make_activity("integrator", "the inflow is off its balance: PV ramps", on));
  }
  const auto& d = config_.disturbances;
  if (!d.steps.empty() || !d.drifts.empty() || !d.noises.empty()) {
    const double level =
        config_.measurement_noise_std > 0.0 ? 2.0 * config_.measurement_noise_std : 0.1;
    std::vector<char> on(n, 0);
    for (std::size_t k = 0; k < n; ++k) on[k] = std::abs(trace_.load_pv[k]) > level;
    out.push_back(
        make_activity("disturbance", "the loads move PV beyond the measurement noise", on));
  }
  return out;
}

LoopData simulate_loop(const LoopConfig& config, std::uint64_t seed, std::size_t samples) {
  LoopSimulator sim(config, seed);
  return sim.run(samples);
}

}  // namespace valvediag
