// The stiction quantification's result (stiction_quantification.hpp): He's figures and the summary
// sentence, as the probe's fit and the refinement on the data report them. Private to src/core.
#pragma once

#include <limits>
#include <string>

#include "valvediag/core/stiction_quantification.hpp"

namespace valvediag::detail {

inline constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

// He's figures of (fs, fd); the fit from the cost and the variance it is to explain.
StictionFigures figures(double fs, double fd, double cost, double var);
// Every figure NaN: not measured.
StictionFigures unmeasured();

// The summary of a valid quantification: "stiction: fs .. % of travel (...) over OP lo-hi %", or
// that no stiction is resolved. `span`: "" when OP is in %, else " of the OP span lo:hi"
// (in_percent_of_span), said after the figures' range in place of " %".
std::string stiction_sentence(const StictionQuantification& q, const std::string& span = "");

}  // namespace valvediag::detail
