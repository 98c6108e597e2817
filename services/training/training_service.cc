#include "services/training/training_service.h"

#include <filesystem>

#include "absl/strings/str_cat.h"
#include "common/core/status.h"
#include "common/core/timer.h"
#include "common/rpc/status.h"
#include "common/store/manifest.h"

namespace instascene::training {
namespace fs = std::filesystem;

TrainingService::TrainingService(store::BlobStore* store, std::string work_dir,
                                 const worker::StageWorker* worker, int cache_entries)
    : store_(store),
      work_dir_(std::move(work_dir)),
      worker_(worker),
      cache_entries_(static_cast<size_t>(std::max(1, cache_entries))) {}

grpc::Status TrainingService::GetWorkerStatus(grpc::ServerContext*,
                                              const v1::GetWorkerStatusRequest*,
                                              v1::WorkerStatus* response) {
  worker::FillWorkerStatus(worker_, {"train", "segment"}, response);
  return grpc::Status::OK;
}

absl::StatusOr<std::shared_ptr<TrainingService::Loaded>> TrainingService::Load(
    const store::Digest& scene_digest, const store::Digest& result_digest) {
  const std::string key = absl::StrCat(scene_digest.hash, "/", result_digest.hash);
  std::lock_guard<std::mutex> lock(mutex_);
  for (auto it = cache_.begin(); it != cache_.end(); ++it) {
    if ((*it)->key == key) {
      cache_.splice(cache_.begin(), cache_, it);
      return cache_.front();
    }
  }
  ASSIGN_OR_RETURN(store::Manifest scene_manifest, store::ReadManifest(*store_, scene_digest));
  RETURN_IF_ERROR(store::ValidateSceneManifest(*store_, scene_manifest));
  ASSIGN_OR_RETURN(store::Manifest result_manifest, store::ReadManifest(*store_, result_digest));
  const std::string scene_dir = (fs::path(work_dir_) / "scenes" / scene_digest.hash).string();
  const std::string result_dir = (fs::path(work_dir_) / "results" / result_digest.hash).string();
  RETURN_IF_ERROR(store::MaterializeManifest(*store_, scene_manifest, scene_dir));
  RETURN_IF_ERROR(store::MaterializeManifest(*store_, result_manifest, result_dir));
  auto loaded = std::make_shared<Loaded>();
  loaded->key = key;
  ASSIGN_OR_RETURN(loaded->scene, ReadScene(scene_dir));
  ASSIGN_OR_RETURN(loaded->cloud, ReadSceneGaussians(loaded->scene));
  ASSIGN_OR_RETURN(SegmentationResult result, ReadResult(result_dir, loaded->cloud.size()));
  ASSIGN_OR_RETURN(loaded->index, QueryIndex::Build(loaded->scene, loaded->cloud, result));
  loaded->point_radius = 0.02f * RobustBounds(loaded->cloud).diagonal().norm();
  cache_.push_front(loaded);
  if (cache_.size() > cache_entries_) cache_.pop_back();
  return loaded;
}

absl::Status TrainingService::Answer(const v1::QueryRequest& request, v1::QueryResponse* response) {
  ASSIGN_OR_RETURN(store::Digest scene,
                   rpc::ParseProtoDigest(request.scene_manifest(), "scene_manifest"));
  ASSIGN_OR_RETURN(store::Digest result,
                   rpc::ParseProtoDigest(request.result_manifest(), "result_manifest"));
  ASSIGN_OR_RETURN(std::shared_ptr<Loaded> loaded, Load(scene, result));
  Stopwatch watch;
  QueryAnswer answer;
  if (request.has_point()) {
    const Eigen::Vector3f point(static_cast<float>(request.point_x()),
                                static_cast<float>(request.point_y()),
                                static_cast<float>(request.point_z()));
    if (!point.allFinite()) return absl::InvalidArgumentError("query point is not finite");
    ASSIGN_OR_RETURN(answer, loaded->index->Point(point, loaded->point_radius));
  } else {
    ASSIGN_OR_RETURN(int view, ResolveView(loaded->scene, request.view()));
    ASSIGN_OR_RETURN(answer, loaded->index->Click(view, request.x(), request.y()));
  }
  response->set_instance(answer.instance);
  response->set_instance_gaussians(static_cast<int64_t>(answer.gaussians));
  response->set_microseconds(watch.ElapsedSeconds() * 1e6);
  return absl::OkStatus();
}

grpc::Status TrainingService::Query(grpc::ServerContext*, const v1::QueryRequest* request,
                                    v1::QueryResponse* response) {
  return rpc::ToGrpcStatus(Answer(*request, response));
}

}  // namespace instascene::training
