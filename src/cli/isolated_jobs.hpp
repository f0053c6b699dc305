// Runs independent jobs each in its own child process, a few at once, each with a time limit:
// one loop that hangs, crashes or exhausts memory costs only its own result, never the sweep.
// The caller must be single-threaded when it calls run_isolated (fork copies only the calling
// thread); each child may start threads of its own.
#pragma once

#include <atomic>
#include <cstddef>
#include <functional>
#include <string>

namespace valvediag::cli {

struct JobOutcome {
  enum class Status { Ok, Failed, TimedOut, Crashed, Cancelled };
  Status status = Status::Ok;
  std::string output;   // what the job returned (Ok)
  std::string message;  // why not Ok: the exception text, the signal, the time limit
  int signal = 0;       // Crashed: the signal that ended the child (0: it exited without result)
  double elapsed_s = 0.0;
};

// work(i) runs in a child and returns the text sent back (exceptions: Failed with their text).
// done(i, outcome) runs in the parent as each job ends, in completion order. Stops starting
// jobs when `stop` is set and kills the running ones (Cancelled).
void run_isolated(std::size_t count, int parallel, double timeout_s,
                  const std::function<std::string(std::size_t)>& work,
                  const std::function<void(std::size_t, const JobOutcome&)>& done,
                  const std::atomic<bool>* stop = nullptr);

}  // namespace valvediag::cli
