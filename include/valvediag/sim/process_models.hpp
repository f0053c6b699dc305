// Linear process models between valve position x (%) and PV y, discretized exactly for a
// valve position held constant over each sample (zero-order hold), including dead times that
// are not a multiple of the sample period.
#pragma once

#include <Eigen/Dense>
#include <deque>
#include <string>

namespace valvediag {

enum class ProcessType {
  first_order,  // K e^{-theta s} / (tau s + 1)
  // K e^{-theta s} / ((tau s + 1)(tau2 s + 1)), or K wn^2 e^{-theta s} / (s^2 + 2 zeta wn s +
  // wn^2); with tau3 > 0 a third lag (tau3 s + 1) in series (a process with more lags than the
  // usual second-order ARX fit carries)
  second_order,
  integrating,  // K e^{-theta s} / s, or with a lag K e^{-theta s} / (s (tau s + 1)) when tau > 0
};
std::string to_string(ProcessType type);  // "first-order", "second-order", "integrating"
// Parses the names above; throws std::invalid_argument listing them.
ProcessType process_type_from_string(const std::string& name);

// The process acts on deviations from the valve position the loop starts at rest with:
// PV = pv0 + G(s) (x - x_rest). For an integrating process x_rest is the balance position.
struct ProcessSpec {
  ProcessType type = ProcessType::first_order;
  double gain = 1.0;       // K; integrating: PV units per second per % of valve position
  double tau = 1.0;        // s; second order: first time constant; integrating: lag, 0 = none
  double tau2 = 0.0;       // s; second order: second time constant (used when wn == 0)
  double tau3 = 0.0;       // s; second order, tau form: optional third lag, 0 = none
  double wn = 0.0;         // rad/s; second order: wn > 0 selects the wn/zeta form
  double zeta = 1.0;       // second order damping in the wn/zeta form
  double dead_time = 0.0;  // s, any value >= 0
  double pv0 = 0.0;        // PV at the initial steady state
};

ProcessSpec first_order_process(double gain, double tau, double dead_time, double pv0 = 0.0);
ProcessSpec second_order_process(double gain, double tau1, double tau2, double dead_time,
                                 double pv0 = 0.0);
ProcessSpec second_order_process_wn(double gain, double wn, double zeta, double dead_time,
                                    double pv0 = 0.0);
ProcessSpec integrating_process(double gain, double dead_time, double lag = 0.0, double pv0 = 0.0);
// One line, e.g. "first-order: K=3.8163, tau=156.46 s, theta=2.5 s".
std::string describe(const ProcessSpec& spec);

// The discretized process. With theta = n Ts + eps, 0 <= eps < Ts, the delayed held input
// switches inside each sample period, so
//   s(k+1) = Phi s(k) + Gamma0 u(k-n-1) + Gamma1 u(k-n),   y(k) = pv0 + C s(k)
//   Phi = e^{A Ts},  Gamma1 = int_0^{Ts-eps} e^{A r} dr B,
//   Gamma0 = e^{A (Ts-eps)} int_0^eps e^{A r} dr B.
class DiscreteProcess {
 public:
  DiscreteProcess(const ProcessSpec& spec, double Ts);  // throws std::invalid_argument
  // Steady state with valve position x_rest held since t = -infinity: PV = pv0.
  void reset(double x_rest);
  double output() const;   // PV at the current sampling instant (depends on earlier inputs only)
  void advance(double x);  // hold x for one sample period and move to the next instant
  const ProcessSpec& spec() const { return spec_; }
  double sample_period() const { return Ts_; }
  int delay_samples() const { return n_; }          // n
  double fractional_delay() const { return eps_; }  // eps, s

 private:
  ProcessSpec spec_;
  double Ts_;
  int n_ = 0;
  double eps_ = 0.0;
  Eigen::MatrixXd Phi_;
  Eigen::VectorXd Gamma0_, Gamma1_;
  Eigen::RowVectorXd C_;
  Eigen::VectorXd s_;
  std::deque<double> inputs_;  // u(k-n-1), ..., u(k) as deviations from x_rest
  double x_rest_ = 0.0;
};

}  // namespace valvediag
