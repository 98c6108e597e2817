#include "services/generation/free_space.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <mutex>

#include "absl/strings/str_cat.h"

namespace instascene::generation {
namespace {

// Entry / exit distances of a ray through an axis-aligned box (slab test); false when it misses.
bool ClipToBox(const Eigen::Vector3f& o, const Eigen::Vector3f& d, const Eigen::Vector3f& lo,
               const Eigen::Vector3f& hi, float* t0, float* t1) {
  float near = 0, far = std::numeric_limits<float>::infinity();
  for (int a = 0; a < 3; ++a) {
    if (std::abs(d[a]) < 1e-12f) {
      if (o[a] < lo[a] || o[a] > hi[a]) return false;
      continue;
    }
    float ta = (lo[a] - o[a]) / d[a], tb = (hi[a] - o[a]) / d[a];
    if (ta > tb) std::swap(ta, tb);
    near = std::max(near, ta);
    far = std::min(far, tb);
  }
  *t0 = near;
  *t1 = far;
  return near < far;
}

// The pixels whose rays can reach the box [lo, hi]: the bounding box of its projected corners
// (the whole image when a corner lies behind the camera).
struct PixelWindow {
  double x0, y0, x1, y1;
};
PixelWindow BoxFootprint(const PinholeCamera& camera, const Eigen::Vector3f& lo,
                         const Eigen::Vector3f& hi) {
  PixelWindow w{0, 0, static_cast<double>(camera.width), static_cast<double>(camera.height)};
  Eigen::AlignedBox2d footprint;
  for (int corner = 0; corner < 8; ++corner) {
    const Eigen::Vector3d p((corner & 1) ? hi.x() : lo.x(), (corner & 2) ? hi.y() : lo.y(),
                            (corner & 4) ? hi.z() : lo.z());
    const Eigen::Vector3d in_camera = camera.camera_from_world * p;
    if (in_camera.z() <= 1e-6) return w;
    footprint.extend(camera.ProjectFromCamera(in_camera));
  }
  w.x0 = std::clamp(footprint.min().x(), 0.0, static_cast<double>(camera.width));
  w.y0 = std::clamp(footprint.min().y(), 0.0, static_cast<double>(camera.height));
  w.x1 = std::clamp(footprint.max().x(), 0.0, static_cast<double>(camera.width));
  w.y1 = std::clamp(footprint.max().y(), 0.0, static_cast<double>(camera.height));
  return w;
}

// A grid of rays `stride` pixels apart over the window, each with its first hit (inf: none).
struct RayFan {
  int rows = 0, cols = 0;
  std::vector<Eigen::Vector3f> dirs;
  std::vector<float> hits;
  float Hit(int r, int q) const { return hits[static_cast<size_t>(r) * cols + q]; }
};
RayFan CastRayFan(const PinholeCamera& camera, const Eigen::Vector3f& eye, const PixelWindow& w,
                  double stride, const RayCaster& surfaces) {
  RayFan fan;
  fan.cols = std::max(0, static_cast<int>(std::ceil((w.x1 - w.x0) / stride - 0.5)));
  fan.rows = std::max(0, static_cast<int>(std::ceil((w.y1 - w.y0) / stride - 0.5)));
  fan.dirs.resize(static_cast<size_t>(fan.rows) * fan.cols);
  fan.hits.assign(fan.dirs.size(), std::numeric_limits<float>::infinity());
  const Eigen::Matrix3d camera_to_world = camera.camera_from_world.rotation.transpose();
  for (int r = 0; r < fan.rows; ++r) {
    for (int q = 0; q < fan.cols; ++q) {
      const double x = w.x0 + (q + 0.5) * stride, y = w.y0 + (r + 0.5) * stride;
      const size_t i = static_cast<size_t>(r) * fan.cols + q;
      fan.dirs[i] = (camera_to_world *
                     Eigen::Vector3d((x - camera.cx) / camera.fx, (y - camera.cy) / camera.fy, 1.0))
                        .normalized()
                        .cast<float>();
      const RayHit hit = surfaces.Cast(eye, fan.dirs[i]);
      if (hit.hit) fan.hits[i] = hit.distance;
    }
  }
  return fan;
}

// Where ray (r, q) stops: its hit, or, through a hole (all neighbours within hole_rays but
// hole_slack stop more than the margin before it), where the farthest of those does. (A
// silhouette has far fewer such neighbours.)
float HoleAwareHit(const RayFan& fan, int r, int q, const FreeSpaceOptions& options, float voxel) {
  const int reach = options.hole_rays;
  const float own = fan.Hit(r, q);
  if (reach <= 0) return own;
  int nearer = 0, neighbours = 0;
  float farthest_nearer = 0;
  for (int dr = -reach; dr <= reach; ++dr) {
    for (int dq = -reach; dq <= reach; ++dq) {
      const int rr = r + dr, qq = q + dq;
      if ((dr == 0 && dq == 0) || rr < 0 || rr >= fan.rows || qq < 0 || qq >= fan.cols) continue;
      ++neighbours;
      const float h = fan.Hit(rr, qq);
      if (h < own - options.margin_voxels * voxel) {
        ++nearer;
        farthest_nearer = std::max(farthest_nearer, h);
      }
    }
  }
  return neighbours > 0 && nearer >= neighbours - options.hole_slack ? farthest_nearer : own;
}

}  // namespace

int64_t FreeSpaceGrid::VoxelOf(const Eigen::Vector3f& p) const {
  const Eigen::Vector3f cell = (p - origin_) / voxel_;
  if ((cell.array() < 0).any()) return -1;
  const int64_t i = static_cast<int64_t>(cell.x()), j = static_cast<int64_t>(cell.y()),
                k = static_cast<int64_t>(cell.z());
  if (i >= resolution_ || j >= resolution_ || k >= resolution_) return -1;
  return (k * resolution_ + j) * resolution_ + i;
}

int FreeSpaceGrid::FreeViews(const Eigen::Vector3f& p) const {
  const int64_t v = VoxelOf(p);
  return v < 0 ? 0 : free_views_[v];
}

bool FreeSpaceGrid::IsFree(const Eigen::Vector3f& p) const { return FreeViews(p) >= min_views_; }

double FreeSpaceGrid::FreeFraction() const {
  if (free_views_.empty()) return 0;
  size_t free = 0;
  for (uint16_t c : free_views_) free += c >= min_views_;
  return static_cast<double>(free) / free_views_.size();
}

std::vector<uint8_t> FreeSpaceGrid::SeenFrom(const PinholeCamera& camera, const RayCaster& surfaces,
                                             const ObjectFrame& frame,
                                             const FreeSpaceOptions& options) const {
  const float half = options.extent_radii * frame.radius;  // as Carve placed the grid
  const Eigen::Vector3f lo = origin_, hi = origin_ + Eigen::Vector3f::Constant(2 * half);
  const Eigen::Vector3f eye = camera.CenterInWorld().cast<float>();
  const double distance = std::max(1e-6f, (frame.center - eye).norm());
  const PixelWindow window = BoxFootprint(camera, lo, hi);
  // Rays about half a voxel apart at the object (every pixel when pixels are coarser), bounded
  // by the per-view ray budget.
  double stride = std::max(1.0, 0.5 * voxel_ * camera.fx / distance);
  const double area = std::max(0.0, (window.x1 - window.x0) * (window.y1 - window.y0));
  stride = std::max(stride, std::sqrt(area / options.max_rays_per_view));
  // Cast every ray of the grid first, so that each ray can end at the nearest hit among its
  // neighbours: a ray slipping through a hole between surfel discs must not carve the inside.
  const RayFan fan = CastRayFan(camera, eye, window, stride, surfaces);
  std::vector<uint8_t> seen(free_views_.size(), 0);
  const float step = 0.5f * voxel_;
  for (int r = 0; r < fan.rows; ++r) {
    for (int q = 0; q < fan.cols; ++q) {
      const Eigen::Vector3f& dir = fan.dirs[static_cast<size_t>(r) * fan.cols + q];
      float t0, t1;
      if (!ClipToBox(eye, dir, lo, hi, &t0, &t1)) continue;
      const float nearest = HoleAwareHit(fan, r, q, options, voxel_);
      const float end =
          std::min(t1, std::isfinite(nearest) ? nearest - options.margin_voxels * voxel_ : t1);
      for (float t = t0 + 0.5f * step; t < end; t += step) {
        const int64_t v = VoxelOf(eye + t * dir);
        if (v >= 0) seen[v] = 1;
      }
    }
  }
  return seen;
}

absl::StatusOr<FreeSpaceGrid> FreeSpaceGrid::Carve(const std::vector<PinholeCamera>& cameras,
                                                   const RayCaster& surfaces,
                                                   const ObjectFrame& frame,
                                                   const FreeSpaceOptions& options) {
  if (options.resolution < 4 || options.resolution > 512 || !(options.extent_radii > 0) ||
      options.min_views < 1 || !(frame.radius > 0)) {
    return absl::InvalidArgumentError(
        absl::StrCat("free space: bad options (resolution ", options.resolution, ", extent ",
                     options.extent_radii, ", radius ", frame.radius, ")"));
  }
  FreeSpaceGrid grid;
  grid.resolution_ = options.resolution;
  grid.min_views_ = options.min_views;
  const float half = options.extent_radii * frame.radius;
  grid.origin_ = frame.center - Eigen::Vector3f::Constant(half);
  grid.voxel_ = 2.0f * half / options.resolution;
  const size_t voxels =
      static_cast<size_t>(options.resolution) * options.resolution * options.resolution;
  grid.free_views_.assign(voxels, 0);
  std::mutex merge;
  tbb::parallel_for(size_t{0}, cameras.size(), [&](size_t c) {
    const std::vector<uint8_t> seen = grid.SeenFrom(cameras[c], surfaces, frame, options);
    std::lock_guard<std::mutex> lock(merge);  // integer sums: the order does not matter
    for (size_t v = 0; v < voxels; ++v) {
      if (seen[v] && grid.free_views_[v] < std::numeric_limits<uint16_t>::max()) {
        ++grid.free_views_[v];
      }
    }
  });
  return grid;
}

}  // namespace instascene::generation
