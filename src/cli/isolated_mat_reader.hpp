// MAT-files read in a child process. libmatio (and libhdf5 under it, for v7.3) can crash or loop
// forever on a damaged file; a researcher's .mat file is untrusted input. Read in a child with a
// time limit, such a file costs a clear DataError, never the command (or the sweep).
// The caller must be single-threaded (run_isolated forks).
#pragma once

#include <string>
#include <vector>

#include "valvediag/io/mat_reader.hpp"

namespace valvediag::cli {

// Reading a loop record takes well under a second; a minute means libmatio is stuck.
inline constexpr double kMatReadTimeoutS = 60.0;

// As list_mat_loops / read_mat_loop (mat_reader.hpp), same results and same DataErrors; a crash
// or a time-out in the child is a DataError naming the file and what to do.
MatFileInfo list_mat_loops_isolated(const std::string& path, double timeout_s = kMatReadTimeoutS);
LoopData read_mat_loop_isolated(const std::string& path, const std::string& loop,
                                const MatOptions& options = {},
                                std::vector<std::string>* notes = nullptr,
                                double timeout_s = kMatReadTimeoutS);

}  // namespace valvediag::cli
