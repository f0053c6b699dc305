#include "isolated_jobs.hpp"

#include <poll.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <iostream>
#include <stdexcept>
#include <vector>

namespace valvediag::cli {

namespace {

using Clock = std::chrono::steady_clock;

struct Running {
  std::size_t job = 0;
  pid_t pid = -1;
  int fd = -1;
  Clock::time_point started, deadline;
  std::string data;
  bool eof = false;
};

// The child: run the job, send 'O' + output or 'E' + message, leave without running the
// parent's destructors or atexit handlers (they belong to the parent's state).
[[noreturn]] void child(int fd, std::size_t job,
                        const std::function<std::string(std::size_t)>& work) {
  std::string msg(1, 'O');
  try {
    msg.append(work(job));
  } catch (const std::exception& e) {
    msg.assign(1, 'E');
    msg.append(e.what());
  } catch (...) {
    msg.assign("Eunknown error");
  }
  const char* p = msg.data();
  std::size_t left = msg.size();
  while (left > 0) {
    const ssize_t n = ::write(fd, p, left);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) ::_exit(3);
    p += n;
    left -= static_cast<std::size_t>(n);
  }
  ::close(fd);
  ::_exit(0);
}

JobOutcome finish(Running& r, bool killed, const char* why) {
  int status = 0;
  while (::waitpid(r.pid, &status, 0) < 0 && errno == EINTR) {
  }
  ::close(r.fd);
  JobOutcome o;
  o.elapsed_s = std::chrono::duration<double>(Clock::now() - r.started).count();
  if (killed) {
    o.status = std::strcmp(why, "cancelled") == 0 ? JobOutcome::Status::Cancelled
                                                  : JobOutcome::Status::TimedOut;
    o.message = why;
  } else if (WIFSIGNALED(status)) {
    o.status = JobOutcome::Status::Crashed;
    o.signal = WTERMSIG(status);
    o.message = std::string("the analysis crashed (signal ") + std::to_string(WTERMSIG(status)) +
                ", " + strsignal(WTERMSIG(status)) + ")";
  } else if (r.data.empty() || (r.data[0] != 'O' && r.data[0] != 'E')) {
    o.status = JobOutcome::Status::Crashed;
    o.message = "the analysis ended without a result (exit status " +
                std::to_string(WIFEXITED(status) ? WEXITSTATUS(status) : -1) + ")";
  } else if (r.data[0] == 'E') {
    o.status = JobOutcome::Status::Failed;
    o.message = r.data.substr(1);
  } else {
    o.output = r.data.substr(1);
  }
  return o;
}

}  // namespace

void run_isolated(std::size_t count, int parallel, double timeout_s,
                  const std::function<std::string(std::size_t)>& work,
                  const std::function<void(std::size_t, const JobOutcome&)>& done,
                  const std::atomic<bool>* stop) {
  parallel = std::max(parallel, 1);
  const auto limit = std::chrono::duration_cast<Clock::duration>(
      std::chrono::duration<double>(std::max(timeout_s, 0.001)));
  std::vector<Running> running;
  std::size_t next = 0;
  auto stopping = [&] { return stop && stop->load(); };
  while (next < count || !running.empty()) {
    while (next < count && static_cast<int>(running.size()) < parallel && !stopping()) {
      int fds[2];
      if (::pipe(fds) != 0)
        throw std::runtime_error(std::string("cannot create a pipe: ") + std::strerror(errno));
      std::cout.flush();
      std::cerr.flush();
      std::fflush(nullptr);  // or the child would repeat buffered output
      const pid_t parent = ::getpid();
      const pid_t pid = ::fork();
      if (pid < 0) {
        ::close(fds[0]);
        ::close(fds[1]);
        throw std::runtime_error(std::string("cannot start a process: ") + std::strerror(errno));
      }
      if (pid == 0) {
        // The job dies with its parent: a sweep killed at its own time limit (or by kill -9)
        // must not leave a job running, e.g. a .mat read stuck in libmatio.
        ::prctl(PR_SET_PDEATHSIG, SIGKILL);
        if (::getppid() != parent) ::_exit(3);  // the parent died before prctl
        ::close(fds[0]);
        for (const auto& r : running) ::close(r.fd);
        child(fds[1], next, work);
      }
      ::close(fds[1]);
      Running r;
      r.job = next++;
      r.pid = pid;
      r.fd = fds[0];
      r.started = Clock::now();
      r.deadline = r.started + limit;
      running.push_back(std::move(r));
    }
    if (running.empty()) break;  // stopped before starting more
    // Wait for output, an end, or the nearest deadline (at most 200 ms: the stop flag).
    auto now = Clock::now();
    auto nearest = running.front().deadline;
    for (const auto& r : running) nearest = std::min(nearest, r.deadline);
    const auto wait_ms = std::clamp<long long>(
        std::chrono::duration_cast<std::chrono::milliseconds>(nearest - now).count(), 0, 200);
    std::vector<pollfd> pfds;
    for (const auto& r : running) pfds.push_back({r.fd, POLLIN, 0});
    const int n = ::poll(pfds.data(), pfds.size(), static_cast<int>(wait_ms));
    if (n < 0 && errno != EINTR)
      throw std::runtime_error(std::string("poll failed: ") + std::strerror(errno));
    for (std::size_t i = 0; i < running.size(); ++i) {
      if (n <= 0 || !(pfds[i].revents & (POLLIN | POLLHUP | POLLERR))) continue;
      char buf[65536];
      const ssize_t got = ::read(running[i].fd, buf, sizeof buf);
      if (got > 0)
        running[i].data.append(buf, static_cast<std::size_t>(got));
      else if (got == 0 || errno != EINTR)
        running[i].eof = true;
    }
    now = Clock::now();
    const bool cancel = stopping();
    for (std::size_t i = 0; i < running.size();) {
      Running& r = running[i];
      const bool late = now >= r.deadline;
      if (r.eof || late || cancel) {
        if (!r.eof) ::kill(r.pid, SIGKILL);
        const JobOutcome o = finish(r, !r.eof, cancel && !late ? "cancelled" : "time limit");
        const std::size_t job = r.job;
        running.erase(running.begin() + static_cast<std::ptrdiff_t>(i));
        done(job, o);
      } else {
        ++i;
      }
    }
  }
}

}  // namespace valvediag::cli
