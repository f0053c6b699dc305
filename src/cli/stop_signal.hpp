// Ctrl-C / SIGTERM for the long-running commands (record, sim-plc): the first signal asks for a
// clean stop, which the command polls; SIGPIPE is ignored (a closed socket is an error code).
#pragma once

#include <atomic>

namespace valvediag::cli {

// Installs the handlers; returns the flag the first SIGINT/SIGTERM sets.
std::atomic<bool>& install_stop_signals();

}  // namespace valvediag::cli
