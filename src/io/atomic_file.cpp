#include "valvediag/io/atomic_file.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <filesystem>
#include <random>
#include <stdexcept>
#include <system_error>

namespace valvediag {

namespace {

std::string reason(int err) {
  return std::generic_category().message(err);
}

std::string folder_of(const std::string& path) {
  const std::filesystem::path p(path);
  return p.has_parent_path() ? p.parent_path().string() : std::string(".");
}

}  // namespace

AtomicFile::AtomicFile(std::string path) : path_(std::move(path)) {
  if (path_.empty()) throw std::runtime_error("no file name to write");
  std::random_device rd;
  std::mt19937_64 rng((static_cast<std::uint64_t>(rd()) << 32) ^ rd());
  // A fresh name each try: O_EXCL refuses anything already there, links included.
  for (int attempt = 0; attempt < 16; ++attempt) {
    char suffix[24];
    std::snprintf(suffix, sizeof suffix, ".%012llx.tmp",
                  static_cast<unsigned long long>(rng() & 0xffffffffffffULL));
    tmp_ = path_ + suffix;
    fd_ = ::open(tmp_.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_NOFOLLOW | O_CLOEXEC, 0666);
    if (fd_ >= 0) return;
    const int err = errno;
    if (err != EEXIST)
      throw std::runtime_error("cannot write " + path_ + ": " + reason(err) + " (is its folder " +
                               folder_of(path_) + " there and writable?)");
  }
  throw std::runtime_error("cannot write " + path_ +
                           ": no free temporary name beside it (16 tries); clean its folder");
}

AtomicFile::~AtomicFile() {
  if (fd_ >= 0) ::close(fd_);
  if (!committed_ && !tmp_.empty()) ::unlink(tmp_.c_str());
}

void AtomicFile::write(std::string_view text) {
  if (fd_ < 0) throw std::runtime_error("writing " + path_ + ": the file is closed");
  while (!text.empty()) {
    const ssize_t n = ::write(fd_, text.data(), text.size());
    if (n < 0) {
      if (errno == EINTR) continue;
      throw std::runtime_error("writing " + path_ + " failed: " + reason(errno) + " (disk full?)");
    }
    text.remove_prefix(static_cast<std::size_t>(n));
  }
}

void AtomicFile::commit() {
  if (fd_ < 0) throw std::runtime_error("writing " + path_ + ": the file is closed");
  if (::fsync(fd_) != 0)
    throw std::runtime_error("writing " + path_ + " failed: " + reason(errno) + " (disk full?)");
  const int fd = fd_;
  fd_ = -1;
  if (::close(fd) != 0)
    throw std::runtime_error("writing " + path_ + " failed: " + reason(errno) + " (disk full?)");
  if (::rename(tmp_.c_str(), path_.c_str()) != 0) {
    const int err = errno;
    throw std::runtime_error("cannot replace " + path_ + ": " + reason(err) +
                             (err == EISDIR ? " (it is a folder)" : ""));
  }
  committed_ = true;
  // The rename itself on disk: the folder's entry.
  const int dir = ::open(folder_of(path_).c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (dir >= 0) {
    ::fsync(dir);
    ::close(dir);
  }
}

void write_file_atomically(const std::string& path, std::string_view text) {
  AtomicFile f(path);
  f.write(text);
  f.commit();
}

}  // namespace valvediag
