// services/worker/input_cache.h: the worker's on-disk cache of materialised inputs (scenes and
// dependency outputs, one directory per manifest digest). Entries are evicted least recently used
// first when the cache exceeds its byte budget; entries the current job needs are never evicted.
// Not thread-safe: one cache directory belongs to one worker loop.
#pragma once

#include <cstdint>
#include <set>
#include <string>
#include <vector>

#include "absl/status/statusor.h"

namespace instascene::worker {

struct EvictionReport {
  int64_t bytes_before = 0, bytes_after = 0;
  std::vector<std::string> evicted;  // directories removed, oldest first
};

// Marks an entry as used now (its directory's modification time is the LRU clock).
void TouchCacheEntry(const std::string& directory);

// Removes the least recently used entries (immediate subdirectories of each of `roots`) until the
// total size is at most `budget_bytes` (0 = unlimited), never those in `keep`.
absl::StatusOr<EvictionReport> EvictCache(const std::vector<std::string>& roots,
                                          int64_t budget_bytes, const std::set<std::string>& keep);

}  // namespace instascene::worker
