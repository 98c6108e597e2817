// services/generation/diffusion/grpc_denoiser.h: the Denoiser over gRPC (proto/instascene/v1/
// denoiser.proto). DenoiserService serves any Denoiser (a site wraps its model; the tests wrap the
// analytic one); GrpcDenoiser is the client the sampler uses, with a deadline per call and retries
// of UNAVAILABLE / DEADLINE_EXCEEDED with doubling backoff; an unreachable denoiser ends as
// UNAVAILABLE naming its address (retryable: the job is tried again later). Sizes are bounded as
// the proto says. A query's condition latent and relative pose travel with it (the server hands
// them to its model in the NoiseQuery). Thread-safe.
#pragma once

#include <chrono>
#include <memory>
#include <string>
#include <vector>

#include <grpcpp/grpcpp.h>

#include "instascene/v1/denoiser.grpc.pb.h"
#include "services/generation/diffusion/denoiser.h"

namespace instascene::generation::diffusion {

inline constexpr int kMaxDenoiserItems = 64;

class DenoiserService final : public v1::Denoiser::Service {
 public:
  // `impl` must outlive the service.
  DenoiserService(const Denoiser* impl, std::string model, std::vector<int> latent_shape,
                  int timesteps);
  grpc::Status PredictNoise(grpc::ServerContext* context, const v1::PredictNoiseRequest* request,
                            v1::PredictNoiseResponse* response) override;
  grpc::Status Describe(grpc::ServerContext* context, const v1::DescribeDenoiserRequest* request,
                        v1::DenoiserInfo* response) override;

 private:
  const Denoiser* impl_;
  std::string model_;
  std::vector<int> latent_shape_;
  int timesteps_;
};

struct GrpcDenoiserOptions {
  std::vector<int> latent_shape;              // sent with every latent; its product = size
  std::chrono::milliseconds deadline{30000};  // per call
  int attempts = 3;                           // tries of a retryable failure
  std::chrono::milliseconds backoff{200};     // before the 2nd try, doubled after
};

class GrpcDenoiser : public Denoiser {
 public:
  // `address` names the denoiser in messages.
  GrpcDenoiser(std::shared_ptr<grpc::Channel> channel, std::string address,
               GrpcDenoiserOptions options);
  absl::StatusOr<std::vector<float>> PredictNoise(const NoiseQuery& query) const override;

 private:
  std::unique_ptr<v1::Denoiser::Stub> stub_;
  std::string address_;
  GrpcDenoiserOptions options_;
};

}  // namespace instascene::generation::diffusion
