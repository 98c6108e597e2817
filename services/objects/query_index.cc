#include "services/objects/query_index.h"

#include "absl/strings/str_cat.h"
#include "common/core/status.h"
#include "common/raster/label_render.h"
#include "common/scene/image_io.h"

namespace instascene::objects {

absl::StatusOr<std::unique_ptr<QueryIndex>> QueryIndex::Build(const Scene& scene,
                                                              const GaussianCloud& cloud,
                                                              const SegmentationResult& result,
                                                              int num_threads, bool eager) {
  if (result.labels.size() != cloud.size())
    return absl::InvalidArgumentError("result and scene disagree on the Gaussian count");
  auto index = std::unique_ptr<QueryIndex>(new QueryIndex());
  index->scene_ = &scene;
  index->cloud_ = &cloud;
  index->labels_ = result.labels;
  index->num_threads_ = num_threads;
  for (uint32_t g = 0; g < result.labels.size(); ++g) {
    if (result.labels[g] != 0) index->members_[result.labels[g]].push_back(g);
  }
  for (size_t v = 0; v < scene.views.size(); ++v)
    index->views_.push_back(std::make_unique<LazyView>());
  if (eager) {
    for (size_t v = 0; v < scene.views.size(); ++v) {
      ASSIGN_OR_RETURN(const std::vector<uint32_t>* map, index->LabelMap(static_cast<int>(v)));
      std::map<uint32_t, size_t> counts;
      for (uint32_t l : *map) {
        if (l != 0) ++counts[l];
      }
      for (const auto& [l, c] : counts) index->visible_[l].emplace_back(static_cast<int>(v), c);
    }
  }
  // Point queries look for the nearest object: only labelled Gaussians are indexed (a table
  // Gaussian nearer than the object must not hide it).
  std::vector<Eigen::Vector3f> positions;
  for (size_t g = 0; g < cloud.size(); ++g) {
    if (result.labels[g] == 0) continue;
    positions.emplace_back(&cloud.positions[3 * g]);
    index->point_labels_.push_back(result.labels[g]);
  }
  index->points_ = std::make_unique<PointIndex3>(std::move(positions));
  return index;
}

absl::StatusOr<const std::vector<uint32_t>*> QueryIndex::LabelMap(int view) const {
  LazyView& v = *views_[view];
  std::call_once(v.once, [&] {
    absl::StatusOr<std::vector<uint32_t>> map =
        RenderLabelMap(*cloud_, scene_->views[view].camera, labels_, 0.5f, num_threads_);
    if (map.ok()) {
      v.map = std::move(*map);
    } else {
      v.status = map.status();
    }
  });
  if (!v.status.ok()) return v.status;
  return &v.map;
}

QueryAnswer QueryIndex::Answer(uint32_t instance) const {
  QueryAnswer answer;
  answer.instance = instance;
  if (instance == 0) return answer;
  answer.gaussians = Gaussians(instance).size();
  auto it = visible_.find(instance);
  if (it != visible_.end()) answer.views = it->second;
  return answer;
}

absl::StatusOr<QueryAnswer> QueryIndex::Click(int view, int x, int y) const {
  if (view < 0 || view >= static_cast<int>(views_.size()))
    return absl::OutOfRangeError(absl::StrCat("no view ", view));
  const PinholeCamera& camera = scene_->views[view].camera;
  if (x < 0 || y < 0 || x >= camera.width || y >= camera.height) {
    return absl::OutOfRangeError(absl::StrCat("pixel (", x, ", ", y, ") outside the ", camera.width,
                                              "x", camera.height, " image"));
  }
  ASSIGN_OR_RETURN(const std::vector<uint32_t>* map, LabelMap(view));
  return Answer((*map)[static_cast<size_t>(y) * camera.width + x]);
}

absl::StatusOr<QueryAnswer> QueryIndex::Point(const Eigen::Vector3f& point,
                                              float max_distance) const {
  if (!point.allFinite()) return absl::InvalidArgumentError("query point is not finite");
  if (points_->size() == 0) return Answer(0);
  const auto [g, dist2] = points_->Nearest(point);
  return Answer(dist2 <= max_distance * max_distance ? point_labels_[g] : 0);
}

absl::StatusOr<QueryAnswer> QueryIndex::Ray(const Eigen::Vector3f& origin,
                                            const Eigen::Vector3f& direction) const {
  if (!origin.allFinite() || !direction.allFinite() || direction.norm() < 1e-12f) {
    return absl::InvalidArgumentError(
        "ray origin and direction must be finite, direction non-zero");
  }
  // A 1x1 camera: its only pixel centre lies on the optical axis.
  const Eigen::Vector3d forward = direction.cast<double>().normalized();
  const Eigen::Vector3d helper =
      std::abs(forward.z()) < 0.9 ? Eigen::Vector3d::UnitZ() : Eigen::Vector3d::UnitX();
  PinholeCamera camera;
  camera.width = camera.height = 1;
  camera.fx = camera.fy = 1000.0;
  camera.cx = camera.cy = 0.5;
  camera.camera_from_world = LookAt(origin.cast<double>(), origin.cast<double>() + forward, helper);
  ASSIGN_OR_RETURN(std::vector<uint32_t> map, RenderLabelMap(*cloud_, camera, labels_, 0.5f));
  return Answer(map[0]);
}

std::vector<uint8_t> QueryIndex::Mask(uint32_t instance, int view) const {
  const PinholeCamera& camera = scene_->views[view].camera;
  std::vector<uint8_t> mask(static_cast<size_t>(camera.width) * camera.height, 0);
  absl::StatusOr<const std::vector<uint32_t>*> map = LabelMap(view);
  if (!map.ok()) return mask;
  if (instance == 0) return mask;
  for (size_t p = 0; p < mask.size(); ++p) mask[p] = (**map)[p] == instance;
  return mask;
}

const std::vector<uint32_t>& QueryIndex::Gaussians(uint32_t instance) const {
  static const std::vector<uint32_t> kEmpty;
  auto it = members_.find(instance);
  return it == members_.end() ? kEmpty : it->second;
}

std::vector<uint32_t> QueryIndex::Instances() const {
  std::vector<uint32_t> ids;
  for (const auto& [id, members] : members_) ids.push_back(id);
  return ids;
}

size_t QueryIndex::ByteSize() const {
  size_t bytes = sizeof(uint32_t) * 2 * labels_.size();  // labels + members
  bytes += (sizeof(Eigen::Vector3f) + 3 * sizeof(uint32_t)) * point_labels_.size();  // k-d tree
  for (const SceneView& v : scene_->views)  // every label map, rendered or not yet
    bytes += sizeof(uint32_t) * static_cast<size_t>(v.camera.width) * v.camera.height;
  return bytes;
}

}  // namespace instascene::objects
