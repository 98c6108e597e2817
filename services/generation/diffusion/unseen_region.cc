#include "services/generation/diffusion/unseen_region.h"

#include <algorithm>
#include <cmath>

#include <opencv2/imgproc.hpp>

namespace instascene::generation::diffusion {
namespace {

// The ray's parameter interval inside the axis-aligned cube centre +- half (empty: t0 > t1).
void CubeInterval(const Eigen::Vector3f& eye, const Eigen::Vector3f& dir,
                  const Eigen::Vector3f& centre, float half, float* t0, float* t1) {
  *t0 = 0.0f;
  *t1 = std::numeric_limits<float>::max();
  for (int k = 0; k < 3; ++k) {
    const float lo = centre[k] - half - eye[k], hi = centre[k] + half - eye[k];
    if (std::abs(dir[k]) < 1e-12f) {
      if (lo > 0 || hi < 0) *t0 = *t1 + 1;  // parallel and outside
      continue;
    }
    float a = lo / dir[k], b = hi / dir[k];
    if (a > b) std::swap(a, b);
    *t0 = std::max(*t0, a);
    *t1 = std::min(*t1, b);
  }
}

void Morph(std::vector<uint8_t>* mask, int w, int h, double radius, bool erode) {
  const int r = static_cast<int>(std::lround(radius));
  if (r <= 0) return;
  cv::Mat m(h, w, CV_8U, mask->data());
  const cv::Mat kernel =
      cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(2 * r + 1, 2 * r + 1));
  cv::Mat out;
  if (erode) {
    cv::erode(m, out, kernel, cv::Point(-1, -1), 1, cv::BORDER_CONSTANT, cv::Scalar(0));
  } else {
    cv::dilate(m, out, kernel, cv::Point(-1, -1), 1, cv::BORDER_CONSTANT, cv::Scalar(0));
  }
  out.copyTo(m);
}

}  // namespace

std::vector<uint8_t> UnseenRegion(const FreeSpaceGrid& free_space, const ObjectFrame& frame,
                                  const PinholeCamera& camera,
                                  const std::vector<float>& instance_depth, int full_width,
                                  const UnseenOptions& options) {
  const int w = camera.width, h = camera.height;
  std::vector<uint8_t> unseen(static_cast<size_t>(w) * h, 0);
  const Eigen::Vector3f eye = camera.CenterInWorld().cast<float>();
  const Eigen::Vector3f axis = camera.camera_from_world.rotation.row(2).transpose().cast<float>();
  const float step = 0.5f * free_space.voxel();
  const float margin = options.surface_margin_voxels * free_space.voxel();
  for (int row = 0; row < h; ++row) {
    for (int col = 0; col < w; ++col) {
      const size_t i = static_cast<size_t>(row) * w + col;
      const Eigen::Vector3f dir = camera.PixelRayInWorld(col, row).cast<float>();
      float t0, t1;
      CubeInterval(eye, dir, frame.center, frame.radius, &t0, &t1);
      if (instance_depth[i] > 0) t1 = std::min(t1, instance_depth[i] / dir.dot(axis) - margin);
      for (float t = t0 + 0.5f * step; t < t1; t += step) {
        const Eigen::Vector3f p = eye + t * dir;
        if (frame.has_support && frame.up.dot(p) < frame.support_height) continue;
        if (free_space.FreeViews(p) < options.min_seen_views) {
          unseen[i] = 1;
          break;
        }
      }
    }
  }
  const double scale = static_cast<double>(w) / std::max(1, full_width);
  Morph(&unseen, w, h, options.erode_px * scale, /*erode=*/true);
  Morph(&unseen, w, h, options.dilate_px * scale, /*erode=*/false);
  return unseen;
}

}  // namespace instascene::generation::diffusion
