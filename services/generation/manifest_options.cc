#include "services/generation/manifest_options.h"

namespace instascene::generation {
namespace {

Eigen::Vector3f Vec3(const nlohmann::json& j) {
  return {j.at(0).get<float>(), j.at(1).get<float>(), j.at(2).get<float>()};
}

}  // namespace

ObjectFrame FrameFromManifest(const nlohmann::json& m) {
  ObjectFrame f;
  const nlohmann::json& j = m.at("frame");
  f.center = Vec3(j.at("center"));
  f.up = Vec3(j.at("up"));
  f.radius = j.at("radius").get<float>();
  f.spacing = j.at("spacing").get<float>();
  if (j.contains("bottom")) f.bottom_height = j["bottom"].get<float>();
  f.has_support = !j.at("support").is_null();
  if (f.has_support) f.support_height = j.at("support").get<float>();
  return f;
}

FreeSpaceOptions FreeSpaceFromManifest(const nlohmann::json& m) {
  FreeSpaceOptions f;
  if (!m.contains("free_space")) return f;  // manifests before 2026-12-05 ran the defaults
  const nlohmann::json& j = m["free_space"];
  f.resolution = j.value("resolution", f.resolution);
  f.extent_radii = j.value("extent_radii", f.extent_radii);
  f.min_views = j.value("min_views", f.min_views);
  f.margin_voxels = j.value("margin_voxels", f.margin_voxels);
  f.max_rays_per_view = j.value("max_rays_per_view", f.max_rays_per_view);
  f.hole_rays = j.value("hole_rays", f.hole_rays);
  f.hole_slack = j.value("hole_slack", f.hole_slack);
  return f;
}

MeshingOptions MeshingFromManifest(const nlohmann::json& m) {
  MeshingOptions meshing;
  if (!m.contains("meshing")) return meshing;
  const nlohmann::json& j = m["meshing"];
  meshing.size_px = j.value("size_px", meshing.size_px);
  meshing.min_alpha = j.value("min_alpha", meshing.min_alpha);
  // Manifests written before the inset meshed without it.
  meshing.inset_sigmas = j.value("inset_sigmas", 0.0f);
  // And before the silhouette carving without it.
  meshing.carve_views = j.value("carve_views", 0);
  meshing.empty_alpha = j.value("empty_alpha", meshing.empty_alpha);
  meshing.empty_close_px = j.value("empty_close_px", 0.0f);
  // And before the snap without it.
  meshing.snap_radius_spacings = j.value("snap_radius_spacings", 0.0f);
  meshing.snap_layer_spacings = j.value("snap_layer_spacings", meshing.snap_layer_spacings);
  meshing.snap_max_voxels = j.value("snap_max_voxels", meshing.snap_max_voxels);
  meshing.snap_reach_spacings = j.value("snap_reach_spacings", 0.0f);
  // And before the base's slide with a fixed base.
  meshing.snap_base_across = j.value("snap_base_across", false);
  meshing.base_on_support = j.value("base_on_support", false);
  // And before the rim's extension without it.
  meshing.rim_to_side = j.value("rim_to_side", false);
  // And before the visual hull without it.
  meshing.enclose_hull = j.value("enclose_hull", false);
  // And before the top and side clamps without them.
  meshing.top_at_highest_surfel = j.value("top_at_highest_surfel", false);
  meshing.sides_within_surfels = j.value("sides_within_surfels", false);
  meshing.sides_within_order_axis_copies = j.value("sides_within_order_axis_copies", false);
  return meshing;
}

RingOptions RingFromManifest(const nlohmann::json& m, std::vector<bool>* known) {
  const nlohmann::json& views = m.at("ring");
  RingOptions ring;
  ring.views = static_cast<int>(views.size());
  if (!views.empty()) ring.elevation_deg = views[0].value("elevation_deg", 30.0);
  if (m.contains("ring_camera")) {
    ring.size_px = m["ring_camera"].value("size_px", ring.size_px);
    ring.focal_px = m["ring_camera"].value("focal_px", ring.focal_px);
    ring.distance_radii = m["ring_camera"].value("distance_radii", ring.distance_radii);
  }
  known->clear();
  for (const nlohmann::json& v : views) known->push_back(v.value("known", false));
  return ring;
}

nlohmann::json FreeSpaceToManifest(const FreeSpaceOptions& f) {
  return {{"resolution", f.resolution},
          {"extent_radii", f.extent_radii},
          {"min_views", f.min_views},
          {"margin_voxels", f.margin_voxels},
          {"max_rays_per_view", f.max_rays_per_view},
          {"hole_rays", f.hole_rays},
          {"hole_slack", f.hole_slack}};
}

nlohmann::json MeshingToManifest(const MeshingOptions& m) {
  return {{"size_px", m.size_px},
          {"azimuths", m.azimuths},
          {"voxel_radii", m.voxel_radii},
          {"min_alpha", m.min_alpha},
          {"inset_sigmas", m.inset_sigmas},
          {"snap_radius_spacings", m.snap_radius_spacings},
          {"snap_layer_spacings", m.snap_layer_spacings},
          {"snap_max_voxels", m.snap_max_voxels},
          {"snap_reach_spacings", m.snap_reach_spacings},
          {"snap_base_across", m.snap_base_across},
          {"base_on_support", m.base_on_support},
          {"rim_to_side", m.rim_to_side},
          {"carve_views", m.carve_views},
          {"enclose_hull", m.enclose_hull},
          {"top_at_highest_surfel", m.top_at_highest_surfel},
          {"sides_within_surfels", m.sides_within_surfels},
          {"sides_within_order_axis_copies", m.sides_within_order_axis_copies},
          {"empty_alpha", m.empty_alpha},
          {"empty_close_px", m.empty_close_px}};
}

}  // namespace instascene::generation
