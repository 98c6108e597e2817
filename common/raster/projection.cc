#include "common/raster/projection.h"

#include <algorithm>
#include <cmath>

#if defined(__SSE2__)
#include <immintrin.h>
#endif

#include "common/splat/sh.h"

namespace instascene {
namespace {

constexpr float kCutoff = 3.0f;           // 3 sigma bounding box
constexpr float kFilterSize = 0.707106f;  // sqrt(2)/2 px low-pass filter radius
constexpr float kDilation = 0.3f;         // Inria 3DGS covariance dilation, px^2

inline float Sigmoid(float x) { return 1.0f / (1.0f + std::exp(-x)); }

// out = (sqrt(a), sqrt(b)), correctly rounded like std::sqrt, in one packed instruction.
inline void Sqrt2(double a, double b, double out[2]) {
#if defined(__SSE2__)
  _mm_storeu_pd(out, _mm_sqrt_pd(_mm_set_pd(b, a)));
#else
  out[0] = std::sqrt(a);
  out[1] = std::sqrt(b);
#endif
}

// Rotation of the unnormalised quaternion q (w first): the products scaled by s = 2 / |q|^2 (one
// division, no square root). T is float for 3DGS (as the Inria rasterizer), double for surfels.
template <typename T>
void QuaternionToMatrix(const float* q, T r[9]) {
  const T w = q[0], x = q[1], y = q[2], z = q[3];
  const T s = T{2} / (w * w + x * x + y * y + z * z);
  r[0] = 1 - s * (y * y + z * z);
  r[1] = s * (x * y - w * z);
  r[2] = s * (x * z + w * y);
  r[3] = s * (x * y + w * z);
  r[4] = 1 - s * (x * x + z * z);
  r[5] = s * (y * z - w * x);
  r[6] = s * (x * z - w * y);
  r[7] = s * (y * z + w * x);
  r[8] = 1 - s * (x * x + y * y);
}

// Rotates a world vector into the camera frame.
inline void RotateToView(const ProjectionParams& p, const float v[3], float out[3]) {
  for (int r = 0; r < 3; ++r) {
    out[r] = p.rotation[3 * r] * v[0] + p.rotation[3 * r + 1] * v[1] + p.rotation[3 * r + 2] * v[2];
  }
}

// Shared tail: colour, tile rectangle, visibility. Returns false if the tile rectangle is empty.
bool Finish(const GaussianCloud& cloud, size_t i, const ProjectionParams& p, float radius,
            ProjectedSplat* out) {
  const float* pos = &cloud.positions[3 * i];
  const int32_t tx0 =
      std::clamp(static_cast<int>((out->mean_px[0] - radius) / kTileSize), 0, p.tiles_x);
  const int32_t ty0 =
      std::clamp(static_cast<int>((out->mean_px[1] - radius) / kTileSize), 0, p.tiles_y);
  const int32_t tx1 = std::clamp(
      static_cast<int>((out->mean_px[0] + radius + kTileSize - 1) / kTileSize), 0, p.tiles_x);
  const int32_t ty1 = std::clamp(
      static_cast<int>((out->mean_px[1] + radius + kTileSize - 1) / kTileSize), 0, p.tiles_y);
  if ((tx1 - tx0) * (ty1 - ty0) == 0) return false;
  out->tiles[0] = tx0;
  out->tiles[1] = tx1;
  out->tiles[2] = ty0;
  out->tiles[3] = ty1;
  float dir[3] = {pos[0] - p.camera_center[0], pos[1] - p.camera_center[1],
                  pos[2] - p.camera_center[2]};
  const float inv_len = 1.0f / std::sqrt(dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2]);
  for (float& d : dir) d *= inv_len;
  EvalShColor(p.sh_degree, &cloud.sh[static_cast<size_t>(cloud.sh_stride()) * i], dir[0], dir[1],
              dir[2], out->rgb);
  return true;
}

// Sets the pixel window [x0, x1) x [y0, y1) to the integer pixels inside the closed float range
// [lo, hi] widened by 0.05 px (far above float rounding, far below the alpha falloff), clamped to
// the image, and shrinks the tile rectangle used for binning to the tiles the window touches.
// A splat whose window misses a tile contributes nothing there, so the output is unchanged.
inline void SetWindow(float x_lo, float x_hi, float y_lo, float y_hi, const ProjectionParams& p,
                      ProjectedSplat* out) {
  constexpr float kSlack = 0.05f;
  int32_t* window = out->window;
  window[0] =
      static_cast<int32_t>(std::clamp(std::ceil(x_lo - kSlack), 0.0f, static_cast<float>(p.width)));
  window[1] = static_cast<int32_t>(
      std::clamp(std::floor(x_hi + kSlack) + 1.0f, 0.0f, static_cast<float>(p.width)));
  window[2] = static_cast<int32_t>(
      std::clamp(std::ceil(y_lo - kSlack), 0.0f, static_cast<float>(p.height)));
  window[3] = static_cast<int32_t>(
      std::clamp(std::floor(y_hi + kSlack) + 1.0f, 0.0f, static_cast<float>(p.height)));
  int32_t* tiles = out->tiles;
  if (window[0] >= window[1] || window[2] >= window[3]) {
    tiles[1] = tiles[0];  // nothing to blend anywhere
    return;
  }
  tiles[0] = std::max(tiles[0], window[0] / kTileSize);
  tiles[1] = std::min(tiles[1], (window[1] - 1) / kTileSize + 1);
  tiles[2] = std::max(tiles[2], window[2] / kTileSize);
  tiles[3] = std::min(tiles[3], (window[3] - 1) / kTileSize + 1);
  if (tiles[0] >= tiles[1] || tiles[2] >= tiles[3]) tiles[1] = tiles[0];
}

// A splat too transparent to ever reach alpha 1/255: visible, but binned nowhere.
inline void NoWindow(ProjectedSplat* out) {
  out->window[0] = out->window[1] = out->window[2] = out->window[3] = 0;
  out->tiles[1] = out->tiles[0];
}

}  // namespace

ProjectionParams MakeProjectionParams(const PinholeCamera& camera, const RenderOptions& options,
                                      int cloud_sh_degree) {
  ProjectionParams p;
  p.fx = static_cast<float>(camera.fx);
  p.fy = static_cast<float>(camera.fy);
  p.cx = static_cast<float>(camera.cx - 0.5);
  p.cy = static_cast<float>(camera.cy - 0.5);
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c)
      p.rotation[3 * r + c] = static_cast<float>(camera.camera_from_world.rotation(r, c));
    p.translation[r] = static_cast<float>(camera.camera_from_world.translation[r]);
  }
  const Eigen::Vector3d center = camera.CenterInWorld();
  for (int r = 0; r < 3; ++r) p.camera_center[r] = static_cast<float>(center[r]);
  p.width = camera.width;
  p.height = camera.height;
  p.tiles_x = (camera.width + kTileSize - 1) / kTileSize;
  p.tiles_y = (camera.height + kTileSize - 1) / kTileSize;
  p.near_plane = options.near_plane;
  p.scale_modifier = options.scale_modifier;
  p.sh_degree = std::min(std::max(options.max_sh_degree, 0), cloud_sh_degree);
  p.tan_fov_x = static_cast<float>(0.5 * camera.width / camera.fx);
  p.tan_fov_y = static_cast<float>(0.5 * camera.height / camera.fy);
  return p;
}

bool ProjectSurfel(const GaussianCloud& cloud, size_t i, const ProjectionParams& p,
                   ProjectedSplat* out) {
  // Double precision for the transform and the bounding boxes: it keeps the stored planes
  // accurate for the float per-pixel loop. Transcendentals of float inputs (scales, opacity) are
  // evaluated in float: their inputs carry no more precision than that.
  const float* pos = &cloud.positions[3 * i];
  double pv[3];
  for (int r = 0; r < 3; ++r) {
    pv[r] = double{p.rotation[3 * r]} * pos[0] + double{p.rotation[3 * r + 1]} * pos[1] +
            double{p.rotation[3 * r + 2]} * pos[2] + p.translation[r];
  }
  if (pv[2] <= p.near_plane) return false;
  double rot[9];
  QuaternionToMatrix(&cloud.rotations[4 * i], rot);
  const double su = double{std::exp(cloud.log_scales[2 * i])} * p.scale_modifier;
  const double sv = double{std::exp(cloud.log_scales[2 * i + 1])} * p.scale_modifier;
  double a[3], b[3], n[3];
  for (int r = 0; r < 3; ++r) {
    const float* row = &p.rotation[3 * r];
    a[r] = su * (double{row[0]} * rot[0] + double{row[1]} * rot[3] + double{row[2]} * rot[6]);
    b[r] = sv * (double{row[0]} * rot[1] + double{row[1]} * rot[4] + double{row[2]} * rot[7]);
    n[r] = double{row[0]} * rot[2] + double{row[1]} * rot[5] + double{row[2]} * rot[8];
  }
  // Dual visibility: the normal always faces the camera.
  const double cos = -(pv[0] * n[0] + pv[1] * n[1] + pv[2] * n[2]);
  if (cos == 0.0) return false;
  const double sign = cos > 0.0 ? 1.0 : -1.0;
  for (int r = 0; r < 3; ++r) out->normal_view[r] = static_cast<float>(sign * n[r]);
  // M = K [a | b | pv]: rows Tu, Tv, Tw.
  const double* cols[3] = {a, b, pv};
  double tu[3], tv[3], tw[3];
  for (int c = 0; c < 3; ++c) {
    tu[c] = p.fx * cols[c][0] + p.cx * cols[c][2];
    tv[c] = p.fy * cols[c][1] + p.cy * cols[c][2];
    tw[c] = cols[c][2];
  }
  // Screen AABB of the ellipse of squared cutoff c2 (compute_aabb of the 2DGS rasterizer);
  // returns d. Both square roots in one instruction (they are on the critical path).
  auto aabb = [&](double c2, double center[2], double extent[2]) {
    const double d = c2 * tw[0] * tw[0] + c2 * tw[1] * tw[1] - tw[2] * tw[2];
    if (d == 0.0) return 0.0;
    const double inv_d = 1.0 / d;
    const double f[3] = {c2 * inv_d, c2 * inv_d, -inv_d};
    center[0] = f[0] * tu[0] * tw[0] + f[1] * tu[1] * tw[1] + f[2] * tu[2] * tw[2];
    center[1] = f[0] * tv[0] * tw[0] + f[1] * tv[1] * tw[1] + f[2] * tv[2] * tw[2];
    const double sx = f[0] * tu[0] * tu[0] + f[1] * tu[1] * tu[1] + f[2] * tu[2] * tu[2];
    const double sy = f[0] * tv[0] * tv[0] + f[1] * tv[1] * tv[1] + f[2] * tv[2] * tv[2];
    Sqrt2(std::max(1e-4, center[0] * center[0] - sx), std::max(1e-4, center[1] * center[1] - sy),
          extent);
    return d;
  };
  double mean[2], extent[2];
  if (aabb(kCutoff * kCutoff, mean, extent) == 0.0) return false;
  const float radius = static_cast<float>(
      std::ceil(std::max({extent[0], extent[1], double{kCutoff * kFilterSize}})));
  out->mean_px[0] = static_cast<float>(mean[0]);
  out->mean_px[1] = static_cast<float>(mean[1]);
  out->opacity = Sigmoid(cloud.opacity_logits[i]);
  out->depth = static_cast<float>(pv[2]);
  if (!Finish(cloud, i, p, radius, out)) return false;
  // Any integer pixel near the splat serves as the origin; floor(x + 0.5) inlines, round() does
  // not.
  const double ox = std::clamp(std::floor(mean[0] + 0.5), -1e6, 1e6);
  const double oy = std::clamp(std::floor(mean[1] + 0.5), -1e6, 1e6);
  out->origin_px[0] = static_cast<int32_t>(ox);
  out->origin_px[1] = static_cast<int32_t>(oy);
  for (int c = 0; c < 3; ++c) {
    out->tu[c] = static_cast<float>(ox * tw[c] - tu[c]);
    out->tv[c] = static_cast<float>(oy * tw[c] - tv[c]);
    out->tw[c] = static_cast<float>(tw[c]);
  }
  // Pixel window where alpha = opacity * max(G3d, G2d) >= 1/255 is possible:
  // rho <= rho_max = 2 ln(255 opacity). Empty when the opacity alone is below 1/255.
  const double rho_max = 2.0 * double{std::log(255.0f * out->opacity)};
  if (!(rho_max > 0.0)) {
    NoWindow(out);
    return true;
  }
  const double r2d = std::sqrt(0.5 * rho_max);  // low-pass disk: 2 |mu - x|^2 <= rho_max
  double x_lo = mean[0] - r2d, x_hi = mean[0] + r2d, y_lo = mean[1] - r2d, y_hi = mean[1] + r2d;
  double c3[2], e3[2];
  if (aabb(rho_max, c3, e3) < 0.0) {  // bounded ellipse: its box is exact
    x_lo = std::min(x_lo, c3[0] - e3[0]);
    x_hi = std::max(x_hi, c3[0] + e3[0]);
    y_lo = std::min(y_lo, c3[1] - e3[1]);
    y_hi = std::max(y_hi, c3[1] + e3[1]);
  } else {  // unbounded projection (grazing or crossing the camera plane): whole image
    x_lo = y_lo = 0.0;
    x_hi = p.width;
    y_hi = p.height;
  }
  SetWindow(static_cast<float>(std::max(x_lo, -1e6)), static_cast<float>(std::min(x_hi, 1e6)),
            static_cast<float>(std::max(y_lo, -1e6)), static_cast<float>(std::min(y_hi, 1e6)), p,
            out);
  return true;
}

bool ProjectEllipsoid(const GaussianCloud& cloud, size_t i, const ProjectionParams& p,
                      ProjectedSplat* out) {
  const float* pos = &cloud.positions[3 * i];
  float t[3];
  RotateToView(p, pos, t);
  for (int r = 0; r < 3; ++r) t[r] += p.translation[r];
  if (t[2] <= p.near_plane) return false;
  float rot[9];
  QuaternionToMatrix(&cloud.rotations[4 * i], rot);
  float s[3];
  for (int k = 0; k < 3; ++k) s[k] = std::exp(cloud.log_scales[3 * i + k]) * p.scale_modifier;
  // World covariance Sigma = R S S^T R^T.
  float cov[9];
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) {
      float v = 0.0f;
      for (int k = 0; k < 3; ++k) v += rot[3 * r + k] * s[k] * s[k] * rot[3 * c + k];
      cov[3 * r + c] = v;
    }
  }
  // EWA: J (Jacobian of the perspective map, clamped at 1.3x the fov) times W (camera rotation).
  const float limx = 1.3f * p.tan_fov_x, limy = 1.3f * p.tan_fov_y;
  const float tx = std::min(limx, std::max(-limx, t[0] / t[2])) * t[2];
  const float ty = std::min(limy, std::max(-limy, t[1] / t[2])) * t[2];
  const float j00 = p.fx / t[2], j02 = -(p.fx * tx) / (t[2] * t[2]);
  const float j11 = p.fy / t[2], j12 = -(p.fy * ty) / (t[2] * t[2]);
  float jw[2][3];  // (J W), rows 0..1
  for (int c = 0; c < 3; ++c) {
    jw[0][c] = j00 * p.rotation[c] + j02 * p.rotation[6 + c];
    jw[1][c] = j11 * p.rotation[3 + c] + j12 * p.rotation[6 + c];
  }
  float c2d[3] = {0, 0, 0};  // (0,0), (0,1), (1,1) of JW Sigma (JW)^T
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) {
      c2d[0] += jw[0][r] * cov[3 * r + c] * jw[0][c];
      c2d[1] += jw[0][r] * cov[3 * r + c] * jw[1][c];
      c2d[2] += jw[1][r] * cov[3 * r + c] * jw[1][c];
    }
  }
  c2d[0] += kDilation;
  c2d[2] += kDilation;
  const float det = c2d[0] * c2d[2] - c2d[1] * c2d[1];
  if (det == 0.0f) return false;
  out->tu[0] = c2d[2] / det;
  out->tu[1] = -c2d[1] / det;
  out->tu[2] = c2d[0] / det;
  const float mid = 0.5f * (c2d[0] + c2d[2]);
  const float lambda1 = mid + std::sqrt(std::max(0.1f, mid * mid - det));
  const float lambda2 = mid - std::sqrt(std::max(0.1f, mid * mid - det));
  const float radius = std::ceil(3.0f * std::sqrt(std::max(lambda1, lambda2)));
  out->mean_px[0] = p.fx * t[0] / t[2] + p.cx;
  out->mean_px[1] = p.fy * t[1] / t[2] + p.cy;
  out->opacity = Sigmoid(cloud.opacity_logits[i]);
  out->depth = t[2];
  // Normal: the shortest axis, facing the camera.
  const int k = static_cast<int>(std::min_element(s, s + 3) - s);
  const float axis_w[3] = {rot[k], rot[3 + k], rot[6 + k]};
  RotateToView(p, axis_w, out->normal_view);
  if (out->normal_view[0] * t[0] + out->normal_view[1] * t[1] + out->normal_view[2] * t[2] > 0.0f) {
    for (float& v : out->normal_view) v = -v;
  }
  if (!Finish(cloud, i, p, radius, out)) return false;
  const float rho_max = 2.0f * std::log(255.0f * out->opacity);
  if (!(rho_max > 0.0f)) {
    NoWindow(out);
    return true;
  }
  // d^T Sigma^-1 d <= rho_max spans sqrt(rho_max * Sigma_xx) horizontally.
  const float ex = std::sqrt(rho_max * c2d[0]), ey = std::sqrt(rho_max * c2d[2]);
  SetWindow(out->mean_px[0] - ex, out->mean_px[0] + ex, out->mean_px[1] - ey, out->mean_px[1] + ey,
            p, out);
  return true;
}

}  // namespace instascene
