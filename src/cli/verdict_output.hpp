// The loop's one verdict (loop_verdict.hpp) as the commands print and write it: fit --verdict,
// diagnose, report, demo (the sweep writes it through its assessment).
#pragma once

#include <nlohmann/json.hpp>
#include <string>

#include "valvediag/sweep/loop_verdict.hpp"

namespace valvediag::cli {

// The verdict's options from a command's: the sweep's, with the held-out share, the valve's OP
// span, --keep-lead-in and --min-gain; the reason's times on the data's own axis (t0: the time
// stamp of its first sample).
VerdictOptions verdict_options(const OpRange& range, double validate, bool keep_lead_in, double t0,
                               double min_gain_percent = 2.0);

// What the verdict rests on, one sentence, for a command that shows another analysis beside it;
// why there is none when the analysis failed; "" for a record that cannot be judged (its reason
// is the verdict's).
std::string verdict_basis(const LoopVerdict& v);

// The size line, "stiction:  8.41 % of valve travel (He's fs), slip jump 4.86 %; ...\n"; "" when
// the verdict has no size.
std::string stiction_text(const FrictionSize& f);

// "verdict:   WORD" (with the reason when the record cannot be judged), what it rests on (with
// `basis`) and the size line.
std::string verdict_text(const LoopVerdict& v, bool basis);

// Writes the verdict's keys: verdict, verdict_reason, verdict_model, stiction_percent,
// slip_jump_percent, stiction_lo_percent, stiction_hi_percent, stiction_hi_open, split_check.
void add_verdict_json(nlohmann::json& j, const LoopVerdict& v);

}  // namespace valvediag::cli
