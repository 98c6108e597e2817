#include "common/raster/splat_chain.h"

#include <unsupported/Eigen/AutoDiff>

#include <cmath>

#include "common/splat/sh.h"

namespace instascene {
namespace {

constexpr double kCutoff2 = 9.0;  // squared 3-sigma cut-off of the AABB (projection.cc)

using Quat = Eigen::AutoDiffScalar<Eigen::Vector4d>;

// The rotation's columns from a quaternion (w, x, y, z; not necessarily unit), with their
// derivatives with respect to its 4 components.
void RotationColumns(const float* q, Quat r0[3], Quat r1[3], Quat r2[3]) {
  const Quat w(q[0], 4, 0), x(q[1], 4, 1), y(q[2], 4, 2), z(q[3], 4, 3);
  const Quat s = 2.0 / (w * w + x * x + y * y + z * z);
  r0[0] = 1.0 - s * (y * y + z * z);
  r0[1] = s * (x * y + w * z);
  r0[2] = s * (x * z - w * y);
  r1[0] = s * (x * y - w * z);
  r1[1] = 1.0 - s * (x * x + z * z);
  r1[2] = s * (y * z + w * x);
  r2[0] = s * (x * z + w * y);
  r2[1] = s * (y * z - w * x);
  r2[2] = 1.0 - s * (x * x + y * y);
}

// Adds the low-pass centre's gradient to the planes': mean = N / d with
// N_x = 9 (Tu0 Tw0 + Tu1 Tw1) - Tu2 Tw2, d = 9 (Tw0^2 + Tw1^2) - Tw2^2.
void AddMeanGradient(const double tu[3], const double tv[3], const double tw[3],
                     const double d_mean[2], double dTu[3], double dTv[3], double dTw[3]) {
  const double d = kCutoff2 * (tw[0] * tw[0] + tw[1] * tw[1]) - tw[2] * tw[2];
  const double mean_x = (kCutoff2 * (tu[0] * tw[0] + tu[1] * tw[1]) - tu[2] * tw[2]) / d;
  const double mean_y = (kCutoff2 * (tv[0] * tw[0] + tv[1] * tw[1]) - tv[2] * tw[2]) / d;
  const double sign[3] = {kCutoff2, kCutoff2, -1.0};
  for (int k = 0; k < 3; ++k) {
    dTu[k] += d_mean[0] * sign[k] * tw[k] / d;
    dTv[k] += d_mean[1] * sign[k] * tw[k] / d;
    dTw[k] += d_mean[0] * sign[k] * (tu[k] - 2.0 * mean_x * tw[k]) / d +
              d_mean[1] * sign[k] * (tv[k] - 2.0 * mean_y * tw[k]) / d;
  }
}

// dL/d(quaternion) from dL/d of the rotation's columns r0, r1 (scaled tangent axes, through the
// camera's rotation) and of the camera-frame normal n = sign R_cam r2 (sign: the one that makes it
// face the camera, `normal_view`); the columns carry their derivatives by the quaternion.
Eigen::Vector4d QuaternionGradient(const Eigen::Matrix3d& rot, const Quat r0[3], const Quat r1[3],
                                   const Quat r2[3], const Eigen::Vector3d& d_r0,
                                   const Eigen::Vector3d& d_r1, const double d_normal[3],
                                   const float normal_view[3]) {
  Eigen::Vector3d r2v;
  for (int k = 0; k < 3; ++k) r2v[k] = r2[k].value();
  const Eigen::Vector3d n_cam = rot * r2v;
  const double facing =
      n_cam[0] * normal_view[0] + n_cam[1] * normal_view[1] + n_cam[2] * normal_view[2] < 0 ? -1.0
                                                                                            : 1.0;
  const Eigen::Vector3d d_r2 =
      facing * (rot.transpose() * Eigen::Vector3d(d_normal[0], d_normal[1], d_normal[2]));
  Eigen::Vector4d d_quat = Eigen::Vector4d::Zero();
  for (int k = 0; k < 3; ++k) {
    d_quat += d_r0[k] * r0[k].derivatives() + d_r1[k] * r1[k].derivatives() +
              d_r2[k] * r2[k].derivatives();
  }
  return d_quat;
}

// Carries dL/d(Tu, Tv, Tw, low-pass centre, opacity) of surfel g to its 10 parameters (position
// 3, log-scale 2, quaternion 4, logit 1) through the production projection (projection.cc):
// M = K [R_cam r0 su | R_cam r1 sv | R_cam p + t] with rows Tu, Tv, Tw, the centre of the 3-sigma
// ellipse's screen box, opacity = sigmoid(logit), and of its camera-frame normal
// n = sign R_cam r2 (QuaternionGradient). The quaternion's rotation columns are differentiated by
// forward-mode AD (4 derivatives); the rest is the chain rule by hand.
void ChainToParameters(const GaussianCloud& cloud, size_t g, const ProjectionParams& p,
                       double dTu[3], double dTv[3], double dTw[3], const double d_mean[2],
                       double d_opacity, const double d_normal[3], const float normal_view[3],
                       double out[10]) {
  Eigen::Matrix3d rot;
  Eigen::Vector3d trans, pos;
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) rot(r, c) = p.rotation[3 * r + c];
    trans[r] = p.translation[r];
    pos[r] = cloud.positions[3 * g + r];
  }
  const double su = std::exp(double(cloud.log_scales[2 * g])) * p.scale_modifier;
  const double sv = std::exp(double(cloud.log_scales[2 * g + 1])) * p.scale_modifier;
  Quat r0[3], r1[3], r2[3];
  RotationColumns(&cloud.rotations[4 * g], r0, r1, r2);
  Eigen::Vector3d r0v, r1v;
  for (int k = 0; k < 3; ++k) {
    r0v[k] = r0[k].value();
    r1v[k] = r1[k].value();
  }
  const Eigen::Vector3d a = rot * r0v * su, b = rot * r1v * sv, c = rot * pos + trans;
  const Eigen::Vector3d* cols[3] = {&a, &b, &c};
  double tu[3], tv[3], tw[3];
  for (int k = 0; k < 3; ++k) {
    tu[k] = p.fx * (*cols[k])[0] + p.cx * (*cols[k])[2];
    tv[k] = p.fy * (*cols[k])[1] + p.cy * (*cols[k])[2];
    tw[k] = (*cols[k])[2];
  }
  AddMeanGradient(tu, tv, tw, d_mean, dTu, dTv, dTw);
  // Columns a, b, c of K^-1 M: dL/dcol_k = (fx dTu_k, fy dTv_k, cx dTu_k + cy dTv_k + dTw_k).
  Eigen::Vector3d dcol[3];
  for (int k = 0; k < 3; ++k) {
    dcol[k] = Eigen::Vector3d(p.fx * dTu[k], p.fy * dTv[k], p.cx * dTu[k] + p.cy * dTv[k] + dTw[k]);
  }
  const Eigen::Vector3d d_pos = rot.transpose() * dcol[2];
  for (int k = 0; k < 3; ++k) out[k] = d_pos[k];
  out[3] = dcol[0].dot(a);  // d a / d log su = a
  out[4] = dcol[1].dot(b);
  const Eigen::Vector4d d_quat =
      QuaternionGradient(rot, r0, r1, r2, su * (rot.transpose() * dcol[0]),
                         sv * (rot.transpose() * dcol[1]), d_normal, normal_view);
  for (int k = 0; k < 4; ++k) out[5 + k] = d_quat[k];
  const double opacity = 1.0 / (1.0 + std::exp(-double(cloud.opacity_logits[g])));
  out[9] = d_opacity * opacity * (1.0 - opacity);
}

// SH basis (degree 0-3, ALGORITHM.md 2.7) of a direction of scalar type S.
template <typename S>
void ShBasis(int degree, const S& x, const S& y, const S& z, S basis[16]) {
  basis[0] = S(kShC0);
  if (degree < 1) return;
  basis[1] = -double(kShC1) * y;
  basis[2] = double(kShC1) * z;
  basis[3] = -double(kShC1) * x;
  if (degree < 2) return;
  const S xx = x * x, yy = y * y, zz = z * z;
  basis[4] = double(kShC2[0]) * x * y;
  basis[5] = double(kShC2[1]) * y * z;
  basis[6] = double(kShC2[2]) * (2.0 * zz - xx - yy);
  basis[7] = double(kShC2[3]) * x * z;
  basis[8] = double(kShC2[4]) * (xx - yy);
  if (degree < 3) return;
  basis[9] = double(kShC3[0]) * y * (3.0 * xx - yy);
  basis[10] = double(kShC3[1]) * x * y * z;
  basis[11] = double(kShC3[2]) * y * (4.0 * zz - xx - yy);
  basis[12] = double(kShC3[3]) * z * (2.0 * zz - 3.0 * xx - 3.0 * yy);
  basis[13] = double(kShC3[4]) * x * (4.0 * zz - xx - yy);
  basis[14] = double(kShC3[5]) * z * (xx - yy);
  basis[15] = double(kShC3[6]) * x * (xx - 3.0 * yy);
}

}  // namespace

void ChainSplatGradient(const GaussianCloud& cloud, size_t g, const ProjectedSplat& s,
                        const ProjectionParams& params, const SplatGrad& t, SurfelGradients* out) {
  // Back from the stored planes: tu' = ox Tw - Tu, tv' = oy Tw - Tv.
  double dTu[3], dTv[3], dTw[3];
  for (int c = 0; c < 3; ++c) {
    dTu[c] = -t.tu[c];
    dTv[c] = -t.tv[c];
    dTw[c] = t.tw[c] + s.origin_px[0] * t.tu[c] + s.origin_px[1] * t.tv[c];
  }
  double geo[10];
  ChainToParameters(cloud, g, params, dTu, dTv, dTw, t.mean, t.opacity, t.normal, s.normal_view,
                    geo);
  // Colour: rgb = max(0, 0.5 + sum basis_k(dir) sh_k), dir = (p - eye) / |p - eye|.
  const int stride = cloud.sh_stride();
  const int coeffs = NumShCoeffs(params.sh_degree);
  using D3 = Eigen::AutoDiffScalar<Eigen::Vector3d>;
  Eigen::Matrix<D3, 3, 1> dir;
  for (int k = 0; k < 3; ++k) {
    dir[k] =
        D3(cloud.positions[3 * g + k] - double(params.camera_center[k]), Eigen::Vector3d::Unit(k));
  }
  const D3 len = sqrt(dir.squaredNorm());
  for (int k = 0; k < 3; ++k) dir[k] = dir[k] / len;
  D3 basis[16];
  ShBasis(params.sh_degree, dir[0], dir[1], dir[2], basis);
  const float* sh = &cloud.sh[stride * g];
  Eigen::Vector3d d_pos(geo[0], geo[1], geo[2]);
  for (int c = 0; c < 3; ++c) {
    D3 value = D3(0.5);
    for (int k = 0; k < coeffs; ++k) value += basis[k] * double(sh[3 * k + c]);
    if (value.value() < 0) continue;  // clamped: no gradient
    d_pos += t.rgb[c] * value.derivatives();
    for (int k = 0; k < coeffs; ++k) {
      out->sh[stride * g + 3 * k + c] = static_cast<float>(t.rgb[c] * basis[k].value());
    }
  }
  for (int k = 0; k < 3; ++k) out->positions[3 * g + k] = static_cast<float>(d_pos[k]);
  for (int k = 0; k < 2; ++k) out->log_scales[2 * g + k] = static_cast<float>(geo[3 + k]);
  for (int k = 0; k < 4; ++k) out->rotations[4 * g + k] = static_cast<float>(geo[5 + k]);
  out->opacity_logits[g] = static_cast<float>(geo[9]);
}

}  // namespace instascene
