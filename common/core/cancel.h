// common/core/cancel.h: cooperative cancellation. The caller owns a CancelFlag and sets it from any
// thread; long-running library functions poll it between units of work (a view, a step) and return
// absl::CancelledError. Libraries take `const CancelFlag*` (nullptr = not cancellable).
#pragma once

#include <atomic>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"

namespace instascene {

using CancelFlag = std::atomic<bool>;

inline bool IsCancelled(const CancelFlag* flag) {
  return flag != nullptr && flag->load(std::memory_order_relaxed);
}

inline absl::Status CheckCancelled(const CancelFlag* flag, absl::string_view where) {
  if (IsCancelled(flag)) return absl::CancelledError(absl::StrCat(where, ": cancelled"));
  return absl::OkStatus();
}

}  // namespace instascene
