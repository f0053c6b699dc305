// Checks on LoopData from any source (reader, simulator, recorder) before it is used.
// Failures throw DataError with the data's source as the file name.
#pragma once

#include <cstddef>
#include <string>
#include <string_view>

#include "valvediag/io/loop_data.hpp"

namespace valvediag {

// The largest magnitude a signal (OP, PV, SP, MV) may have: no instrument reports 1e12 in any
// unit, but historians write 1e308, 3.4e38 or -9.99e37 for a bad value, and numbers that large
// overflow the estimators' squares and searches (a hang, measured). A cell beyond it is refused.
inline constexpr double kMaxSignalMagnitude = 1e12;
// The reason a signal value cannot be used ("" when it can): NaN, infinite, or beyond
// kMaxSignalMagnitude, with what to do. `shown`: the value as the user wrote it (a cell's text,
// quoted), else the number.
std::string signal_value_problem(double v, std::string_view shown = {});

// Consistent series lengths (sp and mv empty or full length), usable signal values
// (signal_value_problem), finite and strictly increasing time.
void check_loop_data(const LoopData& data);

// check_loop_data, then at least min_samples samples (model names the model that needs them,
// for the message) and non-constant OP and PV: a flat signal carries nothing to identify.
void check_identifiable_data(const LoopData& data, std::size_t min_samples,
                             std::string_view model = {});

}  // namespace valvediag
