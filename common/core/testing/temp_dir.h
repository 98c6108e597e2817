// common/core/testing/temp_dir.h: a scratch directory per test that removes itself. ctest runs
// every test case as its own process, in parallel, and several builds may test at once on one
// machine, so the name is unique per process and object; the directory lives under gtest's
// TempDir() ($TEST_TMPDIR or $TMPDIR), and nothing is left behind when the object goes away.
#pragma once

#include <gtest/gtest.h>
#include <unistd.h>

#include <atomic>
#include <filesystem>
#include <string>

namespace instascene::testing {

class ScopedTempDir {
 public:
  explicit ScopedTempDir(std::string name = "test") {
    static std::atomic<int> counter{0};
    for (char& c : name)
      if (c == '/') c = '_';  // parameterised test names contain slashes
    path_ = std::filesystem::path(::testing::TempDir()) /
            (name + "_" + std::to_string(::getpid()) + "_" + std::to_string(counter++));
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
    std::filesystem::create_directories(path_, ec);
  }
  ~ScopedTempDir() {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  ScopedTempDir(const ScopedTempDir&) = delete;
  ScopedTempDir& operator=(const ScopedTempDir&) = delete;

  const std::filesystem::path& path() const { return path_; }
  std::string str() const { return path_.string(); }
  // path() / relative, as a string.
  std::string Sub(const std::string& relative) const { return (path_ / relative).string(); }

 private:
  std::filesystem::path path_;
};

}  // namespace instascene::testing
