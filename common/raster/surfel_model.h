// common/raster/surfel_model.h: one 2DGS surfel as the differentiable reference renderer
// (surfel_backward.h) evaluates it, in doubles or in forward-mode duals over its 10 geometric
// parameters: projection to the ray-splat intersection rows (ALGORITHM.md 2.2), the raw alpha at a
// pixel, and the view-dependent colour (SH degree 0 or 1) with its derivatives. Internal to
// common/raster.
#pragma once

#include <unsupported/Eigen/AutoDiff>

#include <algorithm>
#include <cmath>

#include "common/geometry/camera.h"
#include "common/splat/gaussian_cloud.h"
#include "common/splat/sh.h"

namespace instascene::surfel_model {

inline constexpr double kAlphaMinD = 1.0 / 255.0;
inline constexpr double kAlphaMaxD = 0.99;
inline constexpr double kTMin = 1e-4;
inline constexpr double kShC1 = 0.4886025119029199;

using Deriv = Eigen::Matrix<double, 10, 1>;  // position 3, log-scale 2, quaternion 4, logit 1
using Dual = Eigen::AutoDiffScalar<Deriv>;

struct Camera {
  double fx, fy, cx, cy;  // pixel centres at integers
  Eigen::Matrix3d rotation;
  Eigen::Vector3d translation, center;
  double near_plane;
};

inline Camera MakeCamera(const PinholeCamera& c, double near_plane) {
  return {c.fx,
          c.fy,
          c.cx - 0.5,
          c.cy - 0.5,
          c.camera_from_world.rotation,
          c.camera_from_world.translation,
          c.CenterInWorld(),
          near_plane};
}

// The surfel's parameters as scalars of type S (double, or Dual seeded with unit derivatives).
template <typename S>
struct SurfelParams {
  Eigen::Matrix<S, 3, 1> position;
  S log_scale[2];
  S quat[4];  // w x y z, not normalised
  S logit;
};

inline SurfelParams<double> Plain(const GaussianCloud& cloud, size_t g) {
  SurfelParams<double> s;
  for (int k = 0; k < 3; ++k) s.position[k] = cloud.positions[3 * g + k];
  for (int k = 0; k < 2; ++k) s.log_scale[k] = cloud.log_scales[2 * g + k];
  for (int k = 0; k < 4; ++k) s.quat[k] = cloud.rotations[4 * g + k];
  s.logit = cloud.opacity_logits[g];
  return s;
}

inline SurfelParams<Dual> Seeded(const GaussianCloud& cloud, size_t g) {
  const SurfelParams<double> p = Plain(cloud, g);
  SurfelParams<Dual> s;
  int k = 0;
  for (int i = 0; i < 3; ++i, ++k) s.position[i] = Dual(p.position[i], Deriv::Unit(k));
  for (int i = 0; i < 2; ++i, ++k) s.log_scale[i] = Dual(p.log_scale[i], Deriv::Unit(k));
  for (int i = 0; i < 4; ++i, ++k) s.quat[i] = Dual(p.quat[i], Deriv::Unit(k));
  s.logit = Dual(p.logit, Deriv::Unit(k));
  return s;
}

// The rows Tu, Tv, Tw of M = K V H (ALGORITHM.md 2.2) and the projected centre.
template <typename S>
struct Splat {
  Eigen::Matrix<S, 3, 1> tu, tv, tw;
  S center_x, center_y;  // low-pass filter centre (screen box centre)
  S proj_x, proj_y;      // projected surfel centre
  S depth, opacity;
};

template <typename S>
Splat<S> Project(const SurfelParams<S>& s, const Camera& cam) {
  using std::exp;
  using std::sqrt;
  const S norm = sqrt(s.quat[0] * s.quat[0] + s.quat[1] * s.quat[1] + s.quat[2] * s.quat[2] +
                      s.quat[3] * s.quat[3]);
  const S w = s.quat[0] / norm, x = s.quat[1] / norm, y = s.quat[2] / norm, z = s.quat[3] / norm;
  Eigen::Matrix<S, 3, 1> r0, r1;  // rotation columns 0 and 1
  r0 << S(1) - S(2) * (y * y + z * z), S(2) * (x * y + w * z), S(2) * (x * z - w * y);
  r1 << S(2) * (x * y - w * z), S(1) - S(2) * (x * x + z * z), S(2) * (y * z + w * x);
  const Eigen::Matrix<S, 3, 3> rc = cam.rotation.cast<S>();
  const Eigen::Matrix<S, 3, 1> a = rc * (r0 * exp(s.log_scale[0]));
  const Eigen::Matrix<S, 3, 1> b = rc * (r1 * exp(s.log_scale[1]));
  const Eigen::Matrix<S, 3, 1> c = rc * s.position + cam.translation.cast<S>();
  auto k = [&](const Eigen::Matrix<S, 3, 1>& v) {  // K v, homogeneous pixel coordinates
    Eigen::Matrix<S, 3, 1> out;
    out << S(cam.fx) * v[0] + S(cam.cx) * v[2], S(cam.fy) * v[1] + S(cam.cy) * v[2], v[2];
    return out;
  };
  const Eigen::Matrix<S, 3, 1> ka = k(a), kb = k(b), kc = k(c);
  Splat<S> sp;
  sp.tu << ka[0], kb[0], kc[0];
  sp.tv << ka[1], kb[1], kc[1];
  sp.tw << ka[2], kb[2], kc[2];
  sp.proj_x = kc[0] / kc[2];
  sp.proj_y = kc[1] / kc[2];
  // The low-pass filter's centre: the centre of the screen box of the 3-sigma ellipse, as the
  // production rasterizer (projection.cc, compute_aabb of the 2DGS CUDA code) has it.
  const S d = S(9) * sp.tw[0] * sp.tw[0] + S(9) * sp.tw[1] * sp.tw[1] - sp.tw[2] * sp.tw[2];
  const S f0 = S(9) / d, f2 = S(-1) / d;
  sp.center_x = f0 * sp.tu[0] * sp.tw[0] + f0 * sp.tu[1] * sp.tw[1] + f2 * sp.tu[2] * sp.tw[2];
  sp.center_y = f0 * sp.tv[0] * sp.tw[0] + f0 * sp.tv[1] * sp.tw[1] + f2 * sp.tv[2] * sp.tw[2];
  sp.depth = c[2];
  sp.opacity = S(1) / (S(1) + exp(-s.logit));
  return sp;
}

// Alpha of the splat at pixel (px, py) (pixel centres at integers), before the 0.99 clamp; 0 when
// the intersection is invalid (behind the near plane, parallel plane).
template <typename S>
S RawAlpha(const Splat<S>& sp, double px, double py, double near_plane) {
  using std::exp;
  const Eigen::Matrix<S, 3, 1> k = S(px) * sp.tw - sp.tu;
  const Eigen::Matrix<S, 3, 1> l = S(py) * sp.tw - sp.tv;
  const S pz = k[0] * l[1] - k[1] * l[0];
  if (pz == S(0)) return S(0);
  const S u = (k[1] * l[2] - k[2] * l[1]) / pz;
  const S v = (k[2] * l[0] - k[0] * l[2]) / pz;
  const S rho3d = u * u + v * v;
  const S dx = sp.center_x - S(px), dy = sp.center_y - S(py);
  const S rho2d = S(2) * (dx * dx + dy * dy);
  const bool use3d = rho3d <= rho2d;
  const S depth = use3d ? u * sp.tw[0] + v * sp.tw[1] + sp.tw[2] : sp.tw[2];
  if (depth < S(near_plane)) return S(0);
  return sp.opacity * exp(S(-0.5) * (use3d ? rho3d : rho2d));
}

// View-dependent colour (SH degree 0 or 1), clamped at 0 as the CUDA code does; also returns
// d colour / d position (3x3) and d colour / d sh coefficient via the basis.
struct Colour {
  Eigen::Vector3d rgb;
  Eigen::Matrix3d d_position;  // row = channel
  double basis[4];             // SH basis values (degree 0: basis[0] only)
  bool clamped[3];
};

inline Colour SurfelColour(const GaussianCloud& cloud, size_t g, const Camera& cam) {
  Colour out;
  const int stride = cloud.sh_stride();
  const float* sh = &cloud.sh[stride * g];
  const Eigen::Vector3d p(cloud.positions[3 * g], cloud.positions[3 * g + 1],
                          cloud.positions[3 * g + 2]);
  const Eigen::Vector3d diff = p - cam.center;
  const double len = diff.norm();
  const Eigen::Vector3d d = diff / len;
  out.basis[0] = kShC0;
  out.basis[1] = -kShC1 * d.y();
  out.basis[2] = kShC1 * d.z();
  out.basis[3] = -kShC1 * d.x();
  // d basis / d dir, then d dir / d p = (I - d d^T) / len.
  Eigen::Matrix<double, 4, 3> db_ddir = Eigen::Matrix<double, 4, 3>::Zero();
  db_ddir(1, 1) = -kShC1;
  db_ddir(2, 2) = kShC1;
  db_ddir(3, 0) = -kShC1;
  const Eigen::Matrix3d ddir_dp = (Eigen::Matrix3d::Identity() - d * d.transpose()) / len;
  const int coeffs = cloud.sh_degree == 0 ? 1 : 4;
  for (int c = 0; c < 3; ++c) {
    double value = 0.5;
    Eigen::RowVector3d grad = Eigen::RowVector3d::Zero();
    for (int k = 0; k < coeffs; ++k) {
      value += out.basis[k] * sh[3 * k + c];
      grad += sh[3 * k + c] * db_ddir.row(k) * ddir_dp;
    }
    out.clamped[c] = value < 0;
    out.rgb[c] = std::max(0.0, value);
    out.d_position.row(c) = out.clamped[c] ? Eigen::RowVector3d::Zero() : grad;
  }
  return out;
}

}  // namespace instascene::surfel_model
