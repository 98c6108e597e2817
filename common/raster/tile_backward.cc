#include "common/raster/tile_backward.h"

#include <tbb/parallel_for.h>
#include <unsupported/Eigen/AutoDiff>

#include <algorithm>
#include <cmath>

#include "absl/strings/str_cat.h"
#include "common/core/parallel.h"
#include "common/raster/projection.h"
#include "common/raster/rasterizer.h"
#include "common/splat/sh.h"

namespace instascene {
namespace {

constexpr double kCutoff2 = 9.0;  // squared 3-sigma cut-off of the AABB (projection.cc)

// Per splat and view: dL / d(k-plane offset tu', l-plane offset tv', Tw, low-pass centre,
// opacity), dL / d rgb and dL / d normal (camera frame, facing the camera), summed over pixels.
struct SplatGrad {
  double tu[3], tv[3], tw[3], mean[2], opacity, rgb[3], normal[3];
};

// Carries dL/d(Tu, Tv, Tw, low-pass centre, opacity) of surfel g to its 10 parameters (position
// 3, log-scale 2, quaternion 4, logit 1) through the production projection (projection.cc):
// M = K [R_cam r0 su | R_cam r1 sv | R_cam p + t] with rows Tu, Tv, Tw, the centre of the 3-sigma
// ellipse's screen box, opacity = sigmoid(logit), and of its camera-frame normal
// n = sign R_cam r2 (sign: the one that makes it face the camera, `normal_view`). The quaternion's
// rotation columns are differentiated by forward-mode AD (4 derivatives); the rest is the chain
// rule by hand.
using Quat = Eigen::AutoDiffScalar<Eigen::Vector4d>;

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
  const Quat w(cloud.rotations[4 * g], 4, 0), x(cloud.rotations[4 * g + 1], 4, 1),
      y(cloud.rotations[4 * g + 2], 4, 2), z(cloud.rotations[4 * g + 3], 4, 3);
  const Quat s = 2.0 / (w * w + x * x + y * y + z * z);
  const Quat r0[3] = {1.0 - s * (y * y + z * z), s * (x * y + w * z), s * (x * z - w * y)};
  const Quat r1[3] = {s * (x * y - w * z), 1.0 - s * (x * x + z * z), s * (y * z + w * x)};
  const Quat r2[3] = {s * (x * z + w * y), s * (y * z - w * x), 1.0 - s * (x * x + y * y)};
  Eigen::Vector3d r0v, r1v, r2v;
  for (int k = 0; k < 3; ++k) {
    r0v[k] = r0[k].value();
    r1v[k] = r1[k].value();
    r2v[k] = r2[k].value();
  }
  const Eigen::Vector3d a = rot * r0v * su, b = rot * r1v * sv, c = rot * pos + trans;
  const Eigen::Vector3d* cols[3] = {&a, &b, &c};
  double tu[3], tv[3], tw[3];
  for (int k = 0; k < 3; ++k) {
    tu[k] = p.fx * (*cols[k])[0] + p.cx * (*cols[k])[2];
    tv[k] = p.fy * (*cols[k])[1] + p.cy * (*cols[k])[2];
    tw[k] = (*cols[k])[2];
  }
  // mean = N / d with N_x = 9 (Tu0 Tw0 + Tu1 Tw1) - Tu2 Tw2, d = 9 (Tw0^2 + Tw1^2) - Tw2^2.
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
  // Columns a, b, c of K^-1 M: dL/dcol_k = (fx dTu_k, fy dTv_k, cx dTu_k + cy dTv_k + dTw_k).
  Eigen::Vector3d dcol[3];
  for (int k = 0; k < 3; ++k) {
    dcol[k] = Eigen::Vector3d(p.fx * dTu[k], p.fy * dTv[k], p.cx * dTu[k] + p.cy * dTv[k] + dTw[k]);
  }
  const Eigen::Vector3d d_pos = rot.transpose() * dcol[2];
  const Eigen::Vector3d d_r0 = su * (rot.transpose() * dcol[0]);
  const Eigen::Vector3d d_r1 = sv * (rot.transpose() * dcol[1]);
  for (int k = 0; k < 3; ++k) out[k] = d_pos[k];
  out[3] = dcol[0].dot(a);  // d a / d log su = a
  out[4] = dcol[1].dot(b);
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

// One band of rows: its own sparse accumulators (touched splats in first-touch order).
struct Band {
  std::vector<uint32_t> touched;
  std::vector<SplatGrad> grads;  // parallel to touched
};

}  // namespace

absl::StatusOr<RenderResult> RenderForBackward(const GaussianCloud& cloud,
                                               const PinholeCamera& camera,
                                               const RenderOptions& options) {
  if (cloud.num_scales != 2) return absl::InvalidArgumentError("backward: needs a 2DGS cloud");
  RenderOptions o = options;
  o.model = SplatModel::kSurfel2d;
  o.color = true;
  o.trace = TraceOptions{};
  o.trace.enabled = true;  // weights only (the fast vector trace): T is recovered from them
  return Render(cloud, camera, o);
}

absl::StatusOr<SurfelGradients> TileBackward(const GaussianCloud& cloud,
                                             const PinholeCamera& camera,
                                             const RenderOptions& options,
                                             const RenderResult& forward,
                                             const std::vector<float>& dloss_dcolor,
                                             const std::vector<float>& dloss_dalpha) {
  if (dloss_dcolor.size() != 3 * static_cast<size_t>(camera.width) * camera.height) {
    return absl::InvalidArgumentError("backward: loss gradients do not match the image");
  }
  return TileBackward(cloud, camera, options, forward,
                      ImageAdjoints{.color = dloss_dcolor, .alpha = dloss_dalpha});
}

absl::StatusOr<SurfelGradients> TileBackward(const GaussianCloud& cloud,
                                             const PinholeCamera& camera,
                                             const RenderOptions& options,
                                             const RenderResult& forward,
                                             const ImageAdjoints& adjoints) {
  if (cloud.num_scales != 2) return absl::InvalidArgumentError("backward: needs a 2DGS cloud");
  const size_t pixels = static_cast<size_t>(camera.width) * camera.height;
  const ContributorTrace& trace = forward.trace;
  if (forward.width != camera.width || forward.height != camera.height ||
      trace.pixels.size() != pixels || trace.offsets.size() != pixels + 1 ||
      forward.visible.size() != cloud.size()) {
    return absl::InvalidArgumentError(
        "backward: the forward is not a full trace with transmittance of this cloud and camera");
  }
  const std::span<const float> dloss_dcolor = adjoints.color, dloss_dalpha = adjoints.alpha,
                               dloss_dnormal = adjoints.normal,
                               dloss_dmedian = adjoints.median_depth;
  if ((!dloss_dcolor.empty() && dloss_dcolor.size() != 3 * pixels) ||
      (!dloss_dalpha.empty() && dloss_dalpha.size() != pixels) ||
      (!dloss_dnormal.empty() && dloss_dnormal.size() != 3 * pixels) ||
      (!dloss_dmedian.empty() && dloss_dmedian.size() != pixels)) {
    return absl::InvalidArgumentError("backward: loss gradients do not match the image");
  }
  const ProjectionParams params = MakeProjectionParams(camera, options, cloud.sh_degree);
  const size_t n = cloud.size();
  // The splats exactly as the forward blended them: the forward's own when it left them in the
  // workspace, else projected again (the same function, the same result).
  std::vector<ProjectedSplat> own;
  const ProjectedSplat* splats_ptr = nullptr;
  if (options.workspace != nullptr && options.workspace->splats.size() == n) {
    splats_ptr = options.workspace->splats.data();
  } else {
    own.resize(n);
    std::vector<uint8_t> visible(n);
    ProjectSurfels(cloud, 0, n, params, own.data(), visible.data());
    splats_ptr = own.data();
  }
  const ProjectedSplat* splats = splats_ptr;
  const double bg[3] = {options.background[0], options.background[1], options.background[2]};
  const float* cam_from_world = params.rotation;  // row-major

  const int bands = (camera.height + kTileSize - 1) / kTileSize;
  std::vector<Band> band_grads(bands);
  RunWithThreads(options.num_threads, [&] {
    tbb::parallel_for(0, bands, [&](int band) {
      Band& out = band_grads[band];
      std::vector<int32_t> slot(n, -1);
      auto at = [&](uint32_t g) -> SplatGrad& {
        if (slot[g] < 0) {
          slot[g] = static_cast<int32_t>(out.touched.size());
          out.touched.push_back(g);
          out.grads.push_back(SplatGrad{});
        }
        return out.grads[slot[g]];
      };
      std::vector<double> transmittance;
      const int y_end = std::min(camera.height, (band + 1) * kTileSize);
      for (int y = band * kTileSize; y < y_end; ++y) {
        for (int x = 0; x < camera.width; ++x) {
          const size_t i = static_cast<size_t>(y) * camera.width + x;
          const uint64_t first = trace.offsets[i], last = trace.offsets[i + 1];
          if (first == last) continue;
          double dc[3] = {0, 0, 0}, dn[3] = {0, 0, 0};
          if (!dloss_dcolor.empty()) {
            for (int c = 0; c < 3; ++c) dc[c] = dloss_dcolor[3 * i + c];
          }
          if (!dloss_dnormal.empty()) {  // world -> camera frame: dL/dn_cam = R_cw dL/dn_world
            for (int r = 0; r < 3; ++r) {
              for (int c = 0; c < 3; ++c)
                dn[r] += cam_from_world[3 * r + c] * dloss_dnormal[3 * i + c];
            }
          }
          const double da = dloss_dalpha.empty() ? 0.0 : dloss_dalpha[i];
          const double dmedian = dloss_dmedian.empty() ? 0.0 : dloss_dmedian[i];
          // T before each contributor, front to back: T_0 = 1, T_{k+1} = T_k - w_k (w = alpha T).
          // The median depth is the last contributor's with T > 0.5 before it (tile_blend.h).
          transmittance.resize(last - first);
          double T_run = 1.0;
          uint64_t median = last;
          for (uint64_t e = first; e < last; ++e) {
            transmittance[e - first] = T_run;
            if (T_run > 0.5) median = e;
            T_run -= trace.entries[e].weight;
          }
          const double T_final = T_run;
          // Back to front: "after" = the colour (normal) behind contributor k (background
          // included; the normal's is 0).
          double after[3] = {T_final * bg[0], T_final * bg[1], T_final * bg[2]};
          double after_n[3] = {0, 0, 0};
          for (uint64_t e = last; e-- > first;) {
            const uint32_t g = trace.entries[e].gaussian;
            const ProjectedSplat& s = splats[g];
            const double T = transmittance[e - first];
            const double w = trace.entries[e].weight;
            const double alpha = w / T;
            SplatGrad& grad = at(g);
            // C = sum c_j a_j T_j + T_N bg: dC/da_k = c_k T_k - after_k / (1 - a_k);
            // A = 1 - T_N: dA/da_k = T_N / (1 - a_k). The normal is a channel like C.
            double dl_dalpha = da * T_final / (1.0 - alpha);
            for (int c = 0; c < 3; ++c) {
              grad.rgb[c] += w * dc[c];
              dl_dalpha += dc[c] * (s.rgb[c] * T - after[c] / (1.0 - alpha));
              after[c] += w * s.rgb[c];
              grad.normal[c] += w * dn[c];
              dl_dalpha += dn[c] * (s.normal_view[c] * T - after_n[c] / (1.0 - alpha));
              after_n[c] += w * s.normal_view[c];
            }
            // The 0.99 clamp passes no gradient to alpha (w / T is 0.99 up to float rounding
            // there); otherwise alpha = opacity * G.
            const bool clamped = alpha > kAlphaMax - 1e-5;
            const double d_depth = e == median ? dmedian : 0.0;
            if (clamped && d_depth == 0.0) continue;
            if (!clamped) grad.opacity += dl_dalpha * alpha / s.opacity;
            const float d_power =  // d alpha / d power
                clamped ? 0.0f : static_cast<float>(dl_dalpha * alpha);
            // The per-pixel planes, intersection and branch exactly as the forward computed them
            // (tile_blend.h, float); the derivatives are taken in float too and summed in double.
            const float rx = static_cast<float>(x - s.origin_px[0]);
            const float ry = static_cast<float>(y - s.origin_px[1]);
            const float k[3] = {rx * s.tw[0] + s.tu[0], rx * s.tw[1] + s.tu[1],
                                rx * s.tw[2] + s.tu[2]};
            const float l[3] = {ry * s.tw[0] + s.tv[0], ry * s.tw[1] + s.tv[1],
                                ry * s.tw[2] + s.tv[2]};
            const float pz = k[0] * l[1] - k[1] * l[0];
            const float inv = 1.0f / pz;
            const float u = (k[1] * l[2] - k[2] * l[1]) * inv,
                        v = (k[2] * l[0] - k[0] * l[2]) * inv;
            const float dx = s.mean_px[0] - static_cast<float>(x);
            const float dy = s.mean_px[1] - static_cast<float>(y);
            if (!(u * u + v * v <= 2.0f * (dx * dx + dy * dy))) {  // 2D: power = -(dx^2 + dy^2)
              grad.mean[0] += d_power * -2.0f * dx;
              grad.mean[1] += d_power * -2.0f * dy;
              grad.tw[2] += d_depth;  // depth = Tw_z, the centre's
              continue;
            }
            // 3D: power = -(u^2 + v^2) / 2, depth = u Tw_x + v Tw_y + Tw_z, u = nu / pz,
            // v = nv / pz.
            const float fd = static_cast<float>(d_depth);
            const float du = -d_power * u + fd * s.tw[0], dv = -d_power * v + fd * s.tw[1];
            grad.tw[0] += d_depth * u;
            grad.tw[1] += d_depth * v;
            grad.tw[2] += d_depth;
            const float dnu = du * inv, dnv = dv * inv, dpz = -(du * u + dv * v) * inv;
            float dk[3], dl[3];
            // nu = k1 l2 - k2 l1, nv = k2 l0 - k0 l2, pz = k0 l1 - k1 l0.
            dk[0] = -dnv * l[2] + dpz * l[1];
            dk[1] = dnu * l[2] - dpz * l[0];
            dk[2] = -dnu * l[1] + dnv * l[0];
            dl[0] = dnv * k[2] - dpz * k[1];
            dl[1] = -dnu * k[2] + dpz * k[0];
            dl[2] = dnu * k[1] - dnv * k[0];
            for (int c = 0; c < 3; ++c) {  // k = rx Tw + tu', l = ry Tw + tv'
              grad.tu[c] += dk[c];
              grad.tv[c] += dl[c];
              grad.tw[c] += rx * dk[c] + ry * dl[c];
            }
          }
        }
      }
    });
  });
  std::vector<SplatGrad> total(n, SplatGrad{});
  std::vector<uint8_t> touched(n, 0);
  for (const Band& band : band_grads) {
    for (size_t k = 0; k < band.touched.size(); ++k) {
      SplatGrad& t = total[band.touched[k]];
      const SplatGrad& b = band.grads[k];
      touched[band.touched[k]] = 1;
      for (int c = 0; c < 3; ++c) {
        t.tu[c] += b.tu[c];
        t.tv[c] += b.tv[c];
        t.tw[c] += b.tw[c];
        t.rgb[c] += b.rgb[c];
        t.normal[c] += b.normal[c];
      }
      t.mean[0] += b.mean[0];
      t.mean[1] += b.mean[1];
      t.opacity += b.opacity;
    }
  }

  SurfelGradients out = SurfelGradients::Zeros(cloud);
  const int stride = cloud.sh_stride();
  const int degree = params.sh_degree;
  const int coeffs = NumShCoeffs(degree);
  const Eigen::Vector3d eye(params.camera_center[0], params.camera_center[1],
                            params.camera_center[2]);
  RunWithThreads(options.num_threads, [&] {
    tbb::parallel_for(0, static_cast<int>(n), [&](int gi) {
      const size_t g = static_cast<size_t>(gi);
      if (!touched[g]) return;
      const SplatGrad& t = total[g];
      const ProjectedSplat& s = splats[g];
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
      using D3 = Eigen::AutoDiffScalar<Eigen::Vector3d>;
      Eigen::Matrix<D3, 3, 1> dir;
      for (int k = 0; k < 3; ++k) {
        dir[k] = D3(cloud.positions[3 * g + k] - eye[k], Eigen::Vector3d::Unit(k));
      }
      const D3 len = sqrt(dir.squaredNorm());
      for (int k = 0; k < 3; ++k) dir[k] = dir[k] / len;
      D3 basis[16];
      ShBasis(degree, dir[0], dir[1], dir[2], basis);
      const float* sh = &cloud.sh[stride * g];
      Eigen::Vector3d d_pos(geo[0], geo[1], geo[2]);
      for (int c = 0; c < 3; ++c) {
        D3 value = D3(0.5);
        for (int k = 0; k < coeffs; ++k) value += basis[k] * double(sh[3 * k + c]);
        if (value.value() < 0) continue;  // clamped: no gradient
        d_pos += t.rgb[c] * value.derivatives();
        for (int k = 0; k < coeffs; ++k) {
          out.sh[stride * g + 3 * k + c] = static_cast<float>(t.rgb[c] * basis[k].value());
        }
      }
      for (int k = 0; k < 3; ++k) out.positions[3 * g + k] = static_cast<float>(d_pos[k]);
      for (int k = 0; k < 2; ++k) out.log_scales[2 * g + k] = static_cast<float>(geo[3 + k]);
      for (int k = 0; k < 4; ++k) out.rotations[4 * g + k] = static_cast<float>(geo[5 + k]);
      out.opacity_logits[g] = static_cast<float>(geo[9]);
    });
  });
  return out;
}

}  // namespace instascene
