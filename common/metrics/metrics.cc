#include "common/metrics/metrics.h"

#include <prometheus/exposer.h>
#include <prometheus/text_serializer.h>

#include <exception>
#include <sstream>

#include "absl/strings/str_cat.h"

namespace instascene::metrics {

namespace {
// Never destroyed: components and exposers hold references across static destruction.
std::shared_ptr<prometheus::Registry>& SharedRegistry() {
  static auto* registry =
      new std::shared_ptr<prometheus::Registry>(std::make_shared<prometheus::Registry>());
  return *registry;
}
}  // namespace

prometheus::Registry& Registry() { return *SharedRegistry(); }

const prometheus::Histogram::BucketBoundaries& RpcBuckets() {
  static const auto* b = new prometheus::Histogram::BucketBoundaries{
      0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1, 2.5, 5, 10, 30, 60};
  return *b;
}

const prometheus::Histogram::BucketBoundaries& JobBuckets() {
  static const auto* b = new prometheus::Histogram::BucketBoundaries{
      0.1, 0.5, 1, 5, 10, 30, 60, 120, 300, 600, 1800, 3600, 7200, 21600};
  return *b;
}

CallbackCollectable::CallbackCollectable(
    std::function<std::vector<prometheus::MetricFamily>()> collect)
    : collect_(std::move(collect)) {}

std::vector<prometheus::MetricFamily> CallbackCollectable::Collect() const {
  try {
    return collect_();
  } catch (const std::exception&) {
    return {};
  }
}

prometheus::MetricFamily GaugeFamily(const std::string& name, const std::string& help) {
  prometheus::MetricFamily family;
  family.name = name;
  family.help = help;
  family.type = prometheus::MetricType::Gauge;
  return family;
}

void AddGauge(prometheus::MetricFamily* family,
              const std::vector<std::pair<std::string, std::string>>& labels, double value) {
  prometheus::ClientMetric metric;
  for (const auto& [name, label_value] : labels) metric.label.push_back({name, label_value});
  metric.gauge.value = value;
  family->metric.push_back(std::move(metric));
}

absl::StatusOr<std::unique_ptr<Endpoint>> Endpoint::Start(const std::string& listen) {
  std::unique_ptr<Endpoint> endpoint(new Endpoint());
  try {
    endpoint->exposer_ = std::make_unique<prometheus::Exposer>(listen, /*num_threads=*/2);
  } catch (const std::exception& e) {
    return absl::UnavailableError(
        absl::StrCat("metrics endpoint: cannot listen on ", listen, ": ", e.what()));
  }
  endpoint->exposer_->RegisterCollectable(SharedRegistry());
  const std::vector<int> ports = endpoint->exposer_->GetListeningPorts();
  const size_t colon = listen.rfind(':');
  endpoint->address_ = absl::StrCat(colon == std::string::npos ? listen : listen.substr(0, colon),
                                    ":", ports.empty() ? 0 : ports.front());
  return endpoint;
}

Endpoint::~Endpoint() = default;

void Endpoint::Add(const std::weak_ptr<prometheus::Collectable>& collectable) {
  exposer_->RegisterCollectable(collectable);
}

std::string SerializeText(const std::vector<std::weak_ptr<prometheus::Collectable>>& extra) {
  std::vector<prometheus::MetricFamily> families = Registry().Collect();
  for (const auto& weak : extra) {
    if (auto c = weak.lock()) {
      for (auto& f : c->Collect()) families.push_back(std::move(f));
    }
  }
  return prometheus::TextSerializer().Serialize(families);
}

}  // namespace instascene::metrics
