#include "services/generation/completion_manifest.h"

#include "common/mesh/mesh_checks.h"
#include "services/generation/manifest_options.h"

namespace instascene::generation {
namespace {

nlohmann::json Vec(const Eigen::Vector3f& v) { return {v.x(), v.y(), v.z()}; }

// world_from_object: rotation = the frame's basis (x, y, up), translation = the centre.
nlohmann::json Pose(const ObjectFrame& frame) {
  const Eigen::Matrix3f r = frame.Basis();
  nlohmann::json m = nlohmann::json::array();
  for (int i = 0; i < 3; ++i) m.push_back({r(i, 0), r(i, 1), r(i, 2), frame.center[i]});
  return m;
}

// Oriented bounding box in the object frame.
nlohmann::json OrientedBox(const GaussianCloud& cloud, const ObjectFrame& frame) {
  const Eigen::Matrix3f basis = frame.Basis();
  Eigen::AlignedBox3f box;
  for (size_t g = 0; g < cloud.size(); ++g) {
    box.extend(basis.transpose() * (Eigen::Vector3f(&cloud.positions[3 * g]) - frame.center));
  }
  return {{"min", Vec(box.min())}, {"max", Vec(box.max())}, {"extent", Vec(box.sizes())}};
}

// The viewpoint ring: per view its angles, score, visible surfels and whether a real view knows it.
nlohmann::json RingToManifest(const CompletedObject& o, const CompletionOptions& options) {
  nlohmann::json ring = nlohmann::json::array();
  for (size_t k = 0; k < o.ring.size(); ++k) {
    const ViewVisibility& v = o.ring_visibility[k];
    ring.push_back({{"azimuth_deg", 360.0 * k / o.ring.size()},
                    {"elevation_deg", options.ring.elevation_deg},
                    {"score", v.score},
                    {"self_visible", v.self_visible},
                    {"known", v.known}});
  }
  return ring;
}

nlohmann::json FrameToManifest(const ObjectFrame& frame) {
  return {{"center", Vec(frame.center)},
          {"up", Vec(frame.up)},
          {"radius", frame.radius},
          {"spacing", frame.spacing},
          {"bottom", frame.bottom_height},
          {"support",
           frame.has_support ? nlohmann::json(frame.support_height) : nlohmann::json(nullptr)}};
}

}  // namespace

nlohmann::json CompletionManifest(const CompletedObject& o, const CompletionOptions& options) {
  int known = 0;
  for (size_t k = 0; k < o.ring.size(); ++k) known += o.ring_visibility[k].known;
  const size_t observed = o.raw.size(), completed = o.object.size() - o.raw.size();
  nlohmann::json m = {
      {"format", kObjectFormat},
      {"id", o.id},
      {"world_from_object", Pose(o.frame)},
      {"frame", FrameToManifest(o.frame)},
      {"bounding_box", OrientedBox(o.object, o.frame)},
      {"prior", options.prior},
      {"abstained", o.prior.abstained},
      {"prior_summary", o.prior.reason},
      {"prior_report", o.prior.report},
      {"gaussians",
       {{"observed", observed},
        {"stray_removed", o.stray_removed},
        {"completed", completed},
        {"completed_share",
         o.object.size() ? static_cast<double>(completed) / o.object.size() : 0}}},
      {"ring", RingToManifest(o, options)},
      {"meshing", MeshingToManifest(options.meshing)},
      {"free_space", FreeSpaceToManifest(options.free_space)},
      {"ring_camera",
       {{"size_px", options.ring.size_px},
        {"focal_px", options.ring.focal_px},
        {"distance_radii", options.ring.distance_radii}}},
      {"known_views", known},
      {"unknown_views", static_cast<int>(o.ring.size()) - known},
      {"training_views", o.training_views},
      {"mesh",
       {{"file", "mesh.ply"},
        {"vertices", o.mesh.vertices.size()},
        {"triangles", o.mesh.triangles.size()},
        {"closed", IsClosedManifold(o.mesh)},
        {"hull_enclosed", o.hull_enclosed}}},
      {"refinement", o.refinement},
      {"seed", options.seed},
  };
  return m;
}

}  // namespace instascene::generation
