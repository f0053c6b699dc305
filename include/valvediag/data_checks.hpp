// Checks on LoopData from any source (reader, simulator, recorder) before it is used.
// Failures throw DataError with the data's source as the file name.
#pragma once

#include <cstddef>
#include <string_view>

#include "valvediag/loop_data.hpp"

namespace valvediag {

// Consistent series lengths (sp and mv empty or full length), finite values, strictly
// increasing time.
void check_loop_data(const LoopData& data);

// check_loop_data, then at least min_samples samples (model names the model that needs them,
// for the message) and non-constant OP and PV: a flat signal carries nothing to identify.
void check_identifiable_data(const LoopData& data, std::size_t min_samples,
                             std::string_view model = {});

}  // namespace valvediag
