// Valve effect blocks: the nonlinearities and dynamics between controller output u (OP, %) and
// valve position x (%). Names follow ../shared/design/effects.md (they are product interface):
// `stiction` (He, Kano, Choudhury, Stenman, position-dependent), `deadband`, `saturation`,
// `characteristic`, `actuator-lag`, `preisach`.
//
// Every block is a small copyable value holding its parameters and its memory, with
//   void reset(double u0);    // at rest with input u0 held for a long time
//   double step(double u);    // one sample: new input, returns the valve position x
//   double output() const;    // the last position returned (or the rest position after reset)
// Blocks never print or exit; bad parameters throw std::invalid_argument.
#pragma once

#include <string>
#include <variant>
#include <vector>

#include "valvediag/core/preisach.hpp"

namespace valvediag {

// He et al. (2007) two-parameter stiction, the flowchart of the paper's Figure 5:
//   u_cum = u_r + u(t) - u(t-1)
//   |u_cum| > fs: slip,  u_r = sign(u_cum) fd,  x(t) = u(t) - u_r
//   otherwise:    stick, u_r = u_cum,           x(t) = x(t-1)
// u_r is the residual force, u_cum the cumulative force. On a slow ramp the valve moves in
// jumps of fs - fd, each when u is fs ahead of x; after a reversal the input travels between
// fs + fd and 2 fs before the valve moves.
class HeStiction {
 public:
  // Needs fs >= fd >= 0. `initial_motion` m in [-1, 1] is the valve's state when a record
  // starts: u_r = m fd, x = u0 - u_r; 0 is He's rest, +1 "was moving up" (lagging the OP by
  // fd), -1 moving down. A record cut from a running loop starts wherever the valve was, and
  // at rest a band wider than the first OP sweep would pin the valve for the whole record.
  HeStiction(double fs, double fd, double initial_motion = 0.0);
  // The state at u0 that `initial_motion` says (He's rest for 0).
  void reset(double u0) { reset(u0, u0 - initial_motion_ * fd_, initial_motion_ * fd_); }
  // Explicit memory, e.g. u_r = -fd, x0 = u0 + fd for "came down to u0 while slipping".
  void reset(double u0, double x0, double residual_force);
  double step(double u);
  // x[t] = step(u[t]) for t < n, from the present state: block by block over the whole series
  // (a block's outputs depend on its own inputs only, so they are step()'s), one dispatch per
  // block instead of one per block and sample. x may be u.
  void steps(const double* u, double* x, std::size_t n);
  double output() const { return x_; }
  double residual_force() const { return u_r_; }
  double fs() const { return fs_; }
  double fd() const { return fd_; }
  double initial_motion() const { return initial_motion_; }

 private:
  double fs_, fd_, initial_motion_;
  double u_prev_ = 0.0, x_ = 0.0, u_r_ = 0.0;
};

// Kano et al. (2004) stiction with S (deadband + stickband) and J (slip jump). The valve stops
// when the input stops or reverses (u_s = input at that instant). A stopped valve moves again
// when u has gone S past u_s against its last direction, or J past u_s along it; a moving valve
// follows x = u - d (S - J)/2, d = direction. Starting at rest with no known direction, the
// first move needs S either way.
class KanoStiction {
 public:
  KanoStiction(double S, double J);  // needs S >= J >= 0
  void reset(double u0);             // stopped at x = u0, no direction yet
  double step(double u);
  // x[t] = step(u[t]) for t < n, from the present state: block by block over the whole series
  // (a block's outputs depend on its own inputs only, so they are step()'s), one dispatch per
  // block instead of one per block and sample. x may be u.
  void steps(const double* u, double* x, std::size_t n);
  double output() const { return x_; }
  double S() const { return S_; }
  double J() const { return J_; }

 private:
  double S_, J_;
  double u_prev_ = 0.0, x_ = 0.0, u_s_ = 0.0;
  int d_ = 0;  // last moving direction, +1 / -1, 0 before the first move
  bool stopped_ = true;
};

// Choudhury, Thornhill and Shah (2005) stiction with S and J. Whenever the sign of the input
// velocity changes (including to or from zero) the valve sticks at that sample and
// x_ss = u(t-1) is stored; a stuck valve slips once |u - x_ss| > S and then follows
// x = u - sign(v) (S - J)/2. Unlike Kano's model the valve needs S again after the input pauses.
class ChoudhuryStiction {
 public:
  ChoudhuryStiction(double S, double J);  // needs S >= J >= 0
  void reset(double u0);                  // stuck at x = u0, zero velocity
  double step(double u);
  // x[t] = step(u[t]) for t < n, from the present state: block by block over the whole series
  // (a block's outputs depend on its own inputs only, so they are step()'s), one dispatch per
  // block instead of one per block and sample. x may be u.
  void steps(const double* u, double* x, std::size_t n);
  double output() const { return x_; }
  double S() const { return S_; }
  double J() const { return J_; }

 private:
  double S_, J_;
  double u_prev_ = 0.0, x_ = 0.0, x_ss_ = 0.0;
  int v_sign_prev_ = 0;
  bool stuck_ = true;
};

// Stenman et al. (2003) one-parameter stiction: x(t) = x(t-1) while |u(t) - x(t-1)| <= d,
// otherwise x(t) = u(t).
class StenmanStiction {
 public:
  explicit StenmanStiction(double d);  // needs d >= 0
  void reset(double u0) { x_ = u0; }
  double step(double u);
  // x[t] = step(u[t]) for t < n, from the present state: block by block over the whole series
  // (a block's outputs depend on its own inputs only, so they are step()'s), one dispatch per
  // block instead of one per block and sample. x may be u.
  void steps(const double* u, double* x, std::size_t n);
  double output() const { return x_; }
  double d() const { return d_; }

 private:
  double d_;
  double x_ = 0.0;
};

// He's model whose bands depend on where the valve is: fs(x) and fd(x) are piecewise linear
// over the valve position (held constant beyond the end points), evaluated at the position the
// valve sticks at. Asymmetric friction like the paper's Example 2 valve (severe near one
// opening, minor elsewhere) that no two-parameter model reproduces.
class PositionDependentStiction {
 public:
  struct Point {
    double position;  // valve position x, %
    double fs;        // static band at that position
    double fd;        // kinetic band at that position
  };
  // Needs at least one point, strictly increasing positions and fs >= fd >= 0 at every point.
  // `initial_motion` in [-1, 1] as HeStiction's, with the bands at the starting OP.
  explicit PositionDependentStiction(std::vector<Point> points, double initial_motion = 0.0);
  void reset(double u0) {
    const double r = initial_motion_ * fd_at(u0);
    reset(u0, u0 - r, r);
  }
  void reset(double u0, double x0, double residual_force);
  double step(double u);
  // x[t] = step(u[t]) for t < n, from the present state: block by block over the whole series
  // (a block's outputs depend on its own inputs only, so they are step()'s), one dispatch per
  // block instead of one per block and sample. x may be u.
  void steps(const double* u, double* x, std::size_t n);
  double output() const { return x_; }
  const std::vector<Point>& points() const { return points_; }
  double fs_at(double x) const;
  double fd_at(double x) const;
  double initial_motion() const { return initial_motion_; }

 private:
  std::vector<Point> points_;
  double initial_motion_ = 0.0;
  double u_prev_ = 0.0, x_ = 0.0, u_r_ = 0.0;
};

// Backlash with total play d: x follows u at distance d/2 while u pushes, and holds inside the
// play. A triangle input traces a parallelogram of width d without any jump.
class Deadband {
 public:
  explicit Deadband(double d);  // needs d >= 0
  void reset(double u0) { x_ = u0; }
  double step(double u);
  // x[t] = step(u[t]) for t < n, from the present state: block by block over the whole series
  // (a block's outputs depend on its own inputs only, so they are step()'s), one dispatch per
  // block instead of one per block and sample. x may be u.
  void steps(const double* u, double* x, std::size_t n);
  double output() const { return x_; }
  double d() const { return d_; }

 private:
  double d_;
  double x_ = 0.0;
};

// Travel limits: x = clamp(u, lower, upper).
class Saturation {
 public:
  Saturation(double lower, double upper);  // needs lower < upper
  void reset(double u0) { x_ = step(u0); }
  double step(double u);
  // x[t] = step(u[t]) for t < n, from the present state: block by block over the whole series
  // (a block's outputs depend on its own inputs only, so they are step()'s), one dispatch per
  // block instead of one per block and sample. x may be u.
  void steps(const double* u, double* x, std::size_t n);
  double output() const { return x_; }
  double lower() const { return lower_; }
  double upper() const { return upper_; }

 private:
  double lower_, upper_;
  double x_ = 0.0;
};

// Installed flow characteristic, a static map 0..100 % -> 0..100 % (input clamped to 0..100):
//   equal-percentage  x = 100 (R^(u/100) - 1) / (R - 1)
//   quick-opening     x = 100 ln(1 + (R - 1) u/100) / ln R   (the inverse of equal-percentage)
//   linear            x = u
// R is the rangeability (> 1). Both curved maps are monotone and fix 0 and 100.
class Characteristic {
 public:
  enum class Kind { linear, equal_percentage, quick_opening };
  Characteristic(Kind kind, double rangeability);
  void reset(double u0) { x_ = step(u0); }
  double step(double u);
  // x[t] = step(u[t]) for t < n, from the present state: block by block over the whole series
  // (a block's outputs depend on its own inputs only, so they are step()'s), one dispatch per
  // block instead of one per block and sample. x may be u.
  void steps(const double* u, double* x, std::size_t n);
  double output() const { return x_; }
  Kind kind() const { return kind_; }
  double rangeability() const { return R_; }

 private:
  Kind kind_;
  double R_;
  double x_ = 0.0;
};
std::string to_string(Characteristic::Kind kind);  // "linear", "equal-percentage", ...
// Parses the names above; throws std::invalid_argument listing them.
Characteristic::Kind characteristic_kind_from_string(const std::string& name);

// First-order actuator, tau dx/dt = u - x with u held over each sample (exact ZOH:
// x(k+1) = a x(k) + (1 - a) u(k), a = exp(-Ts/tau)). step(u(k)) returns x(k), the position at the
// sampling instant, which the new command has not moved yet. tau = 0 means no lag (x = u).
class ActuatorLag {
 public:
  ActuatorLag(double tau, double Ts);  // needs tau >= 0, Ts > 0
  void reset(double u0) { x_ = out_ = u0; }
  double step(double u);
  double output() const { return out_; }
  double tau() const { return tau_; }
  double sample_period() const { return Ts_; }

 private:
  double tau_, Ts_, a_;
  double x_ = 0.0, out_ = 0.0;  // x_: state at the next instant, out_: last returned
};

// General hysteresis: the discretized Preisach model x = gamma(u)' mu + offset
// (include/valvediag/core/preisach.hpp). reset(u0) puts the memory where u came up from umin to u0.
class PreisachValve {
 public:
  PreisachValve(PreisachGrid grid, std::vector<double> mu, double offset = 0.0);
  void reset(double u0);
  double step(double u) { return x_ = model_.step(u); }
  double output() const { return x_; }
  const PreisachModel& model() const { return model_; }

 private:
  PreisachModel model_;
  double x_ = 0.0;
};

using ValveEffect = std::variant<HeStiction, KanoStiction, ChoudhuryStiction, StenmanStiction,
                                 PositionDependentStiction, Deadband, Saturation, Characteristic,
                                 ActuatorLag, PreisachValve>;

// The effect's product name: "stiction", "deadband", "saturation", "characteristic",
// "actuator-lag" or "preisach".
std::string effect_name(const ValveEffect& effect);
// The model variant within the effect: "he", "kano", "choudhury", "stenman",
// "position-dependent" for stiction, the kind for characteristic, "" otherwise.
std::string effect_model(const ValveEffect& effect);
// One line with name, model and parameters, e.g. "stiction (he: fs=8.4, fd=3.5243)".
std::string describe(const ValveEffect& effect);

// Blocks applied in order, u -> first block -> ... -> last block -> x. Empty chain: x = u.
class ValveChain {
 public:
  ValveChain() = default;
  explicit ValveChain(std::vector<ValveEffect> effects) : effects_(std::move(effects)) {}
  // Each block at rest with the input its predecessor gives at rest; returns the rest position.
  double reset(double u0);
  double step(double u);
  // x[t] = step(u[t]) for t < n, from the present state: block by block over the whole series
  // (a block's outputs depend on its own inputs only, so they are step()'s), one dispatch per
  // block instead of one per block and sample. x may be u.
  void steps(const double* u, double* x, std::size_t n);
  double output() const { return x_; }
  const std::vector<ValveEffect>& effects() const { return effects_; }
  std::vector<ValveEffect>& effects() { return effects_; }

 private:
  std::vector<ValveEffect> effects_;
  double x_ = 0.0;
};

}  // namespace valvediag
