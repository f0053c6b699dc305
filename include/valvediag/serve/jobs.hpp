// The workbench's background jobs (fit, diagnose, add an effect): a bounded queue in front of a
// few worker threads. A job reports its progress, can be cancelled (cooperatively: the fits check
// the flag, core/cancel.hpp) and keeps its result for the client to fetch. Bounded everywhere:
// the queue refuses work when full, and only the latest finished jobs are kept.
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstddef>
#include <deque>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <thread>
#include <vector>

namespace valvediag::serve {

enum class JobState { Queued, Running, Done, Failed, Cancelled };
const char* to_string(JobState s);

// What a running job sees: its cancel flag (pass it to ModelFitOptions::cancel) and where it
// reports how far it got.
class JobControl {
 public:
  const std::atomic<bool>* cancel_flag() const { return &cancel_; }
  bool cancelled() const { return cancel_.load(); }
  // fraction 0..1 and what it is doing now, e.g. "fitting stiction".
  void report(double fraction, const std::string& phase);

 private:
  friend class JobQueue;
  std::atomic<bool> cancel_{false};
  mutable std::mutex m_;
  double progress_ = 0.0;
  std::string phase_;
};

// The job's work: returns its result; throws Cancelled when cancelled, anything else to fail
// (std::invalid_argument: the message is the client's to read).
using JobWork = std::function<nlohmann::json(JobControl&)>;

struct JobLimits {
  unsigned workers = 0;            // 0: hardware_concurrency (at least 1)
  std::size_t max_queued = 16;     // waiting jobs beyond the running ones
  std::size_t max_finished = 100;  // finished jobs kept for GET; older ones are forgotten
};

class JobQueue {
 public:
  explicit JobQueue(JobLimits limits = {});
  // Cancels every job and waits for the workers.
  ~JobQueue();
  JobQueue(const JobQueue&) = delete;
  JobQueue& operator=(const JobQueue&) = delete;

  // The new job's id, or nullopt when the queue is full. `info` (action, loop) is shown with it.
  std::optional<std::string> submit(nlohmann::json info, JobWork work);
  // {"id","state","progress","phase","elapsed_s","result"|"error", ...info}; nullopt: unknown id.
  std::optional<nlohmann::json> status(const std::string& id) const;
  // Cancels a queued job at once and asks a running one to stop; a finished job is left as it
  // is. Its status after the request; nullopt: unknown id.
  std::optional<nlohmann::json> cancel(const std::string& id);
  // Cancels everything and stops the workers (the destructor does it too).
  void shutdown();
  unsigned workers() const { return static_cast<unsigned>(threads_.size()); }
  std::size_t max_queued() const { return limits_.max_queued; }

 private:
  struct Job {
    std::string id;
    nlohmann::json info;
    JobWork work;
    JobState state = JobState::Queued;
    JobControl control;
    nlohmann::json result;
    std::string error;
    std::chrono::steady_clock::time_point started, ended;
  };
  void run();
  nlohmann::json status_locked(const Job& j) const;
  void forget_old_locked();

  JobLimits limits_;
  mutable std::mutex m_;
  std::condition_variable wake_;
  bool stopping_ = false;
  std::size_t next_id_ = 1;
  std::deque<std::shared_ptr<Job>> queue_;
  std::map<std::string, std::shared_ptr<Job>> jobs_;
  std::deque<std::string> finished_;  // ids in the order they finished
  std::vector<std::thread> threads_;
};

}  // namespace valvediag::serve
