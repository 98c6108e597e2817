#include "common/synth/cluttered_scene.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <random>

#include "absl/strings/str_cat.h"
#include "common/core/status.h"
#include "common/mesh/ray_caster.h"
#include "common/synth/random_objects.h"

namespace instascene {
namespace {

constexpr float kTableTopZ = 0.75f;

// Table and room size: the table grows with the object count so that clutter density stays
// similar (12 objects fit the base 1.4 m x 0.8 m table).
struct Layout {
  explicit Layout(int objects) : scale(std::max(1.0f, std::sqrt(objects / 12.0f))) {}
  float scale;
  float half_x() const { return 0.7f * scale; }
  float half_y() const { return 0.4f * scale; }
  float wall_y() const { return half_y() + 0.02f; }
};

// Builds floor, back wall and table as one mesh (with UVs) and its appearance per part.
struct StuffPart {
  TriangleMesh mesh;
  Appearance appearance;
};

std::vector<StuffPart> MakeStuff(const Layout& layout) {
  const float kTableHalfX = layout.half_x(), kTableHalfY = layout.half_y(),
              kWallY = layout.wall_y();
  std::vector<StuffPart> parts;
  Appearance floor{{0.55f, 0.45f, 0.35f}, {0.45f, 0.36f, 0.27f}, TexturePattern::kChecker, 8.0f};
  TriangleMesh floor_mesh = MakeRectangle(4.0f * layout.scale, 4.0f * layout.scale, 8, 8);
  parts.push_back({floor_mesh, floor});
  Appearance wall{
      {0.85f, 0.85f, 0.8f}, {0.75f, 0.78f, 0.8f}, TexturePattern::kNoise, 6.0f, 0.0f, 7};
  TriangleMesh wall_mesh = MakeRectangle(4.0f * layout.scale, 2.2f, 8, 4);
  Rigid3d wall_pose{
      Eigen::AngleAxisd(std::numbers::pi / 2, Eigen::Vector3d::UnitX()).toRotationMatrix(),
      Eigen::Vector3d(0, kWallY + 0.02, 1.1)};
  wall_mesh.Transform(wall_pose);
  parts.push_back({wall_mesh, wall});
  Appearance wood{{0.6f, 0.42f, 0.25f}, {0.5f, 0.34f, 0.2f}, TexturePattern::kStripes, 14.0f};
  TriangleMesh table = MakeShapeMesh({ShapeKind::kBox, {2 * kTableHalfX, 2 * kTableHalfY, 0.04f}});
  table.Transform({Eigen::Matrix3d::Identity(), Eigen::Vector3d(0, 0, kTableTopZ - 0.04)});
  for (int lx : {-1, 1}) {
    for (int ly : {-1, 1}) {
      TriangleMesh leg = MakeShapeMesh({ShapeKind::kBox, {0.05f, 0.05f, kTableTopZ - 0.04f}});
      leg.Transform({Eigen::Matrix3d::Identity(),
                     Eigen::Vector3d(lx * (kTableHalfX - 0.05), ly * (kTableHalfY - 0.05), 0)});
      table.Append(leg);
    }
  }
  parts.push_back({table, wood});
  return parts;
}

struct Placement {
  Eigen::Vector2f xy;
  float radius;
};

bool Fits(const Layout& layout, const std::vector<Placement>& placed, const Eigen::Vector2f& xy,
          float radius) {
  const float kTableHalfX = layout.half_x(), kTableHalfY = layout.half_y(),
              kWallY = layout.wall_y();
  if (std::abs(xy.x()) > kTableHalfX - radius - 0.01f || xy.y() < -kTableHalfY + radius + 0.01f ||
      xy.y() > kWallY - radius - 0.005f) {
    return false;
  }
  for (const Placement& p : placed) {
    if ((p.xy - xy).norm() < p.radius + radius + 0.002f) return false;
  }
  return true;
}

// Appends a copy of surfel i of `from` at p with both scales log_sigma (rotation, opacity and
// colour kept).
void AppendSurfelCopy(const GaussianCloud& from, size_t i, const Eigen::Vector3f& p,
                      float log_sigma, GaussianCloud* out) {
  const int stride = from.sh_stride();
  for (int a = 0; a < 3; ++a) out->positions.push_back(p[a]);
  for (int a = 0; a < from.num_scales; ++a) out->log_scales.push_back(log_sigma);
  for (int a = 0; a < 4; ++a) out->rotations.push_back(from.rotations[4 * i + a]);
  out->opacity_logits.push_back(from.opacity_logits[i]);
  out->sh.insert(out->sh.end(), from.sh.begin() + stride * i, from.sh.begin() + stride * (i + 1));
}

// Splits every table-top surfel whose 2-sigma disc reaches an object's footprint circle into
// detail x detail surfels of sigma / detail tiling its sampling cell (same orientation, opacity and
// colour); the parts an object stands over (never seen) are dropped. Surfels are
// composited in the order of their centres' depth, so one large table disc whose centre lies in
// front of a low object paints the table over it: bowls rendered see-through and tori vanished
// from most views. A 2DGS model trained on photographs cannot keep such a disc (the photometric
// loss splits it), so the table is refined where objects stand, as densification would.
absl::Status RefineTableNearObjects(const std::vector<Placement>& placed,
                                    const std::vector<SynthObject>& objects, int detail,
                                    GaussianCloud* cloud) {
  if (detail <= 1) return absl::OkStatus();
  TriangleMesh object_meshes;
  for (const SynthObject& o : objects) object_meshes.Append(o.mesh);
  ASSIGN_OR_RETURN(std::unique_ptr<RayCaster> caster, RayCaster::Create(object_meshes));
  auto covered = [&](const Eigen::Vector3f& p) {  // an object stands over p
    return caster->Cast(p - Eigen::Vector3f(0, 0, 1e-4f), Eigen::Vector3f::UnitZ()).hit;
  };
  auto footprint_gap = [&](const Eigen::Vector2f& xy) {
    float gap = std::numeric_limits<float>::infinity();
    for (const Placement& p : placed) gap = std::min(gap, (xy - p.xy).norm() - p.radius);
    return gap;
  };
  GaussianCloud out;
  out.num_scales = cloud->num_scales;
  out.sh_degree = cloud->sh_degree;
  std::vector<size_t> source;  // per output surfel, the surfel it came from
  auto append = [&](size_t i, const Eigen::Vector3f& p, float log_sigma) {
    AppendSurfelCopy(*cloud, i, p, log_sigma, &out);
    source.push_back(i);
  };
  for (size_t i = 0; i < cloud->size(); ++i) {
    const Eigen::Vector3f p(cloud->positions[3 * i], cloud->positions[3 * i + 1],
                            cloud->positions[3 * i + 2]);
    const float sigma = std::exp(cloud->log_scales[cloud->num_scales * i]);
    if (std::abs(p.z() - kTableTopZ) > 1e-4f || footprint_gap(p.head<2>()) > 2 * sigma) {
      append(i, p, cloud->log_scales[cloud->num_scales * i]);
      continue;
    }
    const float cell = sigma / SurfelSampling().scale_factor;  // the sampling spacing
    for (int a = 0; a < detail; ++a) {
      for (int b = 0; b < detail; ++b) {
        const Eigen::Vector3f q =
            p + cell * Eigen::Vector3f((a + 0.5f) / detail - 0.5f, (b + 0.5f) / detail - 0.5f, 0);
        if (footprint_gap(q.head<2>()) < 0.0f && covered(q)) continue;
        append(i, q, std::log(sigma / detail));
      }
    }
  }
  out.extras = cloud->extras;
  for (ExtraChannel& e : out.extras) {  // each output surfel's value is its source's
    std::vector<float> values(source.size());
    for (size_t k = 0; k < source.size(); ++k) values[k] = e.values[source[k]];
    e.values = std::move(values);
  }
  *cloud = std::move(out);
  return absl::OkStatus();
}

// A free spot for a footprint of `radius` (up to 400 tries): next in the duplicates' touching
// row, touching a placed neighbour (60 % of the first 200 tries), or anywhere (duplicates in the
// table's back left quarter). Draws from `rng` in the same order whatever it finds.
bool FindSpot(const Layout& layout, const std::vector<Placement>& placed, bool is_dup,
              bool row_continues, float radius, Rng& rng, Eigen::Vector2f* xy) {
  const float kTableHalfX = layout.half_x(), kTableHalfY = layout.half_y(),
              kWallY = layout.wall_y();
  bool ok = false;
  for (int attempt = 0; attempt < 400 && !ok; ++attempt) {
    if (row_continues) {  // a touching row
      *xy = placed.back().xy + Eigen::Vector2f(placed.back().radius + radius + 0.003f, 0);
    } else if (!placed.empty() && attempt < 200 && rng.Uniform(0, 1) < 0.6f) {  // touch a neighbour
      const Placement& n = placed[rng.Int(0, static_cast<int>(placed.size()) - 1)];
      const float a = rng.Uniform(0, 2 * std::numbers::pi_v<float>);
      *xy = n.xy + (n.radius + radius + 0.003f) * Eigen::Vector2f(std::cos(a), std::sin(a));
    } else if (is_dup) {
      *xy = {rng.Uniform(-0.6f * kTableHalfX, -0.1f), rng.Uniform(0.0f, 0.6f * kTableHalfY)};
    } else {
      *xy = {rng.Uniform(-kTableHalfX, kTableHalfX), rng.Uniform(-kTableHalfY, kWallY)};
    }
    ok = Fits(layout, placed, *xy, radius);
  }
  return ok;
}

// 1. Objects: shapes, appearances, placements on the table top (their footprints in `placed`).
absl::Status PlaceObjects(const ClutterOptions& options, const Layout& layout, Rng& rng,
                          ClutterScene* out, std::vector<Placement>* out_placed) {
  ClutterScene& scene = *out;
  std::vector<Placement>& placed = *out_placed;
  const int dup = options.duplicates >= 2 ? std::min(options.duplicates, options.objects) : 0;
  ShapeSpec dup_shape{ShapeKind::kBottle, {0.035f, 0, 0.22f}};
  Appearance dup_look = RandomAppearance(rng, options.sh_degree);
  for (int k = 0; k < options.objects; ++k) {
    SynthObject obj;
    obj.id = k + 1;
    const bool is_dup = k < dup;
    obj.shape = is_dup ? dup_shape : RandomShape(rng);
    if (!is_dup && options.asymmetric_share > 0 && rng.Uniform(0, 1) < options.asymmetric_share) {
      obj.shape = AsymmetricShape(rng);
    }
    obj.appearance = is_dup ? dup_look : RandomAppearance(rng, options.sh_degree);
    obj.duplicate_group = is_dup ? 0 : -1;
    // Some neighbours share a colour (but keep their own pattern).
    if (!is_dup && k > dup && rng.Uniform(0, 1) < 0.25f)
      obj.appearance.color_a = scene.objects.back().appearance.color_a;
    const float radius = obj.shape.FootprintRadius();
    Eigen::Vector2f xy;
    const bool ok =
        FindSpot(layout, placed, is_dup, /*row_continues=*/is_dup && k > 0, radius, rng, &xy);
    if (!ok) {
      return absl::ResourceExhaustedError(absl::StrCat("could not place ", options.objects,
                                                       " objects on the table; use fewer objects"));
    }
    placed.push_back({xy, radius});
    const double yaw = rng.Uniform(0, 2 * std::numbers::pi_v<float>);
    obj.world_from_object = {Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix(),
                             Eigen::Vector3d(xy.x(), xy.y(), kTableTopZ)};
    obj.mesh = MakeShapeMesh(obj.shape);
    obj.mesh.Transform(obj.world_from_object);
    obj.name = absl::StrCat(ShapeKindName(obj.shape.kind), "_", obj.id);
    scene.objects.push_back(std::move(obj));
  }
  return absl::OkStatus();
}

// 2. Surfels: stuff first, then objects, each group split by surface area.
absl::Status SampleSurfels(const ClutterOptions& options, const Layout& layout,
                           const std::vector<Placement>& placed, Rng& rng, ClutterScene* out) {
  ClutterScene& scene = *out;
  scene.cloud.num_scales = 2;
  scene.cloud.sh_degree = options.sh_degree;
  SurfelSampling sampling;
  std::vector<StuffPart> stuff = MakeStuff(layout);
  const size_t stuff_budget = static_cast<size_t>(options.stuff_fraction * options.gaussians);
  double stuff_area = 0, object_area = 0;
  for (const StuffPart& p : stuff) stuff_area += p.mesh.SurfaceArea();
  for (const SynthObject& o : scene.objects) object_area += o.mesh.SurfaceArea();
  size_t used = 0;
  for (size_t p = 0; p < stuff.size(); ++p) {
    const size_t count =
        p + 1 == stuff.size()
            ? stuff_budget - used
            : static_cast<size_t>(stuff_budget * stuff[p].mesh.SurfaceArea() / stuff_area);
    AppendSurfels(stuff[p].mesh, count, stuff[p].appearance, sampling, rng.engine, &scene.cloud);
    used += count;
    scene.stuff_mesh.Append(stuff[p].mesh);
  }
  RETURN_IF_ERROR(
      RefineTableNearObjects(placed, scene.objects, options.table_detail, &scene.cloud));
  scene.instance_ids.assign(scene.cloud.size(), 0);
  const size_t object_budget = options.gaussians - stuff_budget;
  size_t object_used = 0;
  for (size_t k = 0; k < scene.objects.size(); ++k) {
    SynthObject& obj = scene.objects[k];
    const size_t count =
        k + 1 == scene.objects.size()
            ? object_budget - object_used
            : static_cast<size_t>(object_budget * obj.mesh.SurfaceArea() / object_area);
    // A cone's apex carries a surfel: area sampling leaves it bare (until 2026-12-06 cones had
    // none, their highest surfel 4-13 % of the height below the apex; docs/SYNTHETIC.md).
    std::vector<SurfelApex> apices;
    for (const ShapeTip& tip : ShapeTips(obj.shape)) {
      apices.push_back({(obj.world_from_object * tip.position.cast<double>()).cast<float>(),
                        (obj.world_from_object.rotation * Eigen::Vector3d::UnitZ()).cast<float>(),
                        tip.uv});
    }
    obj.first_gaussian = scene.cloud.size();
    obj.num_gaussians = count + apices.size();
    AppendSurfels(obj.mesh, count, obj.appearance, sampling, rng.engine, &scene.cloud, 0.0f,
                  apices);
    object_used += count;
    scene.instance_ids.resize(scene.cloud.size(), static_cast<uint16_t>(obj.id));
  }
  return absl::OkStatus();
}

// 3. Cameras: a handheld-like sweep over the front half at three heights, with jitter.
void PlaceCameras(const ClutterOptions& options, const Layout& layout, Rng& rng,
                  ClutterScene* out) {
  ClutterScene& scene = *out;
  for (int v = 0; v < options.views; ++v) {
    const int ring = v % 3;
    const float t = options.views == 1 ? 0.5f : static_cast<float>(v) / (options.views - 1);
    const float azimuth = -160.0f + 140.0f * t + rng.Uniform(-4.0f, 4.0f);
    const float elevation = 22.0f + 14.0f * ring + rng.Uniform(-3.0f, 3.0f);
    const float distance = layout.scale * rng.Uniform(0.95f, 1.25f);
    const Eigen::Vector3d target =
        scene.focus + Eigen::Vector3d(rng.Uniform(-0.04f, 0.04f), rng.Uniform(-0.04f, 0.04f),
                                      rng.Uniform(-0.02f, 0.02f));
    scene.cameras.push_back(OrbitCamera(target, Eigen::Vector3d::UnitZ(), distance, azimuth,
                                        elevation, options.width, options.height,
                                        options.fov_x_deg));
  }
}

}  // namespace

absl::Status ClutterOptions::Validate() const {
  if (objects < 1 || objects > 200) return absl::InvalidArgumentError("objects must be in 1..200");
  if (views < 1 || views > 2000) return absl::InvalidArgumentError("views must be in 1..2000");
  if (width < 16 || height < 16 || width > 8192 || height > 8192) {
    return absl::InvalidArgumentError("image size must be in 16..8192");
  }
  if (gaussians < size_t{200} * static_cast<size_t>(objects) || gaussians > 50'000'000) {
    return absl::InvalidArgumentError(
        absl::StrCat("gaussians must be in ", 200 * objects, "..5e7 (200 per object)"));
  }
  if (!(stuff_fraction >= 0.05f && stuff_fraction <= 0.9f))
    return absl::InvalidArgumentError("stuff_fraction must be in 0.05..0.9");
  if (sh_degree < 0 || sh_degree > 1) return absl::InvalidArgumentError("sh_degree must be 0 or 1");
  if (!(asymmetric_share >= 0.0f && asymmetric_share <= 1.0f))
    return absl::InvalidArgumentError("asymmetric_share must be in 0..1");
  if (table_detail < 1 || table_detail > 8)
    return absl::InvalidArgumentError("table_detail must be in 1..8");
  return absl::OkStatus();
}

absl::StatusOr<ClutterOptions> ClutterPreset(const std::string& name) {
  ClutterOptions o;
  if (name == "tiny") {
    o.objects = 5;
    o.views = 12;
    o.width = 96;
    o.height = 72;
    o.gaussians = 8000;
  } else if (name == "small" || name.empty()) {
    // the defaults
  } else if (name == "medium") {
    o.objects = 20;
    o.views = 100;
    o.width = 640;
    o.height = 480;
    o.gaussians = 300'000;
  } else if (name == "large") {
    o.objects = 40;
    o.views = 200;
    o.width = 1280;
    o.height = 720;
    o.gaussians = 1'000'000;
  } else {
    return absl::InvalidArgumentError(
        absl::StrCat("unknown preset '", name, "' (tiny, small, medium, large)"));
  }
  return o;
}

absl::StatusOr<ClutterScene> GenerateClutterScene(const ClutterOptions& options) {
  if (absl::Status s = options.Validate(); !s.ok()) return s;
  Rng rng{std::mt19937_64(options.seed)};
  const Layout layout(options.objects);
  ClutterScene scene;
  scene.focus = Eigen::Vector3d(0, 0.05, kTableTopZ + 0.08);
  std::vector<Placement> placed;
  RETURN_IF_ERROR(PlaceObjects(options, layout, rng, &scene, &placed));
  RETURN_IF_ERROR(SampleSurfels(options, layout, placed, rng, &scene));
  PlaceCameras(options, layout, rng, &scene);
  return scene;
}

}  // namespace instascene
