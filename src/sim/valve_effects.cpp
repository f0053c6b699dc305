#include "valvediag/sim/valve_effects.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <type_traits>

#include "valvediag/util/text_stats.hpp"

namespace valvediag {
namespace {

int sign(double v) {
  return (v > 0.0) - (v < 0.0);
}

void require(bool ok, const char* what) {
  if (!ok) throw std::invalid_argument(what);
}

}  // namespace

// ---------------------------------------------------------------------------------------------
HeStiction::HeStiction(double fs, double fd, double initial_motion)
    : fs_(fs), fd_(fd), initial_motion_(initial_motion) {
  require(std::isfinite(fs) && std::isfinite(fd) && fs >= fd && fd >= 0.0,
          "stiction (he): needs fs >= fd >= 0");
  require(std::isfinite(initial_motion) && std::abs(initial_motion) <= 1.0,
          "stiction (he): the initial motion must lie in [-1, 1]");
}

void HeStiction::reset(double u0, double x0, double residual_force) {
  u_prev_ = u0;
  x_ = x0;
  u_r_ = residual_force;
}

double HeStiction::step(double u) {
  const double u_cum = u_r_ + (u - u_prev_);
  if (std::abs(u_cum) > fs_) {
    u_r_ = sign(u_cum) * fd_;  // slip: kinetic friction keeps the valve fd behind the input
    x_ = u - u_r_;
  } else {
    u_r_ = u_cum;  // stick: the force builds up
  }
  u_prev_ = u;
  return x_;
}

// ---------------------------------------------------------------------------------------------
KanoStiction::KanoStiction(double S, double J) : S_(S), J_(J) {
  require(std::isfinite(S) && std::isfinite(J) && S >= J && J >= 0.0,
          "stiction (kano): needs S >= J >= 0");
}

void KanoStiction::reset(double u0) {
  u_prev_ = x_ = u_s_ = u0;
  d_ = 0;
  stopped_ = true;
}

double KanoStiction::step(double u) {
  // A moving valve stops when the input stops or turns back.
  if (!stopped_ && (u - u_prev_) * d_ <= 0.0) {
    stopped_ = true;
    u_s_ = u_prev_;
  }
  if (stopped_) {
    const double moved = u - u_s_;
    if (d_ == 0) {
      if (std::abs(moved) > S_) {
        d_ = sign(moved);
        stopped_ = false;
      }
    } else if (-d_ * moved > S_) {  // against the last direction: static friction plus deadband
      d_ = -d_;
      stopped_ = false;
    } else if (d_ * moved > J_) {  // along the last direction: only the stickband
      stopped_ = false;
    }
  }
  if (!stopped_) x_ = u - d_ * (S_ - J_) / 2.0;
  u_prev_ = u;
  return x_;
}

// ---------------------------------------------------------------------------------------------
ChoudhuryStiction::ChoudhuryStiction(double S, double J) : S_(S), J_(J) {
  require(std::isfinite(S) && std::isfinite(J) && S >= J && J >= 0.0,
          "stiction (choudhury): needs S >= J >= 0");
}

void ChoudhuryStiction::reset(double u0) {
  u_prev_ = x_ = x_ss_ = u0;
  v_sign_prev_ = 0;
  stuck_ = true;
}

double ChoudhuryStiction::step(double u) {
  const int s = sign(u - u_prev_);
  if (s != v_sign_prev_) {
    // Velocity changed sign (or the input paused / resumed): the valve sticks here.
    stuck_ = true;
    x_ss_ = u_prev_;
  }
  if (!stuck_) {
    x_ = u - s * (S_ - J_) / 2.0;
  } else if (std::abs(u - x_ss_) > S_) {
    stuck_ = false;  // the force built up since sticking overcomes static friction: slip
    x_ = u - s * (S_ - J_) / 2.0;
  }
  v_sign_prev_ = s;
  u_prev_ = u;
  return x_;
}

// ---------------------------------------------------------------------------------------------
StenmanStiction::StenmanStiction(double d) : d_(d) {
  require(std::isfinite(d) && d >= 0.0, "stiction (stenman): needs d >= 0");
}

double StenmanStiction::step(double u) {
  if (std::abs(u - x_) > d_) x_ = u;
  return x_;
}

// ---------------------------------------------------------------------------------------------
PositionDependentStiction::PositionDependentStiction(std::vector<Point> points,
                                                     double initial_motion)
    : points_(std::move(points)), initial_motion_(initial_motion) {
  require(std::isfinite(initial_motion) && std::abs(initial_motion) <= 1.0,
          "stiction (position-dependent): the initial motion must lie in [-1, 1]");
  require(!points_.empty(), "stiction (position-dependent): needs at least one point");
  for (std::size_t i = 0; i < points_.size(); ++i) {
    const Point& p = points_[i];
    require(std::isfinite(p.position) && std::isfinite(p.fs) && std::isfinite(p.fd) &&
                p.fs >= p.fd && p.fd >= 0.0,
            "stiction (position-dependent): needs fs >= fd >= 0 at every point");
    require(i == 0 || p.position > points_[i - 1].position,
            "stiction (position-dependent): positions must be strictly increasing");
  }
}

namespace {
template <class Get>
double interpolate(const std::vector<PositionDependentStiction::Point>& pts, double x, Get get) {
  if (x <= pts.front().position) return get(pts.front());
  if (x >= pts.back().position) return get(pts.back());
  const auto hi = std::upper_bound(pts.begin(), pts.end(), x,
                                   [](double v, const auto& p) { return v < p.position; });
  const auto lo = hi - 1;
  const double w = (x - lo->position) / (hi->position - lo->position);
  return get(*lo) + w * (get(*hi) - get(*lo));
}
}  // namespace

double PositionDependentStiction::fs_at(double x) const {
  return interpolate(points_, x, [](const Point& p) { return p.fs; });
}
double PositionDependentStiction::fd_at(double x) const {
  return interpolate(points_, x, [](const Point& p) { return p.fd; });
}

void PositionDependentStiction::reset(double u0, double x0, double residual_force) {
  u_prev_ = u0;
  x_ = x0;
  u_r_ = residual_force;
}

double PositionDependentStiction::step(double u) {
  // He's flowchart with the bands of the position the valve is held at.
  const double fs = fs_at(x_);
  const double fd = fd_at(x_);
  const double u_cum = u_r_ + (u - u_prev_);
  if (std::abs(u_cum) > fs) {
    u_r_ = sign(u_cum) * fd;
    x_ = u - u_r_;
  } else {
    u_r_ = u_cum;
  }
  u_prev_ = u;
  return x_;
}

// ---------------------------------------------------------------------------------------------
Deadband::Deadband(double d) : d_(d) {
  require(std::isfinite(d) && d >= 0.0, "deadband: needs d >= 0");
}

double Deadband::step(double u) {
  const double half = d_ / 2.0;
  if (u > x_ + half) {
    x_ = u - half;
  } else if (u < x_ - half) {
    x_ = u + half;
  }
  return x_;
}

// ---------------------------------------------------------------------------------------------
Saturation::Saturation(double lower, double upper) : lower_(lower), upper_(upper) {
  require(std::isfinite(lower) && std::isfinite(upper) && lower < upper,
          "saturation: needs lower < upper");
}

double Saturation::step(double u) {
  return x_ = std::clamp(u, lower_, upper_);
}

// ---------------------------------------------------------------------------------------------
Characteristic::Characteristic(Kind kind, double rangeability) : kind_(kind), R_(rangeability) {
  require(kind == Kind::linear || (std::isfinite(rangeability) && rangeability > 1.0),
          "characteristic: needs rangeability R > 1");
}

double Characteristic::step(double u) {
  const double z = std::clamp(u, 0.0, 100.0) / 100.0;
  switch (kind_) {
    case Kind::linear:
      x_ = 100.0 * z;
      break;
    case Kind::equal_percentage:
      x_ = 100.0 * std::expm1(z * std::log(R_)) / (R_ - 1.0);
      break;
    case Kind::quick_opening:
      x_ = 100.0 * std::log1p((R_ - 1.0) * z) / std::log(R_);
      break;
  }
  return x_;
}

std::string to_string(Characteristic::Kind kind) {
  switch (kind) {
    case Characteristic::Kind::linear:
      return "linear";
    case Characteristic::Kind::equal_percentage:
      return "equal-percentage";
    case Characteristic::Kind::quick_opening:
      return "quick-opening";
  }
  return "?";
}

Characteristic::Kind characteristic_kind_from_string(const std::string& name) {
  for (auto k : {Characteristic::Kind::linear, Characteristic::Kind::equal_percentage,
                 Characteristic::Kind::quick_opening}) {
    if (to_string(k) == name) return k;
  }
  throw std::invalid_argument("characteristic: unknown kind '" + name +
                              "' (known: linear, equal-percentage, quick-opening)");
}

// ---------------------------------------------------------------------------------------------
ActuatorLag::ActuatorLag(double tau, double Ts) : tau_(tau), Ts_(Ts) {
  require(std::isfinite(tau) && tau >= 0.0, "actuator-lag: needs tau >= 0");
  require(std::isfinite(Ts) && Ts > 0.0, "actuator-lag: needs a sample period Ts > 0");
  a_ = tau > 0.0 ? std::exp(-Ts / tau) : 0.0;
}

double ActuatorLag::step(double u) {
  if (tau_ == 0.0) return out_ = x_ = u;
  out_ = x_;
  x_ = a_ * x_ + (1.0 - a_) * u;
  return out_;
}

// ---------------------------------------------------------------------------------------------
PreisachValve::PreisachValve(PreisachGrid grid, std::vector<double> mu, double offset)
    : model_(grid, std::move(mu), offset) {
  reset(grid.umin);
}

void PreisachValve::reset(double u0) {
  model_.reset({0, model_.grid().level(u0)});
  x_ = model_.step(u0);
}

// ---------------------------------------------------------------------------------------------
namespace {
template <class... F>
struct Overload : F... {
  using F::operator()...;
};
template <class... F>
Overload(F...) -> Overload<F...>;
}  // namespace

std::string effect_name(const ValveEffect& effect) {
  return std::visit(
      Overload{[](const HeStiction&) -> std::string { return "stiction"; },
               [](const KanoStiction&) -> std::string { return "stiction"; },
               [](const ChoudhuryStiction&) -> std::string { return "stiction"; },
               [](const StenmanStiction&) -> std::string { return "stiction"; },
               [](const PositionDependentStiction&) -> std::string { return "stiction"; },
               [](const Deadband&) -> std::string { return "deadband"; },
               [](const Saturation&) -> std::string { return "saturation"; },
               [](const Characteristic&) -> std::string { return "characteristic"; },
               [](const ActuatorLag&) -> std::string { return "actuator-lag"; },
               [](const PreisachValve&) -> std::string { return "preisach"; }},
      effect);
}

std::string effect_model(const ValveEffect& effect) {
  return std::visit(
      Overload{[](const HeStiction&) -> std::string { return "he"; },
               [](const KanoStiction&) -> std::string { return "kano"; },
               [](const ChoudhuryStiction&) -> std::string { return "choudhury"; },
               [](const StenmanStiction&) -> std::string { return "stenman"; },
               [](const PositionDependentStiction&) -> std::string { return "position-dependent"; },
               [](const Characteristic& c) -> std::string { return to_string(c.kind()); },
               [](const auto&) -> std::string { return ""; }},
      effect);
}

std::string describe(const ValveEffect& effect) {
  const std::string params = std::visit(
      Overload{
          [](const HeStiction& b) { return "fs=" + num10g(b.fs()) + ", fd=" + num10g(b.fd()); },
          [](const KanoStiction& b) { return "S=" + num10g(b.S()) + ", J=" + num10g(b.J()); },
          [](const ChoudhuryStiction& b) { return "S=" + num10g(b.S()) + ", J=" + num10g(b.J()); },
          [](const StenmanStiction& b) { return "d=" + num10g(b.d()); },
          [](const PositionDependentStiction& b) {
            std::string s;
            for (const auto& p : b.points()) {
              if (!s.empty()) s += ", ";
              s += "x=" + num10g(p.position) + ": fs=" + num10g(p.fs) + " fd=" + num10g(p.fd);
            }
            return s;
          },
          [](const Deadband& b) { return "d=" + num10g(b.d()); },
          [](const Saturation& b) {
            return "lower=" + num10g(b.lower()) + ", upper=" + num10g(b.upper());
          },
          [](const Characteristic& b) {
            return b.kind() == Characteristic::Kind::linear ? std::string()
                                                            : "R=" + num10g(b.rangeability());
          },
          [](const ActuatorLag& b) { return "tau=" + num10g(b.tau()) + " s"; },
          [](const PreisachValve& b) {
            const auto& g = b.model().grid();
            int nonzero = 0;
            for (double m : b.model().weights()) nonzero += m != 0.0;
            return "umin=" + num10g(g.umin) + ", umax=" + num10g(g.umax) +
                   ", L=" + std::to_string(g.L) + ", " + std::to_string(nonzero) +
                   " nonzero weights";
          }},
      effect);
  const std::string model = effect_model(effect);
  std::string s = effect_name(effect);
  if (!model.empty() || !params.empty()) {
    s += " (" + model + (model.empty() || params.empty() ? "" : ": ") + params + ")";
  }
  return s;
}

// ---------------------------------------------------------------------------------------------
double ValveChain::reset(double u0) {
  double u = u0;
  for (auto& e : effects_) {
    u = std::visit(
        [u](auto& block) {
          block.reset(u);
          return block.output();
        },
        e);
  }
  return x_ = u;
}

double ValveChain::step(double u) {
  for (auto& e : effects_) u = std::visit([u](auto& block) { return block.step(u); }, e);
  return x_ = u;
}

void ValveChain::steps(const double* u, double* x, std::size_t n) {
  if (n == 0) return;
  const double* in = u;
  for (auto& e : effects_) {
    std::visit(
        [&](auto& block) {
          // On a local copy: the block's state could alias x, which kept it in memory.
          auto b = block;
          for (std::size_t t = 0; t < n; ++t) x[t] = b.step(in[t]);
          block = std::move(b);
        },
        e);
    in = x;
  }
  if (in == u) std::copy(u, u + n, x);
  x_ = x[n - 1];
}

}  // namespace valvediag
