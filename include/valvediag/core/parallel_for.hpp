// Independent jobs shared out over worker threads: the one thread pool of the identification,
// the model fits and the stiction quantification.
#pragma once

#include <algorithm>
#include <atomic>
#include <cstddef>
#include <exception>
#include <mutex>
#include <thread>
#include <vector>

namespace valvediag {

// Worker threads for `jobs` independent jobs: `threads` (0: all cores), at most one per job.
inline unsigned worker_count(int threads, std::size_t jobs) {
  const unsigned n = threads > 0 ? static_cast<unsigned>(threads)
                                 : std::max(1u, std::thread::hardware_concurrency());
  return static_cast<unsigned>(std::clamp<std::size_t>(jobs, 1, n));
}

// job(worker, i) for every i < n, on `workers` threads (the caller's is worker 0), each taking
// the next job when it is free. A job's result must not depend on which worker ran it. The first
// exception stops the remaining jobs and is rethrown once all workers have stopped.
template <class Job>
void parallel_for(std::size_t n, unsigned workers, Job&& job) {
  std::atomic<std::size_t> next{0};
  std::exception_ptr error;
  std::mutex m;
  auto work = [&](unsigned w) {
    try {
      for (std::size_t i; (i = next.fetch_add(1)) < n;) job(w, i);
    } catch (...) {
      const std::lock_guard<std::mutex> lock(m);
      if (!error) error = std::current_exception();
      next = n;
    }
  };
  std::vector<std::thread> pool;
  for (unsigned w = 1; w < workers; ++w) pool.emplace_back(work, w);
  work(0);
  for (auto& t : pool) t.join();
  if (error) std::rethrow_exception(error);
}

}  // namespace valvediag
