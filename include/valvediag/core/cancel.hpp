// Cooperative cancellation of a long fit (the workbench's jobs, issue 36): the caller owns an
// atomic flag and passes its address in the options; the fits check it between units of work
// (a structure of identify(), an evaluation of a valve search) and throw Cancelled once it is set.
#pragma once

#include <atomic>
#include <stdexcept>

namespace valvediag {

struct Cancelled : std::runtime_error {
  Cancelled() : std::runtime_error("cancelled") {}
};

// Throws Cancelled when `flag` is set; a null flag never cancels.
inline void throw_if_cancelled(const std::atomic<bool>* flag) {
  if (flag && flag->load(std::memory_order_relaxed)) throw Cancelled();
}

}  // namespace valvediag
