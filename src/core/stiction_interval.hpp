// How well the data fix the refined figures: the profile-likelihood interval of (fs, fd)
// (StictionInterval) and each region's fs range. Private to src/core.
#pragma once

#include <cstdint>
#include <unordered_map>
#include <utility>
#include <vector>

#include "stiction_data_fit.hpp"
#include "valvediag/core/stiction_quantification.hpp"

namespace valvediag::detail {

// A scored band (fs, fd) of the refinement's search.
struct Candidate {
  double cost, fs, fd;
};
// Candidates scored with their own equation-error poles too, whichever cost is lower: at `delay`
// (< 0: not), with `fallback` where those come out unstable; `known`: such costs already
// computed, by position fingerprint.
struct OwnPoles {
  int delay;
  const std::vector<double>& fallback;
  const std::unordered_map<std::uint64_t, double>& known;
};
// The lattice (fs, fd) = (best.fs + i step, best.fd + j step) within 0 <= fd <= fs <= width; it
// starts as the box of half-width `half` around the best.
struct Lattice {
  double step, half, width;
};

// The profile-likelihood interval of (fs, fd) around `best` (StictionInterval). `fit` holds the
// best's linear part. A side of the lattice's box that holds a candidate within the threshold is
// moved out by `half`, until the lattice's limits or the point budget. The search's other
// polished valleys (`valleys`) count too: within the threshold they fit as well, however far from
// the best (on real loops the cost is nearly flat across quite different bands).
StictionInterval profile_interval(const HeDataFit& fit, Candidate best, const OwnPoles& own_poles,
                                  const std::vector<Candidate>& valleys, const Lattice& lattice,
                                  const StictionQuantificationOptions& opt);

// One region's fs range (StictionRegion::fs_lo, fs_hi): from the refined bands, that region's fs
// walks out from its value (walk_profile, a lattice step first), its fd the best of the 9 lattice
// points around the previous point's; `limit`: the largest cost inside.
std::pair<double, double> region_interval(const HeDataFit& fit, const std::vector<Band>& bands,
                                          int r, double best, double limit, double h, double width,
                                          const StictionQuantificationOptions& opt);

}  // namespace valvediag::detail
