// common/core/clock.h: wall-clock time in milliseconds since the Unix epoch behind an interface,
// so that leases, backoff and retention can be tested with a fake clock. Thread-safe.
#pragma once

#include <cstdint>

namespace instascene {

class Clock {
 public:
  virtual ~Clock() = default;
  virtual int64_t NowMs() = 0;
};

// The system clock (a process-wide instance).
Clock* RealClock();

}  // namespace instascene
