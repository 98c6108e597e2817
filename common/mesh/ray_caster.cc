#include "common/mesh/ray_caster.h"

#include <embree3/rtcore.h>

#include <cmath>
#include <mutex>
#include <string>

#include "absl/strings/str_cat.h"

namespace instascene {
namespace {

// The process-wide Embree device, created on first use. Errors raised by Embree calls are read
// back with rtcGetDeviceError right after the calls that can fail (build and commit).
RTCDevice Device() {
  static RTCDevice device = rtcNewDevice(nullptr);
  return device;
}

absl::Status EmbreeStatus(const char* what) {
  const RTCError error = rtcGetDeviceError(Device());
  if (error == RTC_ERROR_NONE) return absl::OkStatus();
  if (error == RTC_ERROR_OUT_OF_MEMORY) {
    return absl::ResourceExhaustedError(absl::StrCat("embree: out of memory while ", what));
  }
  return absl::InternalError(
      absl::StrCat("embree error ", static_cast<int>(error), " while ", what));
}

}  // namespace

struct RayCaster::Impl {
  RTCScene scene = nullptr;
  ~Impl() {
    if (scene != nullptr) rtcReleaseScene(scene);
  }
};

RayCaster::~RayCaster() = default;

absl::StatusOr<std::unique_ptr<RayCaster>> RayCaster::Create(const TriangleMesh& mesh) {
  if (Device() == nullptr) return absl::InternalError("embree: cannot create a device");
  for (size_t v = 0; v < mesh.vertices.size(); ++v) {
    if (!mesh.vertices[v].allFinite()) {
      return absl::InvalidArgumentError(absl::StrCat("mesh vertex ", v, " is not finite"));
    }
  }
  for (size_t t = 0; t < mesh.triangles.size(); ++t) {
    for (uint32_t i : mesh.triangles[t]) {
      if (i >= mesh.vertices.size()) {
        return absl::InvalidArgumentError(
            absl::StrCat("mesh triangle ", t, " index ", i, " >= ", mesh.vertices.size()));
      }
    }
  }
  std::unique_ptr<RayCaster> caster(new RayCaster());
  caster->impl_ = std::make_unique<Impl>();
  caster->num_triangles_ = mesh.triangles.size();
  RTCScene scene = rtcNewScene(Device());
  caster->impl_->scene = scene;
  if (scene == nullptr) return EmbreeStatus("creating a scene");
  rtcSetSceneFlags(scene, RTC_SCENE_FLAG_ROBUST);
  rtcSetSceneBuildQuality(scene, RTC_BUILD_QUALITY_HIGH);
  if (!mesh.triangles.empty()) {
    RTCGeometry geometry = rtcNewGeometry(Device(), RTC_GEOMETRY_TYPE_TRIANGLE);
    if (geometry == nullptr) return EmbreeStatus("creating a triangle geometry");
    auto* vertices = static_cast<float*>(
        rtcSetNewGeometryBuffer(geometry, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                3 * sizeof(float), mesh.vertices.size()));
    auto* indices = static_cast<uint32_t*>(
        rtcSetNewGeometryBuffer(geometry, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                3 * sizeof(uint32_t), mesh.triangles.size()));
    if (vertices == nullptr || indices == nullptr) {
      rtcReleaseGeometry(geometry);
      return EmbreeStatus("allocating mesh buffers");
    }
    for (size_t v = 0; v < mesh.vertices.size(); ++v) {
      for (int k = 0; k < 3; ++k) vertices[3 * v + k] = mesh.vertices[v][k];
    }
    for (size_t t = 0; t < mesh.triangles.size(); ++t) {
      for (int k = 0; k < 3; ++k) indices[3 * t + k] = mesh.triangles[t][k];
    }
    rtcCommitGeometry(geometry);
    rtcAttachGeometry(scene, geometry);
    rtcReleaseGeometry(geometry);
  }
  rtcCommitScene(scene);
  if (absl::Status s = EmbreeStatus("building the BVH"); !s.ok()) return s;
  return caster;
}

RayHit RayCaster::Cast(const Eigen::Vector3f& origin, const Eigen::Vector3f& direction,
                       float t_near, float t_far) const {
  RayHit out;
  if (num_triangles_ == 0) return out;
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  RTCRayHit rh;
  rh.ray.org_x = origin.x();
  rh.ray.org_y = origin.y();
  rh.ray.org_z = origin.z();
  rh.ray.dir_x = direction.x();
  rh.ray.dir_y = direction.y();
  rh.ray.dir_z = direction.z();
  rh.ray.tnear = t_near;
  rh.ray.tfar = t_far;
  rh.ray.mask = 0xFFFFFFFFu;
  rh.ray.flags = 0;
  rh.ray.time = 0;
  rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
  rtcIntersect1(impl_->scene, &context, &rh);
  if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return out;
  out.hit = true;
  out.distance = rh.ray.tfar;
  out.triangle = rh.hit.primID;
  const Eigen::Vector3f n(rh.hit.Ng_x, rh.hit.Ng_y, rh.hit.Ng_z);
  const float length = n.norm();
  out.normal = length > 0 ? Eigen::Vector3f(n / length) : Eigen::Vector3f::Zero();
  return out;
}

std::vector<float> RayCaster::AllHits(const Eigen::Vector3f& origin,
                                      const Eigen::Vector3f& direction, float t_near) const {
  std::vector<float> hits;
  float t = t_near;
  // Each hit restarts just past itself; the step is relative so large scenes do not stall.
  for (int guard = 0; guard < 4096; ++guard) {
    const RayHit hit = Cast(origin, direction, t);
    if (!hit.hit) break;
    hits.push_back(hit.distance);
    t = std::nextafter(hit.distance, std::numeric_limits<float>::infinity()) +
        1e-6f * std::max(1.0f, hit.distance);
  }
  return hits;
}

int RayCaster::CountCrossings(const Eigen::Vector3f& origin, const Eigen::Vector3f& direction,
                              float t_near) const {
  return static_cast<int>(AllHits(origin, direction, t_near).size());
}

}  // namespace instascene
