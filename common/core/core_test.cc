#include <gtest/gtest.h>

#include <tbb/parallel_for.h>

#include <atomic>

#include "common/core/parallel.h"
#include "common/core/statistics.h"
#include "common/core/status.h"

namespace instascene {
namespace {

absl::StatusOr<int> Half(int x) {
  if (x % 2 != 0) return absl::InvalidArgumentError("odd");
  return x / 2;
}

absl::Status UseHalf(int x, int* out) {
  ASSIGN_OR_RETURN(*out, Half(x));
  RETURN_IF_ERROR(absl::OkStatus());
  return absl::OkStatus();
}

TEST(StatusMacros, PropagateErrorsAndValues) {
  int v = 0;
  EXPECT_TRUE(UseHalf(8, &v).ok());
  EXPECT_EQ(v, 4);
  absl::Status s = UseHalf(3, &v);
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(Annotate(s, "x.ply").message(), "x.ply: odd");
}

TEST(Statistics, MedianOddEvenEmpty) {
  EXPECT_DOUBLE_EQ(Median({3, 1, 2}), 2.0);
  EXPECT_DOUBLE_EQ(Median({4, 1, 3, 2}), 2.5);
  EXPECT_DOUBLE_EQ(Median({}), 0.0);
}

TEST(Parallel, ArenaLimitsConcurrency) {
  int seen = RunWithThreads(1, [] { return tbb::this_task_arena::max_concurrency(); });
  EXPECT_EQ(seen, 1);
  std::atomic<int> sum{0};
  RunWithThreads(2, [&] { tbb::parallel_for(0, 100, [&](int i) { sum += i; }); });
  EXPECT_EQ(sum.load(), 4950);
}

}  // namespace
}  // namespace instascene
