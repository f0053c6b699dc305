#include "valvediag/recorder/recorder_lock.hpp"

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <sstream>
#include <thread>

#include "valvediag/util/utc_time.hpp"

namespace valvediag {

namespace {

bool same_file(int fd, const std::string& path) {
  struct stat a {
  }, b{};
  return ::fstat(fd, &a) == 0 && ::stat(path.c_str(), &b) == 0 && a.st_dev == b.st_dev &&
         a.st_ino == b.st_ino;
}

LockHolder read_holder(int fd) {
  char buf[1024];
  const ssize_t n = ::pread(fd, buf, sizeof buf - 1, 0);
  LockHolder h;
  std::istringstream in(std::string(buf, n > 0 ? static_cast<std::size_t>(n) : 0));
  std::string key;
  while (in >> key) {
    if (key == "pid")
      in >> h.pid;
    else if (key == "host")
      in >> h.host;
    else if (key == "started")
      in >> h.started_utc;
    else if (key == "run")
      in >> h.run;
  }
  return h;
}

std::string describe(const LockHolder& h, const std::string& db, const std::string& lock) {
  if (h.pid == 0)
    return db + " is being recorded by another valvediag recorder that is starting (lock file " +
           lock + "); wait for it, stop it, or record into another --db";
  std::string m = db + " is being recorded by valvediag pid " + std::to_string(h.pid) +
                  " on host " + h.host + " since " + h.started_utc;
  if (h.run > 0) m += " (run " + std::to_string(h.run) + ")";
  return m + "; a second recorder would poll the PLC twice: stop that one first (Ctrl-C, or kill " +
         std::to_string(h.pid) + " on " + h.host + ") or record into another --db";
}

}  // namespace

std::string recorder_lock_path(const std::string& db_path) {
  std::error_code ec;
  const auto p = std::filesystem::weakly_canonical(db_path, ec);
  return (ec ? db_path : p.string()) + ".lock";
}

RecorderLock::RecorderLock(const std::string& db_path) : path_(recorder_lock_path(db_path)) {
  // A reader's probe (recorder_holding) holds a shared lock for an instant: try for a second.
  const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(1);
  for (;;) {
    const int fd = ::open(path_.c_str(), O_RDWR | O_CREAT | O_NOFOLLOW | O_CLOEXEC, 0644);
    if (fd < 0)
      throw std::runtime_error(path_ +
                               ": cannot create the recorder's lock file: " + std::strerror(errno) +
                               " (check the database's directory is writable)");
    struct stat st {};
    if (::fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) {
      ::close(fd);
      throw std::runtime_error(path_ +
                               ": the recorder's lock file is not a regular file; remove it");
    }
    if (::flock(fd, LOCK_EX | LOCK_NB) == 0) {
      if (same_file(fd, path_)) {
        fd_ = fd;
        break;
      }
      ::close(fd);  // removed by a recorder that just ended: lock the file now at the path
      continue;
    }
    const int err = errno;
    if (err != EWOULDBLOCK) {
      ::close(fd);
      throw std::runtime_error(path_ + ": cannot lock: " + std::strerror(err));
    }
    if (std::chrono::steady_clock::now() >= give_up) {
      const LockHolder h = read_holder(fd);
      ::close(fd);
      throw DatabaseInUseError(describe(h, db_path, path_));
    }
    ::close(fd);
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  me_.pid = static_cast<long>(::getpid());
  char host[256] = "?";
  if (::gethostname(host, sizeof host) != 0) std::strcpy(host, "?");
  host[sizeof host - 1] = '\0';
  me_.host = host;
  me_.started_utc = utc_timestamp();
  write_holder();
}

RecorderLock::~RecorderLock() {
  // Removed while still locked; a recorder that opened the old file sees it gone and retries.
  if (same_file(fd_, path_)) ::unlink(path_.c_str());
  ::close(fd_);
}

void RecorderLock::set_run(std::int64_t run) {
  me_.run = run;
  write_holder();
}

void RecorderLock::write_holder() {
  // Only for messages: a failure here loses nothing, the lock itself is held.
  const std::string text = "pid " + std::to_string(me_.pid) + "\nhost " + me_.host + "\nstarted " +
                           me_.started_utc + "\nrun " + std::to_string(me_.run) + "\n";
  if (::ftruncate(fd_, 0) != 0) return;
  [[maybe_unused]] const ssize_t n = ::pwrite(fd_, text.data(), text.size(), 0);
}

std::optional<LockHolder> recorder_holding(const std::string& db_path) {
  const std::string path = recorder_lock_path(db_path);
  const int fd = ::open(path.c_str(), O_RDONLY | O_NOFOLLOW | O_CLOEXEC);
  if (fd < 0) return std::nullopt;  // no recorder has it
  std::optional<LockHolder> h;
  if (::flock(fd, LOCK_SH | LOCK_NB) == 0)
    ::flock(fd, LOCK_UN);
  else if (errno == EWOULDBLOCK)
    h = read_holder(fd);
  ::close(fd);
  return h;
}

}  // namespace valvediag
