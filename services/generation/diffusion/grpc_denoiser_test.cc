#include "services/generation/diffusion/grpc_denoiser.h"

#include <gtest/gtest.h>

#include "absl/synchronization/notification.h"
#include "common/rpc/server.h"
#include "services/generation/diffusion/analytic_denoiser.h"
#include "services/generation/diffusion/ddim.h"

namespace instascene::generation::diffusion {
namespace {

class LoopbackDenoiser : public ::testing::Test {
 protected:
  void SetUp() override {
    service_ = std::make_unique<DenoiserService>(&analytic_, "analytic-gaussian",
                                                 std::vector<int>{2, 4, 4}, schedule_.size());
    rpc::ServerOptions options;
    options.listen = "127.0.0.1:0";
    auto server = rpc::Server::Start(options, {service_.get()}, {"instascene.v1.Denoiser"});
    ASSERT_TRUE(server.ok()) << server.status();
    server_ = std::move(*server);
    channel_ = rpc::Connect(server_->address());
  }
  void TearDown() override { server_->Drain(std::chrono::milliseconds(100)); }

  GrpcDenoiserOptions ClientOptions() const {
    GrpcDenoiserOptions o;
    o.latent_shape = {2, 4, 4};
    return o;
  }

  NoiseSchedule schedule_ = NoiseSchedule::ScaledLinear();
  AnalyticDenoiser analytic_{schedule_, {0.1, 0.6}, 0.0, 0.5};
  std::unique_ptr<DenoiserService> service_;
  std::unique_ptr<rpc::Server> server_;
  std::shared_ptr<grpc::Channel> channel_;
};

TEST_F(LoopbackDenoiser, GivesTheSamplesOfTheInProcessDenoiserBitForBit) {
  GrpcDenoiser remote(channel_, server_->address(), ClientOptions());
  DdimOptions options;
  options.steps = 10;
  options.guidance = 2.0;  // the unconditional prediction travels too
  auto local = SampleDdim(analytic_, schedule_, 2, 32, {0, 1}, options);
  auto over_grpc = SampleDdim(remote, schedule_, 2, 32, {0, 1}, options);
  ASSERT_TRUE(local.ok() && over_grpc.ok()) << over_grpc.status();
  EXPECT_EQ(*local, *over_grpc);
}

// Records what reaches the model behind the service.
class RecordingDenoiser : public Denoiser {
 public:
  absl::StatusOr<std::vector<float>> PredictNoise(const NoiseQuery& q) const override {
    condition_latent = q.condition_latent ? *q.condition_latent : std::vector<float>{};
    pose = q.target_from_condition ? std::vector<double>(q.target_from_condition->begin(),
                                                         q.target_from_condition->end())
                                   : std::vector<double>{};
    return std::vector<float>(q.latent->size(), 0.0f);
  }
  mutable std::vector<float> condition_latent;
  mutable std::vector<double> pose;
};

TEST(GrpcDenoiser, TheConditionLatentAndRelativePoseReachTheModel) {
  RecordingDenoiser model;
  DenoiserService service(&model, "recording", {2, 2}, 1000);
  rpc::ServerOptions server_options;
  server_options.listen = "127.0.0.1:0";
  auto server = rpc::Server::Start(server_options, {&service}, {"instascene.v1.Denoiser"});
  ASSERT_TRUE(server.ok()) << server.status();
  GrpcDenoiserOptions o;
  o.latent_shape = {2, 2};
  GrpcDenoiser remote(rpc::Connect((*server)->address()), (*server)->address(), o);
  const std::vector<float> latent(4, 0.0f), condition = {1, 2, 3, 4};
  std::array<double, 16> pose{};
  for (int k = 0; k < 16; ++k) pose[k] = k * 0.5;
  NoiseQuery q{&latent, 10, 3, 1, &condition, &pose};
  ASSERT_TRUE(remote.PredictNoise(q).ok());
  EXPECT_EQ(model.condition_latent, condition);
  EXPECT_EQ(model.pose, std::vector<double>(pose.begin(), pose.end()));
  ASSERT_TRUE(remote.PredictNoise(NoiseQuery{&latent, 10, 3, -1}).ok());  // unconditional
  EXPECT_TRUE(model.condition_latent.empty() && model.pose.empty());
  const std::vector<float> short_condition(3, 0.0f);
  q.condition_latent = &short_condition;
  EXPECT_EQ(remote.PredictNoise(q).status().code(), absl::StatusCode::kInvalidArgument);
  (*server)->Drain(std::chrono::milliseconds(100));
}

TEST_F(LoopbackDenoiser, RefusesOversizedAndMalformedRequests) {
  auto stub = v1::Denoiser::NewStub(channel_);
  auto call = [&](const v1::PredictNoiseRequest& r) {
    grpc::ClientContext context;
    v1::PredictNoiseResponse response;
    return stub->PredictNoise(&context, r, &response);
  };
  v1::PredictNoiseRequest many;
  for (int i = 0; i <= kMaxDenoiserItems; ++i) {
    v1::NoiseItem* item = many.add_items();
    item->mutable_latent()->add_shape(1);
    item->mutable_latent()->add_values(0.0f);
  }
  grpc::Status s = call(many);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(s.error_message().find("65 items (at most 64)"), std::string::npos)
      << s.error_message();
  v1::PredictNoiseRequest huge;
  v1::Latent* big = huge.add_items()->mutable_latent();
  for (int d : {300, 300}) big->add_shape(d);
  s = call(huge);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(s.error_message().find("items[0].latent"), std::string::npos);
  v1::PredictNoiseRequest mismatch;
  v1::NoiseItem* item = mismatch.add_items();
  for (int d : {2, 4, 4}) item->mutable_latent()->add_shape(d);
  item->mutable_latent()->add_values(1.0f);
  s = call(mismatch);
  EXPECT_NE(s.error_message().find("1 values for a shape of 32"), std::string::npos);
  v1::PredictNoiseRequest late;
  item = late.add_items();
  item->mutable_latent()->add_shape(1);
  item->mutable_latent()->add_values(0.0f);
  item->set_timestep(1000);
  EXPECT_EQ(call(late).error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  grpc::ClientContext context;
  v1::DenoiserInfo info;
  ASSERT_TRUE(stub->Describe(&context, v1::DescribeDenoiserRequest(), &info).ok());
  EXPECT_EQ(info.model(), "analytic-gaussian");
  EXPECT_EQ(info.timesteps(), 1000);
}

TEST_F(LoopbackDenoiser, PassesTheModelsErrorsOnNamingTheDenoiser) {
  GrpcDenoiser remote(channel_, server_->address(), ClientOptions());
  const std::vector<float> latent(32, 0.0f);
  auto eps = remote.PredictNoise(NoiseQuery{&latent, 10, 0, 5});  // the model has 2 conditions
  EXPECT_EQ(eps.status().code(), absl::StatusCode::kOutOfRange);
  EXPECT_NE(eps.status().message().find("denoiser " + server_->address()), std::string::npos);
  const std::vector<float> wrong(7, 0.0f);
  EXPECT_EQ(remote.PredictNoise(NoiseQuery{&wrong, 10, 0, 0}).status().code(),
            absl::StatusCode::kInvalidArgument);
}

// A model that does not answer until released (at the end of the test).
class StuckDenoiser : public Denoiser {
 public:
  absl::StatusOr<std::vector<float>> PredictNoise(const NoiseQuery& q) const override {
    release_.WaitForNotification();
    return std::vector<float>(q.latent->size(), 0.0f);
  }
  void Release() { release_.Notify(); }

 private:
  mutable absl::Notification release_;
};

TEST(GrpcDenoiser, ADenoiserPastItsDeadlineIsUnavailableAfterItsRetries) {
  StuckDenoiser model;
  DenoiserService service(&model, "stuck", {4}, 1000);
  rpc::ServerOptions server_options;
  server_options.listen = "127.0.0.1:0";
  auto server = rpc::Server::Start(server_options, {&service}, {"instascene.v1.Denoiser"});
  ASSERT_TRUE(server.ok()) << server.status();
  GrpcDenoiserOptions o;
  o.latent_shape = {4};
  o.attempts = 2;
  o.backoff = std::chrono::milliseconds(1);
  o.deadline = std::chrono::milliseconds(200);
  GrpcDenoiser remote(rpc::Connect((*server)->address()), (*server)->address(), o);
  const std::vector<float> latent(4, 0.0f);
  auto eps = remote.PredictNoise(NoiseQuery{&latent, 0, 0, 0});
  EXPECT_EQ(eps.status().code(), absl::StatusCode::kUnavailable);
  EXPECT_NE(eps.status().message().find("after 2 attempts"), std::string::npos) << eps.status();
  EXPECT_NE(eps.status().message().find("Deadline Exceeded"), std::string::npos) << eps.status();
  model.Release();
  (*server)->Drain(std::chrono::milliseconds(100));
}

TEST(GrpcDenoiser, AnUnreachableDenoiserIsUnavailableAfterItsRetries) {
  GrpcDenoiserOptions o;
  o.latent_shape = {4};
  o.attempts = 2;
  o.backoff = std::chrono::milliseconds(1);
  o.deadline = std::chrono::milliseconds(500);
  GrpcDenoiser remote(rpc::Connect("127.0.0.1:1"), "127.0.0.1:1", o);  // nothing listens there
  const std::vector<float> latent(4, 0.0f);
  auto eps = remote.PredictNoise(NoiseQuery{&latent, 0, 0, 0});
  EXPECT_EQ(eps.status().code(), absl::StatusCode::kUnavailable);
  EXPECT_NE(eps.status().message().find("127.0.0.1:1 unreachable after 2 attempts"),
            std::string::npos)
      << eps.status();
}

}  // namespace
}  // namespace instascene::generation::diffusion
