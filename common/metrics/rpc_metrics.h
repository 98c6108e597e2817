// common/metrics/rpc_metrics.h: a gRPC server interceptor recording every call's latency in
// `instascene_rpc_duration_seconds{service, method, code}` (a histogram: its _count is the call
// count per method and status code). Thread-safe.
#pragma once

#include <grpcpp/support/server_interceptor.h>

#include <memory>
#include <vector>

namespace instascene::metrics {

std::vector<std::unique_ptr<grpc::experimental::ServerInterceptorFactoryInterface>>
RpcMetricsInterceptors();

}  // namespace instascene::metrics
