#include "valvediag/sim/process_models.hpp"

#include <cmath>
#include <stdexcept>

#include "valvediag/util/text_stats.hpp"

namespace valvediag {
namespace {

// Matrix exponential by scaling and squaring with a Taylor series. The matrices here are at
// most 3 x 3 with modest norms, where this is accurate to rounding and needs no library beyond
// Eigen's core module.
Eigen::MatrixXd expm(const Eigen::MatrixXd& M) {
  const double norm = M.cwiseAbs().colwise().sum().maxCoeff();
  int squarings = 0;
  if (norm > 0.5) squarings = static_cast<int>(std::ceil(std::log2(norm / 0.5)));
  const Eigen::MatrixXd X = M / std::ldexp(1.0, squarings);
  const auto n = M.rows();
  Eigen::MatrixXd E = Eigen::MatrixXd::Identity(n, n);
  Eigen::MatrixXd term = Eigen::MatrixXd::Identity(n, n);
  // ||X|| <= 0.5: 30 terms leave a remainder far below double precision.
  for (int k = 1; k <= 30; ++k) {
    term = term * X / static_cast<double>(k);
    E += term;
  }
  for (int i = 0; i < squarings; ++i) E = E * E;
  return E;
}

struct Zoh {
  Eigen::MatrixXd Ah;  // e^{A h}
  Eigen::VectorXd Bh;  // int_0^h e^{A r} dr B
};

// Both blocks from one exponential of the augmented matrix [[A, B], [0, 0]] h.
Zoh zoh(const Eigen::MatrixXd& A, const Eigen::VectorXd& B, double h) {
  const auto n = A.rows();
  Eigen::MatrixXd M = Eigen::MatrixXd::Zero(n + 1, n + 1);
  M.topLeftCorner(n, n) = A * h;
  M.topRightCorner(n, 1) = B * h;
  const Eigen::MatrixXd E = expm(M);
  return {E.topLeftCorner(n, n), E.topRightCorner(n, 1)};
}

bool positive(double v) {
  return std::isfinite(v) && v > 0.0;
}

}  // namespace

std::string to_string(ProcessType type) {
  switch (type) {
    case ProcessType::first_order:
      return "first-order";
    case ProcessType::second_order:
      return "second-order";
    case ProcessType::integrating:
      return "integrating";
  }
  return "?";
}

ProcessType process_type_from_string(const std::string& name) {
  for (auto t : {ProcessType::first_order, ProcessType::second_order, ProcessType::integrating}) {
    if (to_string(t) == name) return t;
  }
  throw std::invalid_argument("process: unknown type '" + name +
                              "' (known: first-order, second-order, integrating)");
}

ProcessSpec first_order_process(double gain, double tau, double dead_time, double pv0) {
  ProcessSpec s;
  s.type = ProcessType::first_order;
  s.gain = gain;
  s.tau = tau;
  s.dead_time = dead_time;
  s.pv0 = pv0;
  return s;
}

ProcessSpec second_order_process(double gain, double tau1, double tau2, double dead_time,
                                 double pv0) {
  ProcessSpec s = first_order_process(gain, tau1, dead_time, pv0);
  s.type = ProcessType::second_order;
  s.tau2 = tau2;
  return s;
}

ProcessSpec second_order_process_wn(double gain, double wn, double zeta, double dead_time,
                                    double pv0) {
  ProcessSpec s = first_order_process(gain, 0.0, dead_time, pv0);
  s.type = ProcessType::second_order;
  s.wn = wn;
  s.zeta = zeta;
  return s;
}

ProcessSpec integrating_process(double gain, double dead_time, double lag, double pv0) {
  ProcessSpec s = first_order_process(gain, lag, dead_time, pv0);
  s.type = ProcessType::integrating;
  return s;
}

std::string describe(const ProcessSpec& s) {
  std::string d = to_string(s.type) + ": K=" + num10g(s.gain);
  switch (s.type) {
    case ProcessType::first_order:
      d += ", tau=" + num10g(s.tau) + " s";
      break;
    case ProcessType::second_order:
      if (s.wn > 0.0) {
        d += ", wn=" + num10g(s.wn) + " rad/s, zeta=" + num10g(s.zeta);
      } else {
        d += ", tau1=" + num10g(s.tau) + " s, tau2=" + num10g(s.tau2) + " s";
        if (s.tau3 > 0.0) d += ", tau3=" + num10g(s.tau3) + " s";
      }
      break;
    case ProcessType::integrating:
      if (s.tau > 0.0) d += ", lag=" + num10g(s.tau) + " s";
      break;
  }
  return d + ", theta=" + num10g(s.dead_time) + " s";
}

DiscreteProcess::DiscreteProcess(const ProcessSpec& spec, double Ts) : spec_(spec), Ts_(Ts) {
  if (!positive(Ts)) throw std::invalid_argument("process: needs a sample period Ts > 0");
  if (!std::isfinite(spec.gain)) throw std::invalid_argument("process: gain must be finite");
  if (!std::isfinite(spec.dead_time) || spec.dead_time < 0.0) {
    throw std::invalid_argument("process: needs dead_time >= 0");
  }
  if (!std::isfinite(spec.pv0)) throw std::invalid_argument("process: pv0 must be finite");

  // Continuous state space dx/dt = A x + B u, y = C x (u, y deviations from the rest point).
  Eigen::MatrixXd A;
  Eigen::VectorXd B;
  const double K = spec.gain;
  switch (spec.type) {
    case ProcessType::first_order:
      if (!positive(spec.tau)) throw std::invalid_argument("process (first-order): needs tau > 0");
      A = Eigen::MatrixXd::Constant(1, 1, -1.0 / spec.tau);
      B = Eigen::VectorXd::Constant(1, K / spec.tau);
      C_ = Eigen::RowVectorXd::Ones(1);
      break;
    case ProcessType::second_order:
      if (spec.wn > 0.0) {
        if (!std::isfinite(spec.wn) || !std::isfinite(spec.zeta) || spec.zeta < 0.0) {
          throw std::invalid_argument("process (second-order): needs finite wn > 0, zeta >= 0");
        }
        // x1 = y, x2 = dy/dt.
        A.resize(2, 2);
        A << 0.0, 1.0, -spec.wn * spec.wn, -2.0 * spec.zeta * spec.wn;
        B.resize(2);
        B << 0.0, K * spec.wn * spec.wn;
        C_.resize(2);
        C_ << 1.0, 0.0;
      } else {
        if (!positive(spec.tau) || !positive(spec.tau2)) {
          throw std::invalid_argument(
              "process (second-order): needs tau > 0 and tau2 > 0 (or wn > 0 and zeta)");
        }
        if (!std::isfinite(spec.tau3) || spec.tau3 < 0.0) {
          throw std::invalid_argument("process (second-order): needs tau3 >= 0 (0: no third lag)");
        }
        // Lags in series: x1 after the first, x2 after the second, x3 after the optional third;
        // y is the last.
        const int n = spec.tau3 > 0.0 ? 3 : 2;
        A = Eigen::MatrixXd::Zero(n, n);
        A(0, 0) = -1.0 / spec.tau;
        A(1, 0) = 1.0 / spec.tau2;
        A(1, 1) = -1.0 / spec.tau2;
        if (n == 3) {
          A(2, 1) = 1.0 / spec.tau3;
          A(2, 2) = -1.0 / spec.tau3;
        }
        B = Eigen::VectorXd::Zero(n);
        B(0) = K / spec.tau;
        C_ = Eigen::RowVectorXd::Zero(n);
        C_(n - 1) = 1.0;
      }
      break;
    case ProcessType::integrating:
      if (!std::isfinite(spec.tau) || spec.tau < 0.0) {
        throw std::invalid_argument("process (integrating): needs lag tau >= 0");
      }
      if (spec.tau > 0.0) {
        A.resize(2, 2);
        A << -1.0 / spec.tau, 0.0, K, 0.0;
        B.resize(2);
        B << 1.0 / spec.tau, 0.0;
        C_.resize(2);
        C_ << 0.0, 1.0;
      } else {
        A = Eigen::MatrixXd::Zero(1, 1);
        B = Eigen::VectorXd::Constant(1, K);
        C_ = Eigen::RowVectorXd::Ones(1);
      }
      break;
  }

  // theta = n Ts + eps. Snap eps that is rounding noise away from 0 or Ts, so that e.g.
  // theta = 0.3, Ts = 0.1 gives n = 3, eps = 0 rather than n = 2, eps = 0.0999...
  const double ratio = spec.dead_time / Ts;
  double n = std::floor(ratio);
  double frac = ratio - n;
  if (frac > 1.0 - 1e-9) {
    n += 1.0;
    frac = 0.0;
  } else if (frac < 1e-9) {
    frac = 0.0;
  }
  if (n > 1e7) throw std::invalid_argument("process: dead time too long for the sample period");
  n_ = static_cast<int>(n);
  eps_ = frac * Ts;

  const Zoh full = zoh(A, B, Ts);
  Phi_ = full.Ah;
  const Zoh late = zoh(A, B, Ts - eps_);  // u(k-n) acts over [kTs + eps, (k+1)Ts)
  Gamma1_ = late.Bh;
  const Zoh early = zoh(A, B, eps_);  // u(k-n-1) acts over [kTs, kTs + eps)
  Gamma0_ = late.Ah * early.Bh;
  reset(0.0);
}

void DiscreteProcess::reset(double x_rest) {
  x_rest_ = x_rest;
  s_ = Eigen::VectorXd::Zero(Phi_.rows());
  inputs_.assign(static_cast<std::size_t>(n_) + 1, 0.0);
}

double DiscreteProcess::output() const {
  return spec_.pv0 + C_.dot(s_);
}

void DiscreteProcess::advance(double x) {
  inputs_.push_back(x - x_rest_);
  // inputs_ now holds u(k-n-1) ... u(k): n + 2 values.
  const double u_now = inputs_[1];   // u(k-n)
  const double u_prev = inputs_[0];  // u(k-n-1)
  s_ = Phi_ * s_ + Gamma0_ * u_prev + Gamma1_ * u_now;
  inputs_.pop_front();
}

}  // namespace valvediag
