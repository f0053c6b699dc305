// A file written whole or not at all, never through a planted link: every file valvediag writes
// for the user (results, model history, simulated records, pages) goes through it.
#pragma once

#include <string>
#include <string_view>

namespace valvediag {

// Writes into an exclusive temporary file beside `path` (created with O_EXCL and O_NOFOLLOW
// under a fresh name, so a link or file planted there is never written through), then commit()
// flushes it to disk and renames it over `path`. Not committed (an error, an exception), the
// temporary file is removed and `path` is untouched. A link at `path` itself is replaced, not
// followed. Errors throw std::runtime_error naming the file and what to check.
class AtomicFile {
 public:
  explicit AtomicFile(std::string path);
  AtomicFile(const AtomicFile&) = delete;
  AtomicFile& operator=(const AtomicFile&) = delete;
  ~AtomicFile();

  void write(std::string_view text);
  void commit();
  const std::string& temporary_path() const { return tmp_; }

 private:
  std::string path_, tmp_;
  int fd_ = -1;
  bool committed_ = false;
};

// The whole text through an AtomicFile.
void write_file_atomically(const std::string& path, std::string_view text);

}  // namespace valvediag
