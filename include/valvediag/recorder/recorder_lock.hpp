// One recorder per database. Two would poll the PLC twice and interleave their runs, so a
// recorder holds an flock on the side file DB.lock for its lifetime. The kernel drops the lock
// when the process ends, however it ends (kill -9, power cut), so a file left by a dead recorder
// never blocks the next one; the file names its holder for the refusal message and is removed
// when the recorder ends. A run is `recording` only while this lock is held for it.
#pragma once

#include <cstdint>
#include <optional>
#include <stdexcept>
#include <string>

namespace valvediag {

// Who holds a database's recorder lock, as its lock file says.
struct LockHolder {
  long pid = 0;  // 0: the holder has not written its name yet (it is starting)
  std::string host, started_utc;
  std::int64_t run = 0;  // 0: no run begun yet
};

// A second recorder on a database being recorded; the message names the running one.
class DatabaseInUseError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// "DB.lock" beside the database (symbolic links to the database resolved first, so every path
// to one file shares one lock).
std::string recorder_lock_path(const std::string& db_path);

class RecorderLock {
 public:
  // Takes the lock (creating the file) or throws DatabaseInUseError naming the holder;
  // std::runtime_error when the file cannot be created.
  explicit RecorderLock(const std::string& db_path);
  ~RecorderLock();
  RecorderLock(const RecorderLock&) = delete;
  RecorderLock& operator=(const RecorderLock&) = delete;
  void set_run(std::int64_t run);  // named in the file once the run exists

 private:
  void write_holder();
  std::string path_;
  int fd_ = -1;
  LockHolder me_;
};

// The recorder holding `db_path`'s lock, or nullopt when none does. Reads only: creates no file
// and never blocks a recorder that is starting.
std::optional<LockHolder> recorder_holding(const std::string& db_path);

}  // namespace valvediag
