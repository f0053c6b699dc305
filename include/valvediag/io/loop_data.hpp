// Time-aligned samples of one control loop: the common currency of readers, the simulator,
// the recorder and the identification core.
#pragma once

#include <limits>
#include <string>
#include <vector>

namespace valvediag {

struct LoopData {
  std::vector<double> t;   // seconds, strictly increasing
  std::vector<double> op;  // controller output u, % (input of the valve)
  std::vector<double> pv;  // process variable y (empty: OP alone, as in a benchmark .mat loop)
  std::vector<double> sp;  // set point (empty when not available)
  std::vector<double> mv;  // measured valve position x (empty when not available)
  std::string source;      // where the data came from (file name, scenario), for messages
  // The loop's tag when the data names it: historian columns 2111FIC46005.MV and
  // 2111FIC46005.PV name loop 2111FIC46005. Empty otherwise.
  std::string tag;
  // The date and time of t = 0 as seconds since 1970-01-01 00:00:00 of the stamps as the data
  // gives them (a historian's local time read without zone, a recording's UTC); NaN when the
  // data has no date-time stamps. Plots and tables show t on this clock.
  double clock_at_zero_s = std::numeric_limits<double>::quiet_NaN();

  std::size_t size() const { return t.size(); }
  bool has_pv() const { return !pv.empty(); }
  bool has_sp() const { return !sp.empty(); }
  bool has_mv() const { return !mv.empty(); }
  // Sample period from the first two time stamps (0 when fewer than two samples).
  double sample_period() const { return t.size() >= 2 ? t[1] - t[0] : 0.0; }
};

}  // namespace valvediag
