#include "common/raster/projection.h"

#include <algorithm>
#include <cmath>

#include "common/raster/simd_math.h"
#include "common/splat/sh.h"

namespace instascene {
namespace {

constexpr float kCutoff = 3.0f;           // 3 sigma bounding box
constexpr float kFilterSize = 0.707106f;  // sqrt(2)/2 px low-pass filter radius
constexpr float kDilation = 0.3f;         // Inria 3DGS covariance dilation, px^2

inline float Sigmoid(float x) { return 1.0f / (1.0f + std::exp(-x)); }

// Rotation of the unnormalised quaternion (w, x, y, z): the products scaled by s = 2 / |q|^2 (one
// division, no square root). T is float for 3DGS (as the Inria rasterizer) and 4 double lanes for
// the surfel batch (scalars broadcast).
template <typename T>
void QuaternionToMatrix(T w, T x, T y, T z, T r[9]) {
  const T s = 2.0f / (w * w + x * x + y * y + z * z);
  r[0] = 1.0f - s * (y * y + z * z);
  r[1] = s * (x * y - w * z);
  r[2] = s * (x * z + w * y);
  r[3] = s * (x * y + w * z);
  r[4] = 1.0f - s * (x * x + z * z);
  r[5] = s * (y * z - w * x);
  r[6] = s * (x * z - w * y);
  r[7] = s * (y * z + w * x);
  r[8] = 1.0f - s * (x * x + y * y);
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

namespace {

using raster_internal::Ceil4d;
using raster_internal::Exp4f;
using raster_internal::Floor4d;
using raster_internal::Log4f;
using raster_internal::Max4d;
using raster_internal::Min4d;
using raster_internal::Splat4d;
using raster_internal::Splat4f;
using raster_internal::Sqrt4d;
using raster_internal::ToDouble;
using raster_internal::ToFloat;
using raster_internal::v4d;
using raster_internal::v4f;
using raster_internal::v4l;

#define INSTASCENE_INLINE inline __attribute__((always_inline))

// Screen AABB of the ellipse of squared cutoff c2 (compute_aabb of the 2DGS rasterizer): the
// denominator d, the centre and the half extents.
INSTASCENE_INLINE void ScreenBox4(v4d c2, const v4d tu[3], const v4d tv[3], const v4d tw[3], v4d* d,
                                  v4d center[2], v4d extent[2]) {
  *d = c2 * tw[0] * tw[0] + c2 * tw[1] * tw[1] - tw[2] * tw[2];
  const v4d inv_d = Splat4d(1.0) / *d;
  const v4d f0 = c2 * inv_d, f2 = -inv_d;
  center[0] = f0 * tu[0] * tw[0] + f0 * tu[1] * tw[1] + f2 * tu[2] * tw[2];
  center[1] = f0 * tv[0] * tw[0] + f0 * tv[1] * tw[1] + f2 * tv[2] * tw[2];
  const v4d sx = f0 * tu[0] * tu[0] + f0 * tu[1] * tu[1] + f2 * tu[2] * tu[2];
  const v4d sy = f0 * tv[0] * tv[0] + f0 * tv[1] * tv[1] + f2 * tv[2] * tv[2];
  extent[0] = Sqrt4d(Max4d(Splat4d(1e-4), center[0] * center[0] - sx));
  extent[1] = Sqrt4d(Max4d(Splat4d(1e-4), center[1] * center[1] - sy));
}

// 4 surfels in the camera: the centres pv, the scaled tangent axes a, b and the normal n (camera
// frame).
INSTASCENE_INLINE void SurfelAxes4(const GaussianCloud& cloud, const size_t idx[4],
                                   const ProjectionParams& p, v4d pv[3], v4d a[3], v4d b[3],
                                   v4d n[3]) {
  auto gather = [&](const std::vector<float>& v, int stride, int k) {
    return v4d{v[stride * idx[0] + k], v[stride * idx[1] + k], v[stride * idx[2] + k],
               v[stride * idx[3] + k]};
  };
  auto gatherf = [&](const std::vector<float>& v, int stride, int k) {
    return v4f{v[stride * idx[0] + k], v[stride * idx[1] + k], v[stride * idx[2] + k],
               v[stride * idx[3] + k]};
  };
  const v4d pos[3] = {gather(cloud.positions, 3, 0), gather(cloud.positions, 3, 1),
                      gather(cloud.positions, 3, 2)};
  for (int r = 0; r < 3; ++r) {
    pv[r] = Splat4d(p.rotation[3 * r]) * pos[0] + Splat4d(p.rotation[3 * r + 1]) * pos[1] +
            Splat4d(p.rotation[3 * r + 2]) * pos[2] + Splat4d(p.translation[r]);
  }
  v4d rot[9];
  QuaternionToMatrix(gather(cloud.rotations, 4, 0), gather(cloud.rotations, 4, 1),
                     gather(cloud.rotations, 4, 2), gather(cloud.rotations, 4, 3), rot);
  const v4d su = ToDouble(Exp4f(gatherf(cloud.log_scales, 2, 0))) * Splat4d(p.scale_modifier);
  const v4d sv = ToDouble(Exp4f(gatherf(cloud.log_scales, 2, 1))) * Splat4d(p.scale_modifier);
  for (int r = 0; r < 3; ++r) {
    const v4d r0 = Splat4d(p.rotation[3 * r]), r1 = Splat4d(p.rotation[3 * r + 1]),
              r2 = Splat4d(p.rotation[3 * r + 2]);
    a[r] = su * (r0 * rot[0] + r1 * rot[3] + r2 * rot[6]);
    b[r] = sv * (r0 * rot[1] + r1 * rot[4] + r2 * rot[7]);
    n[r] = r0 * rot[2] + r1 * rot[5] + r2 * rot[8];
  }
}

// What the lanes hand to the one-lane finish (Finish, SetWindow).
struct Surfel4 {
  v4d pv[3], n[3], sign, tu[3], tv[3], tw[3], mean[2], ox, oy, rho_max, x_lo, x_hi, y_lo, y_hi;
  v4f radius, opacity;
};

// Stores lane l into `o`; false when the splat is culled.
INSTASCENE_INLINE bool StoreLane(const GaussianCloud& cloud, size_t g, const ProjectionParams& p,
                                 const Surfel4& s, int l, ProjectedSplat* o) {
  for (int r = 0; r < 3; ++r) o->normal_view[r] = static_cast<float>(s.sign[l] * s.n[r][l]);
  o->mean_px[0] = static_cast<float>(s.mean[0][l]);
  o->mean_px[1] = static_cast<float>(s.mean[1][l]);
  o->opacity = s.opacity[l];
  o->depth = static_cast<float>(s.pv[2][l]);
  if (!Finish(cloud, g, p, s.radius[l], o)) return false;
  o->origin_px[0] = static_cast<int32_t>(s.ox[l]);
  o->origin_px[1] = static_cast<int32_t>(s.oy[l]);
  for (int c = 0; c < 3; ++c) {
    o->tu[c] = static_cast<float>(s.ox[l] * s.tw[c][l] - s.tu[c][l]);
    o->tv[c] = static_cast<float>(s.oy[l] * s.tw[c][l] - s.tv[c][l]);
    o->tw[c] = static_cast<float>(s.tw[c][l]);
  }
  if (!(s.rho_max[l] > 0.0)) {
    NoWindow(o);
    return true;
  }
  SetWindow(static_cast<float>(std::max(s.x_lo[l], -1e6)),
            static_cast<float>(std::min(s.x_hi[l], 1e6)),
            static_cast<float>(std::max(s.y_lo[l], -1e6)),
            static_cast<float>(std::min(s.y_hi[l], 1e6)), p, o);
  return true;
}

// The lanes' opacity, origin pixel and pixel window (ALGORITHM.md 2.2): where alpha = opacity *
// max(G3d, G2d) >= 1/255 is possible, rho <= rho_max = 2 ln(255 opacity); empty when the opacity
// alone is below 1/255.
INSTASCENE_INLINE void PixelWindow4(const GaussianCloud& cloud, const size_t idx[4],
                                    const ProjectionParams& p, Surfel4& s) {
  s.opacity =
      Splat4f(1.0f) /
      (Splat4f(1.0f) + Exp4f(-v4f{cloud.opacity_logits[idx[0]], cloud.opacity_logits[idx[1]],
                                  cloud.opacity_logits[idx[2]], cloud.opacity_logits[idx[3]]}));
  // Integer origin pixel near the splat for the per-pixel planes.
  s.ox = Min4d(Max4d(Floor4d(s.mean[0] + Splat4d(0.5)), Splat4d(-1e6)), Splat4d(1e6));
  s.oy = Min4d(Max4d(Floor4d(s.mean[1] + Splat4d(0.5)), Splat4d(-1e6)), Splat4d(1e6));
  s.rho_max = Splat4d(2.0) * ToDouble(Log4f(Splat4f(255.0f) * s.opacity));
  const v4d r2d = Sqrt4d(Splat4d(0.5) * s.rho_max);  // low-pass disk: 2 |mu - x|^2 <= rho_max
  v4d d3, c3[2], e3[2];
  ScreenBox4(s.rho_max, s.tu, s.tv, s.tw, &d3, c3, e3);
  // Bounded ellipse: its box is exact; otherwise (grazing, or crossing the camera plane) the
  // whole image.
  const v4l bounded = d3 < Splat4d(0.0);
  s.x_lo = bounded ? Min4d(s.mean[0] - r2d, c3[0] - e3[0]) : Splat4d(0.0);
  s.x_hi = bounded ? Max4d(s.mean[0] + r2d, c3[0] + e3[0]) : Splat4d(p.width);
  s.y_lo = bounded ? Min4d(s.mean[1] - r2d, c3[1] - e3[1]) : Splat4d(0.0);
  s.y_hi = bounded ? Max4d(s.mean[1] + r2d, c3[1] + e3[1]) : Splat4d(p.height);
}

// Projects 4 surfels, lane l = Gaussian idx[l]; every lane computes exactly what a one-lane call
// computes. Double precision for the transform and the bounding boxes keeps the stored planes
// accurate for the float per-pixel loop; transcendentals of float inputs (scales, opacity) are
// evaluated in float, since their inputs carry no more precision than that.
void ProjectSurfel4(const GaussianCloud& cloud, const size_t idx[4], const ProjectionParams& p,
                    ProjectedSplat* out[4], bool ok_out[4]) {
  Surfel4 s;
  v4d a[3], b[3];
  SurfelAxes4(cloud, idx, p, s.pv, a, b, s.n);
  v4l ok = s.pv[2] > Splat4d(p.near_plane);
  // Dual visibility: the normal always faces the camera.
  const v4d cos = -(s.pv[0] * s.n[0] + s.pv[1] * s.n[1] + s.pv[2] * s.n[2]);
  ok &= cos != Splat4d(0.0);
  s.sign = cos > Splat4d(0.0) ? Splat4d(1.0) : -Splat4d(1.0);
  // M = K [a | b | pv]: rows Tu, Tv, Tw.
  const v4d* cols[3] = {a, b, s.pv};
  for (int c = 0; c < 3; ++c) {
    s.tu[c] = Splat4d(p.fx) * cols[c][0] + Splat4d(p.cx) * cols[c][2];
    s.tv[c] = Splat4d(p.fy) * cols[c][1] + Splat4d(p.cy) * cols[c][2];
    s.tw[c] = cols[c][2];
  }
  v4d d, extent[2];
  ScreenBox4(Splat4d(kCutoff * kCutoff), s.tu, s.tv, s.tw, &d, s.mean, extent);
  ok &= d != Splat4d(0.0);
  s.radius = ToFloat(Ceil4d(Max4d(Max4d(extent[0], extent[1]), Splat4d(kCutoff * kFilterSize))));
  PixelWindow4(cloud, idx, p, s);
  for (int l = 0; l < 4; ++l) {
    ok_out[l] = ok[l] && StoreLane(cloud, idx[l], p, s, l, out[l]);
  }
}

#undef INSTASCENE_INLINE

}  // namespace

void ProjectSurfels(const GaussianCloud& cloud, size_t first, size_t count,
                    const ProjectionParams& params, ProjectedSplat* out, uint8_t* visible) {
  for (size_t k = 0; k < count; k += 4) {
    // A partial last group repeats its last Gaussian in the spare lanes and drops their results.
    size_t idx[4];
    ProjectedSplat spare[4];
    ProjectedSplat* dst[4];
    bool ok[4];
    for (int l = 0; l < 4; ++l) {
      const size_t j = std::min(k + l, count - 1);
      idx[l] = first + j;
      dst[l] = k + l < count ? &out[k + l] : &spare[l];
    }
    ProjectSurfel4(cloud, idx, params, dst, ok);
    for (size_t l = 0; l < 4 && k + l < count; ++l) visible[k + l] = ok[l] ? 1 : 0;
  }
}

namespace {

// The screen covariance (0,0), (0,1), (1,1) of Gaussian i at camera-frame centre t by EWA:
// J (the perspective map's Jacobian, clamped at 1.3x the fov) W (the camera rotation) Sigma
// (R S S^T R^T) (JW)^T, dilated by the low-pass filter. `rot` and `s` receive its rotation and
// scales.
void ScreenCovariance(const GaussianCloud& cloud, size_t i, const ProjectionParams& p,
                      const float t[3], float rot[9], float s[3], float c2d[3]) {
  const float* q = &cloud.rotations[4 * i];
  QuaternionToMatrix(q[0], q[1], q[2], q[3], rot);
  for (int k = 0; k < 3; ++k) s[k] = std::exp(cloud.log_scales[3 * i + k]) * p.scale_modifier;
  float cov[9];
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) {
      float v = 0.0f;
      for (int k = 0; k < 3; ++k) v += rot[3 * r + k] * s[k] * s[k] * rot[3 * c + k];
      cov[3 * r + c] = v;
    }
  }
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
  c2d[0] = c2d[1] = c2d[2] = 0;
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) {
      c2d[0] += jw[0][r] * cov[3 * r + c] * jw[0][c];
      c2d[1] += jw[0][r] * cov[3 * r + c] * jw[1][c];
      c2d[2] += jw[1][r] * cov[3 * r + c] * jw[1][c];
    }
  }
  c2d[0] += kDilation;
  c2d[2] += kDilation;
}

}  // namespace

bool ProjectEllipsoid(const GaussianCloud& cloud, size_t i, const ProjectionParams& p,
                      ProjectedSplat* out) {
  const float* pos = &cloud.positions[3 * i];
  float t[3];
  RotateToView(p, pos, t);
  for (int r = 0; r < 3; ++r) t[r] += p.translation[r];
  if (t[2] <= p.near_plane) return false;
  float rot[9], s[3], c2d[3];
  ScreenCovariance(cloud, i, p, t, rot, s, c2d);
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
