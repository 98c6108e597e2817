// common/core/file_lock.h: an exclusive advisory lock on a file (flock), held for the lifetime of
// the object: one process owns a store folder or a queue file; a second one is refused at start
// instead of silently sharing it. Released when the process exits, also on a crash.
#pragma once

#include <string>

#include "absl/status/statusor.h"

namespace instascene {

class FileLock {
 public:
  // Creates `path` if needed and locks it. FailedPrecondition when another process holds it.
  static absl::StatusOr<FileLock> Acquire(const std::string& path, const std::string& what);
  FileLock(FileLock&& other) noexcept : fd_(other.fd_) { other.fd_ = -1; }
  FileLock& operator=(FileLock&& other) noexcept;
  FileLock(const FileLock&) = delete;
  FileLock& operator=(const FileLock&) = delete;
  ~FileLock();

 private:
  explicit FileLock(int fd) : fd_(fd) {}
  int fd_ = -1;
};

}  // namespace instascene
