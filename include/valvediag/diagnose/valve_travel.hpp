// The valve-travel test: when the valve's position (MV) is recorded, friction is read from
// OP -> MV directly, with no process in between.
//
// Smart positioners report the travel, and the recorder stores it as `mv`. OP against MV is the
// valve signature itself, so the test does not depend on closed-loop identification: a load, an
// extra process lag or a disturbance the controller fights cannot pose as friction. Two models of
// the positioner are fitted to MV over the estimation part of the record (the first 70 %) and
// scored on both parts:
//   follow:   MV = p(lag_tau(OP)) (a healthy valve: the actuator's first-order lag, and p the
//             calibration, a cubic: positioners characterise, transmitters are not linear);
//   friction: MV = p(lag_tau(He(OP; fs, fd))) (He's stiction, valve_effects.hpp; fd = fs is
//             backlash without a jump, fd = 0 a jump onto OP).
// Both clip at travel limits MV rests on. The valve has friction when the friction model removes
// `min_error_share` of the RMS error the follow model leaves, on both parts, and its band reaches
// `min_band_percent` of travel (a positioner's resolution); the slip jump fs - fd then tells
// stiction from deadband. A valve that does not move while OP sweeps well beyond MV's noise
// is called stuck (or its transmitter dead). Otherwise the valve follows OP: no friction, whatever
// a closed-loop model with memory suggests.
#pragma once

#include <cstddef>
#include <limits>
#include <string>
#include <vector>

#include "valvediag/core/op_range.hpp"

namespace valvediag {

struct ValveTravelOptions {
  OpRange op_range;                  // the valve's OP span: % of travel
  double validation_fraction = 0.3;  // last part held out
  std::size_t min_samples = 200;
  int map_degree = 3;       // travel -> transmitted position: a polynomial (1: gain and offset)
  double max_lag_s = 60.0;  // actuator time constants searched: 0 .. this
  double min_error_share = 0.2;         // of follow's RMS error that friction removes, both parts
  double min_band_percent = 0.5;        // band at least this share of travel (resolution)
  double deadband_jump_fraction = 0.1;  // slip jump below this share of the band: backlash
  double stuck_op_noise = 10.0;         // OP span over MV noise that a stuck valve must ignore
  int threads = 0;                      // worker threads of the searches (0: all cores)
};

struct ValveTravel {
  static constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
  bool tested = false;   // MV present and usable
  bool decided = false;  // tested and conclusive: `verdict` is the valve's
  // stiction, deadband, or no-valve-problem (the valve follows OP); "" when not decided.
  std::string verdict;
  // He's figures of the friction fit, % of travel: fs, and the slip jump fs - fd.
  double fs_percent = kNaN, fd_percent = kNaN, jump_percent = kNaN;
  double lag_s = kNaN, gain = kNaN;  // the chosen model's actuator lag and calibration gain
  double mv_noise = kNaN;            // MV's noise (robust sigma of white noise), MV units
  double follow_fitness_percent = kNaN, follow_validation_fitness_percent = kNaN;
  double friction_fitness_percent = kNaN, friction_validation_fitness_percent = kNaN;
  // Share of the follow model's RMS error the friction model removes (estimation, held out).
  double error_share = kNaN, validation_error_share = kNaN;
  std::string summary;  // one plain sentence: what the test found, or why it did not run
};

// op, mv: same length, sample period Ts (s). Never throws for bad data: `tested` false and the
// summary says what is wrong with MV.
ValveTravel check_valve_travel(const std::vector<double>& op, const std::vector<double>& mv,
                               double Ts, const ValveTravelOptions& opt = {});

}  // namespace valvediag
