#include "valvediag/serve/jobs.hpp"

#include <algorithm>
#include <exception>
#include <stdexcept>

#include "valvediag/core/cancel.hpp"

namespace valvediag::serve {

const char* to_string(JobState s) {
  switch (s) {
    case JobState::Queued:
      return "queued";
    case JobState::Running:
      return "running";
    case JobState::Done:
      return "done";
    case JobState::Failed:
      return "failed";
    case JobState::Cancelled:
      return "cancelled";
  }
  return "unknown";
}

void JobControl::report(double fraction, const std::string& phase) {
  std::lock_guard<std::mutex> lock(m_);
  progress_ = std::clamp(fraction, 0.0, 1.0);
  phase_ = phase;
}

JobQueue::JobQueue(JobLimits limits) : limits_(limits) {
  unsigned n = limits_.workers;
  if (n == 0) n = std::max(1u, std::thread::hardware_concurrency());
  for (unsigned i = 0; i < n; ++i) threads_.emplace_back([this] { run(); });
}

JobQueue::~JobQueue() {
  shutdown();
}

void JobQueue::shutdown() {
  {
    std::lock_guard<std::mutex> lock(m_);
    stopping_ = true;
    for (auto& [id, j] : jobs_) {
      j->control.cancel_ = true;
      if (j->state == JobState::Queued) j->state = JobState::Cancelled;
    }
    queue_.clear();
  }
  wake_.notify_all();
  for (auto& t : threads_)
    if (t.joinable()) t.join();
}

std::optional<std::string> JobQueue::submit(nlohmann::json info, JobWork work) {
  std::lock_guard<std::mutex> lock(m_);
  if (stopping_ || queue_.size() >= limits_.max_queued) return std::nullopt;
  auto j = std::make_shared<Job>();
  j->id = std::to_string(next_id_++);
  j->info = std::move(info);
  j->work = std::move(work);
  jobs_[j->id] = j;
  queue_.push_back(j);
  wake_.notify_one();
  return j->id;
}

void JobQueue::run() {
  for (;;) {
    std::shared_ptr<Job> j;
    {
      std::unique_lock<std::mutex> lock(m_);
      wake_.wait(lock, [&] { return stopping_ || !queue_.empty(); });
      if (stopping_) return;
      j = queue_.front();
      queue_.pop_front();
      j->state = JobState::Running;
      j->started = std::chrono::steady_clock::now();
    }
    JobState end = JobState::Done;
    nlohmann::json result;
    std::string error;
    try {
      result = j->work(j->control);
      // Asked to stop after its last check: the client said it does not want the result.
      if (j->control.cancelled()) end = JobState::Cancelled;
    } catch (const Cancelled&) {
      end = JobState::Cancelled;
    } catch (const std::exception& e) {
      end = JobState::Failed;
      error = e.what();
    } catch (...) {
      end = JobState::Failed;
      error = "internal error";
    }
    std::lock_guard<std::mutex> lock(m_);
    j->state = end;
    j->ended = std::chrono::steady_clock::now();
    if (end == JobState::Done) j->result = std::move(result);
    if (end == JobState::Failed) j->error = error.empty() ? "failed" : error;
    j->work = nullptr;  // its captures (data copies) go now, not when the job is forgotten
    finished_.push_back(j->id);
    forget_old_locked();
  }
}

void JobQueue::forget_old_locked() {
  while (finished_.size() > limits_.max_finished) {
    jobs_.erase(finished_.front());
    finished_.pop_front();
  }
}

nlohmann::json JobQueue::status_locked(const Job& j) const {
  nlohmann::json s = j.info.is_object() ? j.info : nlohmann::json::object();
  s["id"] = j.id;
  s["state"] = to_string(j.state);
  {
    std::lock_guard<std::mutex> lock(j.control.m_);
    s["progress"] = j.state == JobState::Done ? 1.0 : j.control.progress_;
    s["phase"] = j.control.phase_;
  }
  const auto now = std::chrono::steady_clock::now();
  const bool ended = j.state == JobState::Done || j.state == JobState::Failed ||
                     (j.state == JobState::Cancelled && j.ended.time_since_epoch().count() != 0);
  s["elapsed_s"] = j.state == JobState::Queued || j.started.time_since_epoch().count() == 0
                       ? 0.0
                       : std::chrono::duration<double>((ended ? j.ended : now) - j.started).count();
  if (j.state == JobState::Running && j.control.cancelled()) s["cancel_requested"] = true;
  if (j.state == JobState::Done) s["result"] = j.result;
  if (j.state == JobState::Failed) s["error"] = j.error;
  return s;
}

std::optional<nlohmann::json> JobQueue::status(const std::string& id) const {
  std::lock_guard<std::mutex> lock(m_);
  const auto it = jobs_.find(id);
  if (it == jobs_.end()) return std::nullopt;
  return status_locked(*it->second);
}

std::optional<nlohmann::json> JobQueue::cancel(const std::string& id) {
  std::lock_guard<std::mutex> lock(m_);
  const auto it = jobs_.find(id);
  if (it == jobs_.end()) return std::nullopt;
  Job& j = *it->second;
  if (j.state == JobState::Queued) {
    queue_.erase(std::remove(queue_.begin(), queue_.end(), it->second), queue_.end());
    j.state = JobState::Cancelled;
    j.work = nullptr;
    finished_.push_back(j.id);
    const nlohmann::json s = status_locked(j);
    forget_old_locked();
    return s;
  }
  if (j.state == JobState::Running) j.control.cancel_ = true;
  return status_locked(j);
}

}  // namespace valvediag::serve
