// services/scheduler/scheduler_service.h: the Scheduler gRPC service (scheduler.proto), a thin
// adapter over the JobQueue core, the stage registry (pipelines are planned and parameters
// validated through the stages' codecs at submission) and the store (to check scene manifests at
// submission and job outputs at completion). Owns the rescuer thread that returns expired leases,
// and wakes WatchJobs streams whenever a job changes. Thread-safe.
#pragma once

#include <condition_variable>
#include <mutex>
#include <thread>

#include "common/auth/authenticator.h"
#include "common/store/blob_store.h"
#include "instascene/v1/scheduler.grpc.pb.h"
#include "services/pipeline/registry.h"
#include "services/scheduler/job_queue.h"

namespace instascene::scheduler {

struct SchedulerServiceOptions {
  int rescue_interval_ms = 1000;  // how often expired leases are looked for
  int max_attempts = 3;           // per job, for submitted pipelines
  int64_t retention_ms = 0;       // finished jobs older than this are pruned (0 = kept for ever)
  int prune_interval_ms = 60000;  // how often the rescuer thread prunes
  // Who may call what (null = authentication off). Clients act on their tenant's scenes only (a
  // client's scene "x" is stored as "<tenant>:x", common/auth/identity.h), workers lease and
  // complete, admins do everything; completing a job grants its outputs to its scene's tenant.
  auth::Authenticator* auth = nullptr;
};

class SchedulerService final : public v1::Scheduler::Service {
 public:
  // queue, store and stages must outlive the service. Starts the rescuer.
  SchedulerService(JobQueue* queue, store::BlobStore* store, const pipeline::StageRegistry* stages,
                   const SchedulerServiceOptions& options);
  ~SchedulerService() override;
  // Ends watch streams and the rescuer (call before the server drains).
  void Stop();

  grpc::Status SubmitPipeline(grpc::ServerContext*, const v1::SubmitPipelineRequest* request,
                              v1::SubmitPipelineResponse* response) override;
  grpc::Status LeaseJob(grpc::ServerContext*, const v1::LeaseJobRequest* request,
                        v1::LeaseJobResponse* response) override;
  grpc::Status Heartbeat(grpc::ServerContext*, const v1::HeartbeatRequest* request,
                         v1::HeartbeatResponse* response) override;
  grpc::Status CompleteJob(grpc::ServerContext*, const v1::CompleteJobRequest* request,
                           v1::CompleteJobResponse* response) override;
  grpc::Status FailJob(grpc::ServerContext*, const v1::FailJobRequest* request,
                       v1::FailJobResponse* response) override;
  grpc::Status CancelJob(grpc::ServerContext*, const v1::CancelJobRequest* request,
                         v1::Job* response) override;
  grpc::Status CancelScene(grpc::ServerContext*, const v1::CancelSceneRequest* request,
                           v1::CancelSceneResponse* response) override;
  grpc::Status DeleteScene(grpc::ServerContext*, const v1::DeleteSceneRequest* request,
                           v1::DeleteSceneResponse* response) override;
  grpc::Status GetScene(grpc::ServerContext*, const v1::GetSceneRequest* request,
                        v1::Scene* response) override;
  grpc::Status ListStages(grpc::ServerContext*, const v1::ListStagesRequest* request,
                          v1::ListStagesResponse* response) override;
  grpc::Status GetJob(grpc::ServerContext*, const v1::GetJobRequest* request,
                      v1::Job* response) override;
  grpc::Status ListJobs(grpc::ServerContext*, const v1::ListJobsRequest* request,
                        v1::ListJobsResponse* response) override;
  grpc::Status GetQueueStats(grpc::ServerContext*, const v1::GetQueueStatsRequest* request,
                             v1::QueueStats* response) override;
  grpc::Status WatchJobs(grpc::ServerContext* context, const v1::WatchJobsRequest* request,
                         grpc::ServerWriter<v1::Job>* writer) override;

 private:
  // A job as the caller sees it: its scene under the caller's own name for it.
  static void ToCallerProto(const auth::Identity& who, const Job& job, v1::Job* out);
  absl::Status Submit(const auth::Identity& who, const v1::SubmitPipelineRequest& request,
                      v1::SubmitPipelineResponse* response);
  absl::StatusOr<auth::Identity> Caller(grpc::ServerContext* context,
                                        std::initializer_list<auth::Role> roles) const;
  // The job, if the caller may see it (NotFound otherwise, as for an unknown job).
  absl::StatusOr<Job> VisibleJob(const auth::Identity& who, const std::string& id);
  // Grants a finished job's output manifest and every blob it names to its scene's tenant.
  absl::Status GrantOutputs(const Job& job, const store::Digest& output);
  absl::Status Lease(const v1::LeaseJobRequest& request, v1::LeaseJobResponse* response);
  // A completion's output must be the lease holder's, a manifest of the job's kind whose blobs
  // are all in the store and that holds the files its stage always writes.
  absl::Status CheckOutput(const std::string& job_id, const std::string& lease_token,
                           const store::Digest& output);
  void Notify();
  void RescueLoop();

  JobQueue* queue_;
  store::BlobStore* store_;
  const pipeline::StageRegistry* stages_;
  SchedulerServiceOptions options_;
  std::mutex mutex_;
  std::condition_variable changed_;
  uint64_t version_ = 0;
  bool stopping_ = false;
  std::thread rescuer_;
};

}  // namespace instascene::scheduler
