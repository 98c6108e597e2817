// common/metrics/metrics.h: Prometheus metrics for every service (issue 16, "Monitoring").
// prometheus-cpp from Debian provides the metric types, the text-format serializer and the HTTP
// exposer (CivetWeb); this file adds the one process-wide registry components register their
// families on, collectables computed at scrape time (queue and store statistics are read when
// Prometheus asks, not maintained), the bucket layouts, and the /metrics endpoint.
// Names and units follow the Prometheus conventions: `instascene_` prefix, `_seconds`, `_bytes`,
// `_total`. Thread-safe.
#pragma once

#include <functional>
#include <memory>
#include <string>
#include <vector>

#include <prometheus/collectable.h>
#include <prometheus/counter.h>
#include <prometheus/family.h>
#include <prometheus/gauge.h>
#include <prometheus/histogram.h>
#include <prometheus/metric_family.h>
#include <prometheus/registry.h>

#include "absl/status/statusor.h"

namespace prometheus {
class Exposer;
}

namespace instascene::metrics {

// The process-wide registry (created on first use, never destroyed).
prometheus::Registry& Registry();

// Bucket boundaries: RPC latencies (1 ms .. 60 s) and job durations / queue waits (0.1 s .. 6 h).
const prometheus::Histogram::BucketBoundaries& RpcBuckets();
const prometheus::Histogram::BucketBoundaries& JobBuckets();

// A collectable whose families are computed by `collect` on every scrape. A failing collect
// (e.g. the queue's database unreachable) yields no families, never an exception.
class CallbackCollectable : public prometheus::Collectable {
 public:
  explicit CallbackCollectable(std::function<std::vector<prometheus::MetricFamily>()> collect);
  std::vector<prometheus::MetricFamily> Collect() const override;

 private:
  std::function<std::vector<prometheus::MetricFamily>()> collect_;
};

// Builders for scrape-time families: one gauge family with labelled values.
prometheus::MetricFamily GaugeFamily(const std::string& name, const std::string& help);
void AddGauge(prometheus::MetricFamily* family,
              const std::vector<std::pair<std::string, std::string>>& labels, double value);

// Serves GET /metrics on `listen` (host:port; port 0 = any free port) with the process registry
// and every collectable added. UnavailableError when the address cannot be bound.
class Endpoint {
 public:
  static absl::StatusOr<std::unique_ptr<Endpoint>> Start(const std::string& listen);
  ~Endpoint();
  // Collectables must outlive the endpoint (or be removed by expiring their shared_ptr).
  void Add(const std::weak_ptr<prometheus::Collectable>& collectable);
  std::string address() const { return address_; }  // with the bound port

 private:
  Endpoint() = default;
  std::unique_ptr<prometheus::Exposer> exposer_;
  std::string address_;
};

// The text exposition format of the registry plus `extra` (what /metrics answers).
std::string SerializeText(const std::vector<std::weak_ptr<prometheus::Collectable>>& extra = {});

}  // namespace instascene::metrics
