// Loop-health figures engineers know from loop-monitoring tools, computed from OP/PV/SP alone
// (no model): oscillation and its period, OP reversals and travel per hour, time at the OP
// limits; and whether a record can carry a model at all.
#pragma once

#include <cstddef>
#include <string>
#include <vector>

#include "valvediag/core/op_range.hpp"
#include "valvediag/io/loop_data.hpp"

namespace valvediag {

struct LoopHealth {
  std::size_t samples = 0;
  double duration_s = 0.0;
  // Oscillation of the control error (SP - PV, or PV without SP; OP when PV was not recorded),
  // about its straight line over the record, detected from the zero crossings of its
  // autocorrelation (Thornhill, Huang and Zhang 2003): regular when the spread of the half-periods
  // is small against their mean (regularity > 1).
  bool oscillating = false;
  double period_s = 0.0;    // 0 when no period is found
  double regularity = 0.0;  // mean half-period / (3 std of half-periods); > 1: regular
  double amplitude = 0.0;   // of that signal about its line: sqrt(2) x RMS (a sine's amplitude)
  std::string signal;       // "sp-pv", "pv" or "op": what was analysed
  double op_reversals_per_hour = 0.0;       // direction changes beyond the OP noise band
  double op_travel_percent_per_hour = 0.0;  // OP path length, % of the OP range per hour
  double time_at_limits_percent = 0.0;      // OP within 0.5 % of the range of either end
  double op_noise = 0.0;                    // OP noise level used as the reversal band, OP units
  double op_span_percent = 0.0;             // max - min of OP, % of the range
};

// `range`: the valve's OP span (site config); data outside it count as at the limit.
LoopHealth loop_health(const LoopData& d, const OpRange& range = {});

// Why a record cannot carry a model, or "" when it can: no PV recorded, too few samples, OP not
// moving (span within its noise, or fewer than 2 reversals), OP at its limits nearly all the
// time, PV flat, or an OP that visits too few levels to identify the Preisach weights (paper
// section 5). A spike comes first, named (spike_in): it would otherwise end as one of those.
std::string unusable_reason(const LoopData& d, const LoopHealth& h, std::size_t min_samples = 200);

}  // namespace valvediag
