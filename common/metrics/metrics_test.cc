#include "common/metrics/metrics.h"

#include <httplib.h>

#include <stdexcept>

#include <gtest/gtest.h>

namespace instascene::metrics {
namespace {

TEST(Metrics, EndpointServesTheRegistryAndScrapeTimeCollectables) {
  auto& counter = prometheus::BuildCounter()
                      .Name("instascene_test_events_total")
                      .Help("events seen by the test")
                      .Register(Registry())
                      .Add({{"kind", "a"}});
  counter.Increment(3);
  int scrapes = 0;
  auto gauges = std::make_shared<CallbackCollectable>([&scrapes] {
    ++scrapes;
    prometheus::MetricFamily f = GaugeFamily("instascene_test_queue", "jobs by state");
    AddGauge(&f, {{"state", "queued"}}, 4);
    AddGauge(&f, {{"state", "running"}}, 1);
    return std::vector<prometheus::MetricFamily>{f};
  });
  auto broken = std::make_shared<CallbackCollectable>(
      []() -> std::vector<prometheus::MetricFamily> { throw std::runtime_error("db down"); });
  auto endpoint = Endpoint::Start("127.0.0.1:0");
  ASSERT_TRUE(endpoint.ok()) << endpoint.status();
  (*endpoint)->Add(gauges);
  (*endpoint)->Add(broken);
  const std::string address = (*endpoint)->address();
  const int port = std::stoi(address.substr(address.rfind(':') + 1));
  ASSERT_GT(port, 0);
  httplib::Client client("127.0.0.1", port);
  auto response = client.Get("/metrics");
  ASSERT_TRUE(response);
  EXPECT_EQ(response->status, 200);
  EXPECT_NE(response->body.find("instascene_test_events_total{kind=\"a\"} 3"), std::string::npos)
      << response->body;
  EXPECT_NE(response->body.find("instascene_test_queue{state=\"queued\"} 4"), std::string::npos);
  EXPECT_NE(response->body.find("# TYPE instascene_test_queue gauge"), std::string::npos);
  EXPECT_EQ(scrapes, 1);
  EXPECT_NE(SerializeText({gauges}).find("instascene_test_queue{state=\"running\"} 1"),
            std::string::npos);
}

TEST(Metrics, RefusesAnAddressInUse) {
  auto first = Endpoint::Start("127.0.0.1:0");
  ASSERT_TRUE(first.ok());
  auto second = Endpoint::Start((*first)->address());
  EXPECT_EQ(second.status().code(), absl::StatusCode::kUnavailable) << second.status();
}

}  // namespace
}  // namespace instascene::metrics
