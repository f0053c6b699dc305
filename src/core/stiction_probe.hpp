// The probe of the stiction quantification (stiction_quantification.hpp): an input the identified
// Preisach valve is driven with, its response, and where the input reverses. Private to src/core.
#pragma once

#include <vector>

#include "valvediag/core/hammerstein.hpp"

namespace valvediag::detail {

// The probe: an input, the identified valve's response to it, and which samples count: all
// `scored` samples in the overall fit; in a region's fit the samples within a window of OP
// travel after a reversal (turning point) that lies in the region.
struct Probe {
  std::vector<double> u, x;
  std::vector<double> uq;  // u on the grid: the level centre the Preisach model sees
  std::vector<char> scored;
  std::vector<int> reversal;       // index into reversal_u of the last turning point, -1: none
  std::vector<double> since;       // OP travel since that turning point
  std::vector<double> reversal_u;  // OP at each turning point
  double longest_sweep = 0.0;      // largest OP travel between turning points (or to the ends)
};

// Synthetic probe over levels lo..hi (no data): the major loop, then first-order reversal curves
// (FORCs) at every level, both ways, one level per sample.
Probe forc_probe(const HammersteinModel& m, int lo, int hi);

// The data as the probe: the identified model is only known on inputs like the data (a limit
// cycle identifies only 2L - 1 weight combinations, Proposition 3), so the valve is probed with
// the data's own OP. Turning points with a hysteresis of half a grid step (OP noise is not a
// reversal). The first samples, until the OP has travelled the visited range, are not scored:
// He's initial state is unknown until the valve has slipped once.
Probe data_probe(const HammersteinModel& m, const std::vector<double>& op, double width);

}  // namespace valvediag::detail
