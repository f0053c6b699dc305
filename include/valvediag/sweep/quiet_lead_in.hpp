// A quiet lead-in: a record whose OP holds still for most of its length before the loop moves.
//
// Why: friction shows only where OP moves. The diagnosis learns on the first part of a record and
// scores on the rest; a loop at steady state until a set-point change near the end of the window
// gives a first part of noise alone and a last part with every event. No trial can learn a
// friction band there, and on the whole record the noise of the long steady state outweighs the
// few minutes that show the valve. An engineer cuts such a record to where things happen; this
// does it by a rule: when OP stays within a quarter of its span of its starting level for more
// than half of the record, the analysis starts a little before OP leaves it. The pre-roll (a
// quarter of the moving part) seeds the model at the operating point before the first move.
// Standard library only.
#pragma once

#include <cstddef>
#include <string>
#include <vector>

#include "valvediag/io/loop_data.hpp"

namespace valvediag {

struct QuietLeadInOptions {
  double level_share = 0.25;      // OP within this share of its span of the starting level: quiet
  double min_share = 0.5;         // a lead-in shorter than this share of the record is kept
  double pre_roll_share = 0.25;   // samples kept before the departure, as a share of the rest
  std::size_t min_samples = 200;  // the analysed part is never shorter (nor the record cut)
};

struct QuietLeadIn {
  std::size_t departure = 0;  // first sample where OP leaves its starting level (size: never)
  std::size_t begin = 0;      // first sample to analyse; 0: the whole record
  bool cut() const { return begin > 0; }
};

// The starting level is the median of the first 2 % of samples (at least 10). Records shorter
// than 2 * min_samples, or with a constant OP, are never cut.
QuietLeadIn quiet_lead_in(const std::vector<double>& op, const QuietLeadInOptions& opt = {});

// The samples [begin, size) of every series of d (t keeps its values).
LoopData drop_lead_in(const LoopData& d, std::size_t begin);

// One sentence for notes and reasons, e.g. "the analysis starts at t = 5290 s (sample 530 of
// 751): before t = 5730 s OP holds within a quarter of its span of where it started, which shows
// nothing of the valve". t: the record's time stamps; times are given as t - origin.
std::string describe_lead_in(const QuietLeadIn& q, const std::vector<double>& t,
                             double origin = 0.0);

}  // namespace valvediag
