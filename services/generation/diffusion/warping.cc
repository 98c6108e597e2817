#include "services/generation/diffusion/warping.h"

#include <tbb/parallel_for.h>

#include <cmath>

#include "absl/strings/str_cat.h"
#include "common/core/status.h"

namespace instascene::generation::diffusion {
namespace {

// Bilinear sample at pixel coordinates (COLMAP convention: pixel centres at +0.5), clamped.
void Sample(const KnownView& view, int channels, const Eigen::Vector2d& px, float* out) {
  const int w = view.camera.width, h = view.camera.height;
  const double x = std::clamp(px.x() - 0.5, 0.0, w - 1.0),
               y = std::clamp(px.y() - 0.5, 0.0, h - 1.0);
  const int x0 = static_cast<int>(x), y0 = static_cast<int>(y);
  const int x1 = std::min(x0 + 1, w - 1), y1 = std::min(y0 + 1, h - 1);
  const double fx = x - x0, fy = y - y0;
  for (int c = 0; c < channels; ++c) {
    auto at = [&](int xx, int yy) {
      return view.values[(static_cast<size_t>(yy) * w + xx) * channels + c];
    };
    out[c] = static_cast<float>((1 - fy) * ((1 - fx) * at(x0, y0) + fx * at(x1, y0)) +
                                fy * ((1 - fx) * at(x0, y1) + fx * at(x1, y1)));
  }
}

absl::Status CheckWarpInputs(const std::vector<KnownView>& known, const PinholeCamera& target,
                             const WarpOptions& options) {
  if (absl::Status s = target.Validate(); !s.ok()) return s;
  if (options.channels < 1) return absl::InvalidArgumentError("warp: channels < 1");
  for (size_t k = 0; k < known.size(); ++k) {
    if (absl::Status s = known[k].camera.Validate(); !s.ok()) return s;
    if (known[k].values.size() !=
        static_cast<size_t>(known[k].camera.width) * known[k].camera.height * options.channels)
      return absl::InvalidArgumentError(
          absl::StrCat("warp: known view ", k, "'s values do not match its camera"));
  }
  return absl::OkStatus();
}

// Whether a known view sees the mesh's surface point x (normal n): in its image, not at a
// grazing angle, and the first hit of its ray to x (within the tolerance).
bool SeesSurfacePoint(const RayCaster& mesh, const PinholeCamera& camera, const Eigen::Vector3f& x,
                      const Eigen::Vector3f& n, const WarpOptions& options,
                      Eigen::Vector3d* in_camera) {
  if (!camera.SeesPoint(x.cast<double>(), in_camera)) return false;
  const Eigen::Vector3f o = camera.CenterInWorld().cast<float>();
  const float distance = (x - o).norm();
  if (n.dot(o - x) < options.min_known_cosine * distance) return false;  // grazing
  const RayHit from_known = mesh.Cast(o, (x - o) / distance);
  return from_known.hit &&
         !(std::abs(from_known.distance - distance) > options.visibility_tolerance * distance);
}

}  // namespace

absl::StatusOr<WarpResult> WarpIntoTarget(const RayCaster& mesh,
                                          const std::vector<KnownView>& known,
                                          const PinholeCamera& target, const WarpOptions& options) {
  RETURN_IF_ERROR(CheckWarpInputs(known, target, options));
  const int w = target.width, h = target.height, channels = options.channels;
  WarpResult out;
  out.values.assign(static_cast<size_t>(w) * h * channels, 0.0f);
  out.known.assign(static_cast<size_t>(w) * h, 0);
  out.depth.assign(static_cast<size_t>(w) * h, 0.0f);
  const Eigen::Vector3f axis = target.camera_from_world.rotation.row(2).transpose().cast<float>();
  std::vector<uint8_t> fate(static_cast<size_t>(w) * h, 0);  // 0 missed, 1 back, 2 unseen, 3 ok
  const Eigen::Vector3f eye = target.CenterInWorld().cast<float>();
  tbb::parallel_for(0, h, [&](int row) {
    for (int col = 0; col < w; ++col) {
      const size_t i = static_cast<size_t>(row) * w + col;
      const Eigen::Vector3f dir = target.PixelRayInWorld(col, row).cast<float>();
      const RayHit hit = mesh.Cast(eye, dir);
      if (!hit.hit) continue;
      out.depth[i] = hit.distance * dir.dot(axis);
      if (!(hit.normal.dot(-dir) > 0.0f)) {
        fate[i] = 1;
        continue;
      }
      const Eigen::Vector3f x = eye + hit.distance * dir;
      fate[i] = 2;
      for (const KnownView& view : known) {
        Eigen::Vector3d in_camera;
        if (!SeesSurfacePoint(mesh, view.camera, x, hit.normal, options, &in_camera)) continue;
        Sample(view, channels, view.camera.ProjectFromCamera(in_camera), &out.values[i * channels]);
        out.known[i] = 1;
        fate[i] = 3;
        break;
      }
    }
  });
  for (uint8_t f : fate) {
    out.missed += f == 0;
    out.back_facing += f == 1;
    out.unseen += f == 2;
    out.written += f == 3;
  }
  return out;
}

}  // namespace instascene::generation::diffusion
