// Oscillations, and the limit-cycle test for a sticky valve (Horch 1999), from OP/PV alone and
// the OP-driven output of a fitted model. Standard library and Eigen only.
//
// Why the phase tells: with the set point steady, the oscillating part of OP is the controller
// acting on PV, OP = -C PV, so the phase of PV against OP at the cycle's frequency is
// -180 deg - arg C. A stick-slip cycle is slow against the integral time (the integral action
// has to wind OP through the friction band before the valve moves), so C acts as an integrator
// and PV lies about 90 deg from OP: an odd OP-PV cross-correlation. A linear loop that oscillates
// because it is tuned too tightly crosses -180 deg where the proportional action counts: PV lies
// near 180 deg (or 0) from OP, an even cross-correlation. The test is Horch's; it holds for
// self-regulating processes (an integrator adds its own 90 deg). A slow oscillation from outside
// the loop is compensated by an integrating controller too, and a model fitted in closed loop
// reproduces it from OP (it learns the inverse controller), so the phase alone cannot tell it
// from stick-slip: the test also wants the trial fits (scored on estimation and held-out data)
// to support a valve with memory, and no memoryless explanation (more lags, a load) to be
// clearly better than it. Known blind spots: a stick-slip cycle fast against the integral time
// looks even; an outside cycle that a memory model fits as well as any linear one passes.
#pragma once

#include <limits>
#include <string>
#include <vector>

namespace valvediag {

// A regular oscillation of a signal, from the zero crossings of its autocorrelation
// (Thornhill, Huang and Zhang 2003): regular when the spread of the half-periods is small
// against their mean (regularity = mean half-period / (3 std) > 1), the autocorrelation one period
// on is above 0.2, and the half-period is at least 2 samples.
struct Oscillation {
  bool oscillating = false;
  double period_samples = 0.0;  // 0 when no period is found
  double regularity = 0.0;
  double acf_peak = 0.0;  // the autocorrelation's first positive peak after one period
};
Oscillation detect_oscillation(const std::vector<double>& x);

// Robust sigma of a signal's white noise, from its second differences (sqrt(6) sigma for white
// noise); the median keeps steps and ramps out of it.
double noise_sigma(const std::vector<double>& x);

struct LimitCycle {
  static constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
  bool oscillating = false;  // PV oscillates regularly
  double period_s = 0.0;
  double op_amplitude = kNaN;  // OP's amplitude at the cycle's frequency, OP units
  double phase_deg = kNaN;     // phase of PV against OP at that frequency, (-180, 180]
  // Share of PV's cycle (complex amplitude at the cycle's frequency) that the model driven by OP
  // reproduces: 1 - |Y - Y_model| / |Y|. 1: all of it; <= 0: none.
  double model_share = kNaN;
  double memory_gain = kNaN;  // best gain of a trial with memory (stiction, preisach), points
  std::string rival;          // a memoryless effect clearly better than the memory ("" if none)
  bool integrating = false;   // the process integrates: the test does not apply
  bool odd = false;           // PV within 45 deg of +-90 deg from OP (Horch: stick-slip)
  bool stick_slip = false;    // the cycle is a sticky valve's: the verdict may rest on it
  // Apparent stiction (Choudhury, Shah and Thornhill 2006): the width of the OP-PV ellipse
  // along OP at PV's mean, 2 A_op |sin phase|, OP units; NaN without a cycle.
  double apparent_band = kNaN;
  std::string summary;  // one sentence: what was found and why it counts or not
};

struct LimitCycleOptions {
  double min_model_share = 0.5;         // OP must drive at least half of PV's cycle
  double min_memory_gain = 2.0;         // points, as DiagnoseOptions::min_gain_percent
  double min_op_amplitude_noise = 2.0;  // OP's cycle amplitude over its noise sigma
};

// What the trial fits say (diagnosis.hpp), in fitness points over the memoryless start model.
struct TrialEvidence {
  double start_fitness = std::numeric_limits<double>::quiet_NaN();  // the start model's, %
  double memory_gain = std::numeric_limits<double>::quiet_NaN();    // best stiction/preisach trial
  double rival_gain = std::numeric_limits<double>::quiet_NaN();     // best other trial
  std::string rival;                                                // its effect
};

// u: OP, y: PV, y_model: the fitted model's output simulated from OP (same length; empty or
// non-finite: the share is unknown and the test does not decide), Ts: s. Gains are the smaller
// of the estimation and held-out gains; NaN: unknown, the test does not decide. The rival is
// clearly better when it removes a fifth of the error the memory trial leaves (the diagnosis's
// own rule).
LimitCycle limit_cycle_test(const std::vector<double>& u, const std::vector<double>& y,
                            const std::vector<double>& y_model, double Ts, bool integrating,
                            const TrialEvidence& trials, const LimitCycleOptions& opt = {});

}  // namespace valvediag
