// services/objects/objects_metrics.h: what the Objects service's index cache reports to
// Prometheus (process-wide families on metrics::Registry(); one Objects service per process):
//   instascene_objects_index_loads_total{outcome="ok|failed"}  indexes loaded from the store
//   instascene_objects_index_load_seconds                      how long each load took
//   instascene_objects_index_hits_total                        queries answered from the cache
//   instascene_objects_index_cache_bytes, _cache_entries       what the cache holds now
// Thread-safe.
#pragma once

#include <cstdint>

namespace instascene::objects {

// Registers every family (at 0), so that a scrape shows them before the first query.
void RegisterIndexMetrics();
void RecordIndexLoad(double seconds, bool ok);
void RecordIndexHit();
void SetIndexCache(int64_t entries, int64_t bytes);

}  // namespace instascene::objects
