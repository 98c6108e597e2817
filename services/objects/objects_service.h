// services/objects/objects_service.h: the Objects gRPC service (objects.proto). A scene name is
// resolved to its latest stored outputs through the scheduler (GetScene, every query, so a rerun
// is seen at once); the index over those outputs (scene_objects.h) is loaded on first use and kept
// in an LRU cache bounded in bytes; an index whose scene was rerun or deleted leaves it at the
// first query that sees so. Concurrent first queries of one scene share one load; loads
// run outside the cache lock, so a cold scene never stalls queries on loaded ones. Thread-safe.
#pragma once

#include <functional>
#include <future>
#include <list>
#include <memory>
#include <mutex>
#include <string>

#include "common/auth/authenticator.h"
#include "common/store/blob_store.h"
#include "instascene/v1/objects.grpc.pb.h"
#include "instascene/v1/scheduler.pb.h"
#include "services/objects/scene_objects.h"

namespace instascene::objects {

// A scene's latest outputs by name (the scheduler's GetScene); NOT_FOUND for an unknown scene.
using SceneLookup = std::function<absl::StatusOr<v1::Scene>(const std::string& scene)>;

// The outputs an index is built from: the latest `segment` output, and the `export` and
// `complete` outputs computed from the same submission. FAILED_PRECONDITION before segmentation.
absl::StatusOr<SceneOutputs> OutputsOf(const v1::Scene& scene);

struct ObjectsServiceOptions {
  int64_t cache_bytes = int64_t{4} << 30;  // loaded indexes kept (at least the newest one)
  int max_page = 1000;                     // ListObjects page size limit
  // Clients ask for their tenant's scenes only (the lookup receives the stored scene name,
  // common/auth/identity.h); null = authentication off. Must outlive the service.
  auth::Authenticator* auth = nullptr;
};

class ObjectsService final : public v1::Objects::Service {
 public:
  // `store` must outlive the service. Indexes are read from the store into memory (nothing on
  // disk): a cold load reads the scene's splat and labels again.
  ObjectsService(store::BlobStore* store, SceneLookup lookup, ObjectsServiceOptions options = {});

  grpc::Status ListObjects(grpc::ServerContext*, const v1::ListObjectsRequest* request,
                           v1::ListObjectsResponse* response) override;
  grpc::Status GetObject(grpc::ServerContext*, const v1::GetObjectRequest* request,
                         v1::Object* response) override;

  struct CacheStats {
    int64_t entries = 0, bytes = 0, loads = 0, hits = 0;
  };
  CacheStats cache_stats() const;

 private:
  using Loaded = absl::StatusOr<std::shared_ptr<const SceneObjects>>;
  struct Entry {
    std::string key;
    std::shared_future<Loaded> future;
    size_t bytes = 0;   // once loaded
    std::string scene;  // whose outputs (the key names it too)
  };
  // The index of a scene's latest outputs; *fresh is true when this call loaded it.
  Loaded Index(const std::string& scene, bool* fresh);
  // The cache's entry for `key` (moved to the front), or a new one whose future `promise` will
  // fulfil (*fresh true: the caller loads it and calls Settle).
  std::shared_future<Loaded> Reserve(const std::string& key, const std::string& scene,
                                     std::promise<Loaded>* promise, bool* fresh);
  // `scene`'s latest outputs are `key`'s (empty: it was deleted): its other entries leave the
  // cache at once instead of waiting for the budget.
  void Forget(const std::string& scene, const std::string& key);
  // Records a loaded entry's size (a failed load's entry goes: the next query retries) and evicts
  // past the budget.
  void Settle(const std::string& key, const Loaded& loaded);
  // Drops loaded entries past the byte budget (mutex_ held); returns them so that the caller
  // destroys them after unlocking (a SceneObjects joins its warm-up thread when destroyed).
  std::list<Entry> Evict();
  // The cache's entries and bytes to the metrics (mutex_ held).
  void PublishCacheSize() const;

  store::BlobStore* store_;
  SceneLookup lookup_;
  ObjectsServiceOptions options_;
  mutable std::mutex mutex_;
  std::list<Entry> lru_;  // most recent first
  int64_t loads_ = 0, hits_ = 0;
};

}  // namespace instascene::objects
