#include "services/generation/diffusion/grpc_denoiser.h"

#include <algorithm>
#include <thread>

#include "absl/strings/str_cat.h"
#include "common/core/status.h"
#include "common/rpc/status.h"

namespace instascene::generation::diffusion {
namespace {

// Values a latent's shape holds, or -1 when the shape is empty, has a non-positive dimension or
// exceeds the limit.
int64_t ShapeSize(const google::protobuf::RepeatedField<int32_t>& shape) {
  if (shape.empty()) return -1;
  int64_t n = 1;
  for (int32_t d : shape) {
    if (d <= 0) return -1;
    n *= d;
    if (n > kMaxValuesPerLatent) return -1;
  }
  return n;
}

absl::Status CheckLatent(const v1::Latent& latent, const std::string& what) {
  const int64_t n = ShapeSize(latent.shape());
  if (n < 0)
    return absl::InvalidArgumentError(absl::StrCat(
        what, ": shape must be positive dimensions of at most ", kMaxValuesPerLatent, " values"));
  if (latent.values_size() != n)
    return absl::InvalidArgumentError(
        absl::StrCat(what, ": ", latent.values_size(), " values for a shape of ", n));
  return absl::OkStatus();
}

// The request for one query: its latent (and condition latent) with the denoiser's shape, the
// timestep, the target and condition views and the warp between them.
absl::StatusOr<v1::PredictNoiseRequest> NoiseRequest(const NoiseQuery& q,
                                                     const std::vector<int>& latent_shape,
                                                     const std::string& address) {
  int64_t size = 1;
  for (int d : latent_shape) size *= d;
  if (latent_shape.empty() || size != static_cast<int64_t>(q.latent->size()) ||
      size > kMaxValuesPerLatent)
    return absl::InvalidArgumentError(absl::StrCat("denoiser ", address, ": a latent of ",
                                                   q.latent->size(), " values for its shape"));
  v1::PredictNoiseRequest request;
  v1::NoiseItem* item = request.add_items();
  for (int d : latent_shape) item->mutable_latent()->add_shape(d);
  item->mutable_latent()->mutable_values()->Add(q.latent->begin(), q.latent->end());
  item->set_timestep(q.timestep);
  item->set_target(q.target);
  item->set_condition(q.condition);
  if (q.condition_latent != nullptr) {
    if (static_cast<int64_t>(q.condition_latent->size()) != size)
      return absl::InvalidArgumentError(
          absl::StrCat("denoiser ", address, ": a condition latent of ", q.condition_latent->size(),
                       " values for a shape of ", size));
    for (int d : latent_shape) item->mutable_condition_latent()->add_shape(d);
    item->mutable_condition_latent()->mutable_values()->Add(q.condition_latent->begin(),
                                                            q.condition_latent->end());
  }
  if (q.target_from_condition != nullptr) {
    item->mutable_target_from_condition()->Add(q.target_from_condition->begin(),
                                               q.target_from_condition->end());
  }
  return request;
}

}  // namespace

DenoiserService::DenoiserService(const Denoiser* impl, std::string model,
                                 std::vector<int> latent_shape, int timesteps)
    : impl_(impl),
      model_(std::move(model)),
      latent_shape_(std::move(latent_shape)),
      timesteps_(timesteps) {}

grpc::Status DenoiserService::PredictNoise(grpc::ServerContext*,
                                           const v1::PredictNoiseRequest* request,
                                           v1::PredictNoiseResponse* response) {
  if (request->items_size() > kMaxDenoiserItems)
    return rpc::ToGrpcStatus(absl::InvalidArgumentError(
        absl::StrCat(request->items_size(), " items (at most ", kMaxDenoiserItems, ")")));
  for (int i = 0; i < request->items_size(); ++i) {
    const v1::NoiseItem& item = request->items(i);
    const std::string where = absl::StrCat("items[", i, "]");
    if (absl::Status s = CheckLatent(item.latent(), where + ".latent"); !s.ok())
      return rpc::ToGrpcStatus(s);
    if (item.has_condition_latent()) {
      if (absl::Status s = CheckLatent(item.condition_latent(), where + ".condition_latent");
          !s.ok())
        return rpc::ToGrpcStatus(s);
    }
    if (item.timestep() < 0 || item.timestep() >= timesteps_ || item.condition() < -1 ||
        (item.target_from_condition_size() != 0 && item.target_from_condition_size() != 16))
      return rpc::ToGrpcStatus(absl::InvalidArgumentError(
          absl::StrCat(where, ": timestep in [0, ", timesteps_,
                       "), condition >= -1, target_from_condition empty or 16 values")));
    const std::vector<float> latent(item.latent().values().begin(), item.latent().values().end());
    NoiseQuery query{&latent, item.timestep(), item.target(), item.condition()};
    const std::vector<float> condition_latent(item.condition_latent().values().begin(),
                                              item.condition_latent().values().end());
    if (item.has_condition_latent()) query.condition_latent = &condition_latent;
    std::array<double, 16> pose{};
    if (item.target_from_condition_size() == 16) {
      std::copy(item.target_from_condition().begin(), item.target_from_condition().end(),
                pose.begin());
      query.target_from_condition = &pose;
    }
    absl::StatusOr<std::vector<float>> eps = impl_->PredictNoise(query);
    if (!eps.ok()) return rpc::ToGrpcStatus(eps.status());
    v1::Latent* out = response->add_noise();
    *out->mutable_shape() = item.latent().shape();
    out->mutable_values()->Add(eps->begin(), eps->end());
  }
  return grpc::Status::OK;
}

grpc::Status DenoiserService::Describe(grpc::ServerContext*, const v1::DescribeDenoiserRequest*,
                                       v1::DenoiserInfo* response) {
  response->set_model(model_);
  for (int d : latent_shape_) response->add_latent_shape(d);
  response->set_timesteps(timesteps_);
  return grpc::Status::OK;
}

GrpcDenoiser::GrpcDenoiser(std::shared_ptr<grpc::Channel> channel, std::string address,
                           GrpcDenoiserOptions options)
    : stub_(v1::Denoiser::NewStub(std::move(channel))),
      address_(std::move(address)),
      options_(std::move(options)) {}

absl::StatusOr<std::vector<float>> GrpcDenoiser::PredictNoise(const NoiseQuery& q) const {
  ASSIGN_OR_RETURN(const v1::PredictNoiseRequest request,
                   NoiseRequest(q, options_.latent_shape, address_));
  grpc::Status last;
  std::chrono::milliseconds backoff = options_.backoff;
  for (int attempt = 1; attempt <= std::max(1, options_.attempts); ++attempt) {
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() + options_.deadline);
    v1::PredictNoiseResponse response;
    last = stub_->PredictNoise(&context, request, &response);
    if (last.ok()) {
      if (response.noise_size() != 1)
        return absl::InvalidArgumentError(absl::StrCat(
            "denoiser ", address_, ": ", response.noise_size(), " answers for one item"));
      const auto& values = response.noise(0).values();
      return std::vector<float>(values.begin(), values.end());
    }
    const bool retryable = last.error_code() == grpc::StatusCode::UNAVAILABLE ||
                           last.error_code() == grpc::StatusCode::DEADLINE_EXCEEDED;
    if (!retryable) {
      const absl::Status s = rpc::FromGrpcStatus(last);
      return absl::Status(s.code(), absl::StrCat("denoiser ", address_, ": ", s.message()));
    }
    if (attempt < options_.attempts) {
      std::this_thread::sleep_for(backoff);  // backoff between tries of a remote service
      backoff *= 2;
    }
  }
  return absl::UnavailableError(absl::StrCat("denoiser ", address_, " unreachable after ",
                                             std::max(1, options_.attempts),
                                             " attempts: ", last.error_message()));
}

}  // namespace instascene::generation::diffusion
