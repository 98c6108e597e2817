// common/core/timer.h: monotonic stopwatch for progress reporting and benchmarks.
// Not thread-safe; one Stopwatch per measuring thread.
#pragma once

#include <chrono>

namespace instascene {

class Stopwatch {
 public:
  Stopwatch() : start_(std::chrono::steady_clock::now()) {}
  void Restart() { start_ = std::chrono::steady_clock::now(); }
  double ElapsedMs() const {
    return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start_)
        .count();
  }
  double ElapsedSeconds() const { return ElapsedMs() / 1000.0; }

 private:
  std::chrono::steady_clock::time_point start_;
};

}  // namespace instascene
