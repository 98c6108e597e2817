#include "common/synth/splat_composite.h"

#include <algorithm>
#include <cmath>
#include <random>

#include "absl/strings/str_cat.h"
#include "common/core/status.h"

namespace instascene {
namespace {

// A capture's scale (to the object height), footprint radius and bottom centre (its frame).
struct Placement {
  float scale, radius;
  Eigen::Vector3f bottom_center;
};

Placement PlaceCapture(const GaussianCloud& c, float object_height) {
  const Eigen::AlignedBox3f box = RobustBounds(c);
  const float x0 = box.min().x(), x1 = box.max().x(), y0 = box.min().y(), y1 = box.max().y();
  const float z0 = box.min().z(), z1 = box.max().z();
  const float scale = object_height / std::max(y1 - y0, 1e-6f);
  const float radius = 0.5f * scale * std::hypot(x1 - x0, z1 - z0);  // circumscribed: no overlap
  return {scale, radius, Eigen::Vector3f(0.5f * (x0 + x1), y1, 0.5f * (z0 + z1))};
}

// Appends `source` scaled by p.scale about its bottom centre and moved to `offset`.
void AppendPlaced(const GaussianCloud& source, const Placement& p, const Eigen::Vector3f& offset,
                  GaussianCloud* cloud) {
  const int stride = cloud->sh_stride();
  const size_t base = cloud->size(), n = source.size();
  cloud->positions.resize(3 * (base + n));
  cloud->log_scales.resize(cloud->num_scales * (base + n));
  cloud->rotations.resize(4 * (base + n));
  cloud->opacity_logits.resize(base + n);
  cloud->sh.resize(static_cast<size_t>(stride) * (base + n), 0.0f);
  const float log_scale = std::log(p.scale);
  const int source_stride = source.sh_stride();
  for (size_t i = 0; i < n; ++i) {
    const Eigen::Vector3f pos(&source.positions[3 * i]);
    const Eigen::Vector3f placed = p.scale * (pos - p.bottom_center) + offset;
    for (int a = 0; a < 3; ++a) cloud->positions[3 * (base + i) + a] = placed[a];
    for (int a = 0; a < cloud->num_scales; ++a) {
      cloud->log_scales[cloud->num_scales * (base + i) + a] =
          source.log_scales[source.num_scales * i + a] + log_scale;
    }
    std::copy_n(&source.rotations[4 * i], 4, &cloud->rotations[4 * (base + i)]);
    cloud->opacity_logits[base + i] = source.opacity_logits[i];
    std::copy_n(&source.sh[static_cast<size_t>(source_stride) * i], source_stride,
                &cloud->sh[static_cast<size_t>(stride) * (base + i)]);
  }
}

// Cameras all around, at several heights, looking at the middle of the row (up is -y).
void AddOrbitCameras(const CompositeOptions& options, float row_length, std::mt19937_64& rng,
                     ClutterScene* scene) {
  std::uniform_real_distribution<float> uni(0.0f, 1.0f);
  scene->focus = Eigen::Vector3d(0, -0.5 * options.object_height, 0);
  const double extent = 0.5 * row_length + options.object_height;
  const double tan_half = std::tan(0.5 * options.fov_x_deg * 3.14159265358979 / 180.0);
  for (int v = 0; v < options.views; ++v) {
    const float azimuth = 360.0f * static_cast<float>(v) / options.views + 6.0f * (uni(rng) - 0.5f);
    const float elevation = 8.0f + 12.0f * (v % 3) + 4.0f * (uni(rng) - 0.5f);
    const double distance = 0.8 * extent / tan_half * (1.0 + 0.15 * uni(rng));
    scene->cameras.push_back(OrbitCamera(scene->focus, Eigen::Vector3d(0, -1, 0), distance, azimuth,
                                         elevation, options.width, options.height,
                                         options.fov_x_deg));
  }
}

// What the composite is made of: surfels when any input is (3DGS inputs are then turned into
// surfels), the highest SH degree.
struct CompositeKind {
  int num_scales = 3;
  int sh_degree = 0;
  bool to_surfels = false;  // 2DGS and 3DGS inputs mixed
};

absl::StatusOr<CompositeKind> InspectInputs(const std::vector<GaussianCloud>& input,
                                            const std::vector<std::string>& names) {
  if (input.empty()) return absl::InvalidArgumentError("no splats to compose");
  if (names.size() != input.size())
    return absl::InvalidArgumentError("one name per splat is required");
  if (input.size() > 1000) return absl::InvalidArgumentError("at most 1000 splats per composite");
  bool any_surfel = false, any_ellipsoid = false;
  CompositeKind kind;
  for (size_t k = 0; k < input.size(); ++k) {
    if (input[k].size() < 10)
      return absl::InvalidArgumentError(absl::StrCat(names[k], ": fewer than 10 Gaussians"));
    any_surfel |= input[k].num_scales == 2;
    any_ellipsoid |= input[k].num_scales == 3;
    kind.sh_degree = std::max(kind.sh_degree, input[k].sh_degree);
  }
  kind.to_surfels = any_surfel && any_ellipsoid;
  kind.num_scales = kind.to_surfels || any_surfel ? 2 : 3;
  return kind;
}

}  // namespace

absl::StatusOr<ClutterScene> ComposeSplats(const std::vector<GaussianCloud>& input,
                                           const std::vector<std::string>& names,
                                           const CompositeOptions& options) {
  ASSIGN_OR_RETURN(const CompositeKind kind, InspectInputs(input, names));
  const bool to_surfels = kind.to_surfels;
  ClutterScene scene;
  scene.cloud.num_scales = kind.num_scales;
  scene.cloud.sh_degree = kind.sh_degree;
  std::mt19937_64 rng(options.seed);
  std::uniform_real_distribution<float> uni(0.0f, 1.0f);
  // Scale and footprint of each capture.
  std::vector<Placement> placements;
  float row_length = 0;
  for (const GaussianCloud& c : input) {
    placements.push_back(PlaceCapture(c, options.object_height));
    row_length += 2 * placements.back().radius + options.gap * options.object_height;
  }
  float cursor = -0.5f * row_length;
  for (size_t k = 0; k < input.size(); ++k) {
    const GaussianCloud source = to_surfels ? ToSurfels(input[k]) : input[k];
    const Placement& p = placements[k];
    cursor += p.radius;
    // Alternate objects slightly forward and back so neighbours overlap in oblique views.
    const float depth = (k % 2 == 0 ? -1.0f : 1.0f) * 0.35f * p.radius * uni(rng);
    const Eigen::Vector3f offset(cursor, 0.0f, depth);
    cursor += p.radius + options.gap * options.object_height;
    SynthObject obj;
    obj.id = static_cast<int>(k) + 1;
    obj.name = names[k];
    obj.first_gaussian = scene.cloud.size();
    obj.num_gaussians = source.size();
    obj.scale = p.scale;
    obj.world_from_object = {Eigen::Matrix3d::Identity(),
                             (offset - p.scale * p.bottom_center).cast<double>()};
    AppendPlaced(source, p, offset, &scene.cloud);
    scene.instance_ids.resize(scene.cloud.size(), static_cast<uint16_t>(obj.id));
    scene.objects.push_back(std::move(obj));
  }
  AddOrbitCameras(options, row_length, rng, &scene);
  return scene;
}

}  // namespace instascene
