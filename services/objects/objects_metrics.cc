#include "services/objects/objects_metrics.h"

#include "common/metrics/metrics.h"

namespace instascene::objects {
namespace {

prometheus::Family<prometheus::Counter>& Loads() {
  static auto& f =
      prometheus::BuildCounter()
          .Name("instascene_objects_index_loads_total")
          .Help("Scene indexes loaded from the store by the Objects service, by outcome")
          .Register(metrics::Registry());
  return f;
}

prometheus::Histogram& LoadSeconds() {
  static auto& h =
      prometheus::BuildHistogram()
          .Name("instascene_objects_index_load_seconds")
          .Help("Time to load a scene's index (splat, labels, k-d tree) from the store")
          .Register(metrics::Registry())
          .Add({}, metrics::RpcBuckets());
  return h;
}

prometheus::Counter& Hits() {
  static auto& c = prometheus::BuildCounter()
                       .Name("instascene_objects_index_hits_total")
                       .Help("Objects queries answered from an index already in the cache")
                       .Register(metrics::Registry())
                       .Add({});
  return c;
}

prometheus::Gauge& CacheBytes() {
  static auto& g = prometheus::BuildGauge()
                       .Name("instascene_objects_index_cache_bytes")
                       .Help("Bytes of the scene indexes the Objects service holds in memory")
                       .Register(metrics::Registry())
                       .Add({});
  return g;
}

prometheus::Gauge& CacheEntries() {
  static auto& g = prometheus::BuildGauge()
                       .Name("instascene_objects_index_cache_entries")
                       .Help("Scene indexes the Objects service holds (loaded or loading)")
                       .Register(metrics::Registry())
                       .Add({});
  return g;
}

}  // namespace

void RegisterIndexMetrics() {
  Loads().Add({{"outcome", "ok"}});
  Loads().Add({{"outcome", "failed"}});
  LoadSeconds();
  Hits();
  CacheBytes();
  CacheEntries();
}

void RecordIndexLoad(double seconds, bool ok) {
  Loads().Add({{"outcome", ok ? "ok" : "failed"}}).Increment();
  LoadSeconds().Observe(seconds);
}

void RecordIndexHit() { Hits().Increment(); }

void SetIndexCache(int64_t entries, int64_t bytes) {
  CacheEntries().Set(static_cast<double>(entries));
  CacheBytes().Set(static_cast<double>(bytes));
}

}  // namespace instascene::objects
