// common/core/testing/files.h: small file helpers for tests: deterministic random bytes and a
// count of the regular files under a directory (to check that nothing was left behind).
#pragma once

#include <cstdint>
#include <filesystem>
#include <random>
#include <string>

namespace instascene::testing {

inline std::string RandomBytes(size_t n, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::string s(n, '\0');
  for (char& c : s) c = static_cast<char>(rng() & 0xff);
  return s;
}

// Regular files under `dir`, not counting lock files (a store or queue holds `.lock` while open).
inline size_t CountFiles(const std::filesystem::path& dir) {
  size_t n = 0;
  for (const auto& e : std::filesystem::recursive_directory_iterator(dir))
    n += e.is_regular_file() && e.path().filename() != ".lock" && e.path().extension() != ".lock";
  return n;
}

}  // namespace instascene::testing
