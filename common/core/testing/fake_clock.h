// common/core/testing/fake_clock.h: a manually advanced clock for tests of leases, backoff and
// retention. Thread-safe.
#pragma once

#include <atomic>

#include "common/core/clock.h"

namespace instascene::testing {

class FakeClock final : public Clock {
 public:
  explicit FakeClock(int64_t start_ms = 1'000'000) : now_(start_ms) {}
  int64_t NowMs() override { return now_.load(); }
  void Advance(int64_t ms) { now_ += ms; }

 private:
  std::atomic<int64_t> now_;
};

}  // namespace instascene::testing
