#include "services/objects/objects_service.h"

#include <exception>
#include <new>

#include <nlohmann/json.hpp>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "common/core/status.h"
#include "common/core/timer.h"
#include "common/rpc/status.h"
#include "services/objects/objects_metrics.h"

namespace instascene::objects {

absl::StatusOr<SceneOutputs> OutputsOf(const v1::Scene& scene) {
  SceneOutputs out;
  out.scene = scene.name();
  const v1::StageOutput* segment = nullptr;
  for (const v1::StageOutput& o : scene.outputs()) {
    if (o.kind() == "segment" && o.item() < 0) segment = &o;
  }
  if (segment == nullptr)
    return absl::FailedPreconditionError(absl::StrCat(
        "scene '", scene.name(),
        "' has no segmentation yet (its segment job has not succeeded): no objects to find"));
  out.segment = rpc::FromProto(segment->output_manifest());
  out.scene_manifest = rpc::FromProto(segment->scene_manifest());
  for (const v1::StageOutput& o : scene.outputs()) {
    if (rpc::FromProto(o.scene_manifest()) != out.scene_manifest) continue;
    if (o.kind() == "export" && o.item() < 0) out.exported = rpc::FromProto(o.output_manifest());
    if (o.kind() == "complete" && o.item() >= 0)
      out.complete[o.item()] = rpc::FromProto(o.output_manifest());
  }
  return out;
}

ObjectsService::ObjectsService(store::BlobStore* store, SceneLookup lookup,
                               ObjectsServiceOptions options)
    : store_(store), lookup_(std::move(lookup)), options_(options) {
  RegisterIndexMetrics();
}

namespace {

absl::Status CheckSceneName(const std::string& scene) {
  if (scene.empty()) return absl::InvalidArgumentError("scene: a scene name is required");
  if (scene.size() > 256)
    return absl::InvalidArgumentError(
        absl::StrCat("scene: a name of ", scene.size(), " bytes (at most 256)"));
  return absl::OkStatus();
}

// A scene's objects index loaded from the store; an exception (e.g. allocation failure, a
// stored manifest of the wrong shape) fails this load only.
absl::StatusOr<std::shared_ptr<const SceneObjects>> LoadGuarded(store::BlobStore& store,
                                                                const SceneOutputs& outputs,
                                                                const std::string& scene) {
  try {
    absl::StatusOr<std::unique_ptr<SceneObjects>> built = SceneObjects::Load(store, outputs);
    if (built.ok()) return std::shared_ptr<const SceneObjects>(std::move(*built));
    return absl::Status(built.status().code(),
                        absl::StrCat("scene '", scene, "': ", built.status().message()));
  } catch (const nlohmann::json::exception& e) {  // a stored manifest of the wrong shape
    return absl::DataLossError(
        absl::StrCat("scene '", scene, "': a stored result is malformed: ", e.what()));
  } catch (const std::bad_alloc&) {
    return absl::ResourceExhaustedError(
        absl::StrCat("scene '", scene, "': out of memory loading its objects"));
  } catch (const std::exception& e) {
    return absl::InternalError(
        absl::StrCat("scene '", scene, "': loading its objects failed: ", e.what()));
  }
}

}  // namespace

ObjectsService::Loaded ObjectsService::Index(const std::string& scene, bool* fresh) {
  *fresh = false;
  RETURN_IF_ERROR(CheckSceneName(scene));
  absl::StatusOr<v1::Scene> described = lookup_(scene);
  if (absl::IsNotFound(described.status())) Forget(scene, "");
  RETURN_IF_ERROR(described.status());
  ASSIGN_OR_RETURN(SceneOutputs outputs, OutputsOf(*described));
  const std::string key = outputs.Key();
  std::promise<Loaded> promise;
  const std::shared_future<Loaded> future = Reserve(key, scene, &promise, fresh);
  Forget(scene, key);
  if (!*fresh) return future.get();
  // Load outside the lock.
  Stopwatch watch;
  const Loaded loaded = LoadGuarded(*store_, outputs, scene);
  RecordIndexLoad(watch.ElapsedSeconds(), loaded.ok());
  promise.set_value(loaded);
  Settle(key, loaded);
  return loaded;
}

std::shared_future<ObjectsService::Loaded> ObjectsService::Reserve(const std::string& key,
                                                                   const std::string& scene,
                                                                   std::promise<Loaded>* promise,
                                                                   bool* fresh) {
  std::lock_guard<std::mutex> lock(mutex_);
  for (auto it = lru_.begin(); it != lru_.end(); ++it) {
    if (it->key != key) continue;
    lru_.splice(lru_.begin(), lru_, it);
    ++hits_;
    RecordIndexHit();
    return lru_.front().future;
  }
  ++loads_;
  std::shared_future<Loaded> future = promise->get_future().share();
  lru_.push_front(Entry{key, future, 0, scene});
  *fresh = true;
  return future;
}

void ObjectsService::Settle(const std::string& key, const Loaded& loaded) {
  std::list<Entry> evicted;  // destroyed after the lock is released
  std::lock_guard<std::mutex> lock(mutex_);
  for (auto it = lru_.begin(); it != lru_.end(); ++it) {
    if (it->key != key) continue;
    if (loaded.ok()) {
      it->bytes = (*loaded)->ByteSize();
    } else {
      lru_.erase(it);  // a failed load is retried by the next query
    }
    break;
  }
  evicted = Evict();
  PublishCacheSize();
}

void ObjectsService::PublishCacheSize() const {
  int64_t bytes = 0;
  for (const Entry& e : lru_) bytes += static_cast<int64_t>(e.bytes);
  SetIndexCache(static_cast<int64_t>(lru_.size()), bytes);
}

void ObjectsService::Forget(const std::string& scene, const std::string& key) {
  std::list<Entry> dropped;  // destroyed after the lock is released
  std::lock_guard<std::mutex> lock(mutex_);
  for (auto it = lru_.begin(); it != lru_.end();) {
    auto next = std::next(it);
    // A loading entry's waiters hold its future; its Settle finds nothing to record.
    if (it->scene == scene && it->key != key) dropped.splice(dropped.end(), lru_, it);
    it = next;
  }
  if (!dropped.empty()) PublishCacheSize();
}

std::list<ObjectsService::Entry> ObjectsService::Evict() {
  std::list<Entry> evicted;
  int64_t total = 0;
  for (const Entry& e : lru_) total += static_cast<int64_t>(e.bytes);
  // Keep the newest entry whatever its size; drop loaded entries from the old end.
  if (lru_.empty()) return evicted;
  for (auto it = std::prev(lru_.end()); total > options_.cache_bytes && it != lru_.begin();) {
    auto newer = std::prev(it);
    if (it->bytes > 0) {  // not still loading
      total -= static_cast<int64_t>(it->bytes);
      evicted.splice(evicted.end(), lru_, it);
    }
    it = newer;
  }
  return evicted;
}

ObjectsService::CacheStats ObjectsService::cache_stats() const {
  std::lock_guard<std::mutex> lock(mutex_);
  CacheStats s;
  s.entries = static_cast<int64_t>(lru_.size());
  for (const Entry& e : lru_) s.bytes += static_cast<int64_t>(e.bytes);
  s.loads = loads_;
  s.hits = hits_;
  return s;
}

grpc::Status ObjectsService::GetObject(grpc::ServerContext* context,
                                       const v1::GetObjectRequest* request, v1::Object* response) {
  auto answer = [&]() -> absl::Status {
    ASSIGN_OR_RETURN(
        auth::Identity who,
        auth::Authorize(options_.auth, context, {auth::Role::kClient, auth::Role::kAdmin}));
    bool fresh = false;
    RETURN_IF_ERROR(CheckSceneName(request->scene()));
    ASSIGN_OR_RETURN(std::shared_ptr<const SceneObjects> index,
                     Index(auth::StoredScene(who, request->scene()), &fresh));
    Stopwatch watch;
    ASSIGN_OR_RETURN(uint32_t id, index->Resolve(request->selector()));
    ASSIGN_OR_RETURN(*response, index->Describe(id));
    response->set_scene(request->scene());
    response->set_query_microseconds(watch.ElapsedSeconds() * 1e6);
    response->set_index_loaded(!fresh);
    return absl::OkStatus();
  };
  return rpc::ToGrpcStatus(answer());
}

grpc::Status ObjectsService::ListObjects(grpc::ServerContext* context,
                                         const v1::ListObjectsRequest* request,
                                         v1::ListObjectsResponse* response) {
  auto answer = [&]() -> absl::Status {
    ASSIGN_OR_RETURN(
        auth::Identity who,
        auth::Authorize(options_.auth, context, {auth::Role::kClient, auth::Role::kAdmin}));
    RETURN_IF_ERROR(CheckSceneName(request->scene()));
    const int limit = request->limit() == 0 ? 100 : request->limit();
    if (limit < 0 || limit > options_.max_page)
      return absl::InvalidArgumentError(
          absl::StrCat("limit ", request->limit(), ": must be in [0, ", options_.max_page, "]"));
    uint32_t after = 0;
    if (!request->page_token().empty() && !absl::SimpleAtoi(request->page_token(), &after))
      return absl::InvalidArgumentError(
          absl::StrCat("page_token '", request->page_token().substr(0, 40),
                       "' is not one this service gave (next_page_token)"));
    bool fresh = false;
    ASSIGN_OR_RETURN(std::shared_ptr<const SceneObjects> index,
                     Index(auth::StoredScene(who, request->scene()), &fresh));
    for (uint32_t id : index->Ids()) {
      if (id <= after) continue;
      if (response->objects_size() == limit) {
        response->set_next_page_token(std::to_string(response->objects().rbegin()->id()));
        break;
      }
      v1::Object* object = response->add_objects();
      ASSIGN_OR_RETURN(*object, index->Describe(id));
      object->set_scene(request->scene());
    }
    return absl::OkStatus();
  };
  return rpc::ToGrpcStatus(answer());
}

}  // namespace instascene::objects
