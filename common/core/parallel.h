// common/core/parallel.h: thread-count control for TBB-parallel kernels.
//
// Every parallel kernel in the project partitions its work into fixed chunks whose results do not
// depend on which thread runs them, so the thread count only changes speed, never results.
// RunWithThreads executes a callable inside a TBB arena limited to `num_threads` (0 = all cores).
#pragma once

#include <tbb/task_arena.h>

#include <utility>

namespace instascene {

// Number of threads the default arena uses (all hardware threads unless limited by the process).
inline int DefaultThreadCount() { return tbb::this_task_arena::max_concurrency(); }

// Runs fn() with TBB parallelism limited to num_threads (0 or negative = default).
template <typename Fn>
decltype(auto) RunWithThreads(int num_threads, Fn&& fn) {
  if (num_threads <= 0) return std::forward<Fn>(fn)();
  tbb::task_arena arena(num_threads);
  return arena.execute(std::forward<Fn>(fn));
}

}  // namespace instascene
