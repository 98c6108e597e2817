// services/objects/scene_objects.h: the loaded index of one scene's objects, what the Objects
// service answers from. Built from stored results only:
//   - the scene (scene.json and its splat; images and masks are not read),
//   - its `segment` output (per-Gaussian instance labels): click, point and ray lookups through a
//     QueryIndex (every view's label map rendered once; a k-d tree over the Gaussians),
//   - its `export` output when there is one (objects.json and each object's manifest.json: pose,
//     metric size, artefact digests), else its `complete` outputs (the completed objects), else
//     the segmentation's per-instance summary (a raw crop, no artefacts but the instance's splat).
// Every file is read from the store into memory and verified against its digest; nothing is
// written to disk. Immutable once loaded: queries are const and safe from many threads.
#pragma once

#include <atomic>
#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "absl/status/statusor.h"
#include "common/store/blob_store.h"
#include "common/store/manifest.h"
#include "instascene/v1/objects.pb.h"
#include "services/objects/query_index.h"

namespace instascene::objects {

// The stored results one index is built from (the scheduler's latest outputs of a scene).
struct SceneOutputs {
  std::string scene;                          // name
  store::Digest scene_manifest;               // the submission the segment output was computed from
  store::Digest segment;                      // `segment` output (required)
  std::optional<store::Digest> exported;      // `export` output
  std::map<int64_t, store::Digest> complete;  // item -> `complete` output
  // Identifies the index: equal keys give equal answers.
  std::string Key() const;
};

class SceneObjects {
 public:
  static absl::StatusOr<std::unique_ptr<SceneObjects>> Load(store::BlobStore& store,
                                                            const SceneOutputs& outputs);

  // The object a selector names: NOT_FOUND (with what was asked) when nothing is there,
  // INVALID_ARGUMENT / OUT_OF_RANGE for a malformed selector.
  absl::StatusOr<uint32_t> Resolve(const v1::ObjectSelector& selector) const;
  // The answer for an object id (NOT_FOUND if the scene has no such object).
  absl::StatusOr<v1::Object> Describe(uint32_t id) const;
  // Every object id, ascending.
  std::vector<uint32_t> Ids() const;
  // Approximate memory held (label maps, Gaussians, k-d tree, manifests): the cache's unit.
  size_t ByteSize() const { return bytes_; }
  // Load renders no label map: a cold start answers points and ids at once, and a background
  // thread then renders every view in order; a click in a view not yet rendered renders it first.
  int Views() const { return static_cast<int>(scene_.views.size()); }

  ~SceneObjects();

 private:
  SceneObjects() = default;
  // Load's steps: the scene (scene.json and the splat), the segment output's labels into the
  // query index, and what the loaded scene holds in memory.
  absl::Status LoadScene(store::BlobStore& store);
  absl::Status IndexLabels(store::BlobStore& store, const store::Manifest& segment);
  size_t HeldBytes() const;
  absl::Status LoadExport(store::BlobStore& store, const store::Digest& digest);
  absl::Status LoadCompleted(store::BlobStore& store,
                             const std::map<int64_t, store::Digest>& items);
  // The splats a viewer shows, on every object: "splat.ply" (the raw crop of the segmentation)
  // and, where the object was completed, "object.ply" (the completed splat).
  absl::Status AddSplats(store::BlobStore& store, const store::Manifest& segment,
                         const std::map<int64_t, store::Digest>& complete);
  void AddSegmentOnly(const store::Manifest& segment);
  // An answer's common fields: scene, id, source, units, observed Gaussians, segment digest.
  v1::Object NewObject(uint32_t id, const std::string& source) const;
  // Resolve's selectors: the object nearest a point, under a pixel, along a ray (NOT_FOUND when
  // none).
  absl::StatusOr<uint32_t> ResolvePoint(const v1::Vector3& p, double max_distance) const;
  absl::StatusOr<uint32_t> ResolveClick(const v1::PixelClick& c) const;
  absl::StatusOr<uint32_t> ResolveRay(const v1::Ray& r) const;

  SceneOutputs outputs_;
  Scene scene_;
  GaussianCloud cloud_;
  std::unique_ptr<QueryIndex> index_;
  float default_radius_ = 0;  // 2 % of the scene's robust diagonal
  float max_radius_ = 0;      // the diagonal
  std::optional<double> meters_per_unit_;
  std::map<uint32_t, v1::Object> objects_;  // id -> answer (query fields unset)
  size_t bytes_ = 0;
  std::atomic<bool> stop_{false};
  std::thread warm_up_;  // renders every view's label map after Load
};

}  // namespace instascene::objects
