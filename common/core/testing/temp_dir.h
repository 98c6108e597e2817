// common/core/testing/temp_dir.h: a fresh, per-process scratch directory for tests. ctest runs
// every test case as its own process, in parallel, and several builds may test at once on one
// machine: a fixed path under /tmp would be shared between them.
#pragma once

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <string>

namespace instascene::testing {

// <gtest TempDir>/<name>_<pid>, emptied and created.
inline std::string FreshTempDir(const std::string& name) {
  namespace fs = std::filesystem;
  const fs::path dir = fs::path(::testing::TempDir()) / (name + "_" + std::to_string(::getpid()));
  std::error_code ec;
  fs::remove_all(dir, ec);
  fs::create_directories(dir, ec);
  return dir.string();
}

}  // namespace instascene::testing
