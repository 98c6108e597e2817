#include "common/raster/testing/reference_renderer.h"

#include <algorithm>
#include <cmath>

#include <Eigen/Dense>

#include "common/splat/sh.h"

namespace instascene::testing {
namespace {

struct RefSplat {
  bool visible = false;
  Eigen::Vector3d p_view, a, b, normal_view;        // a, b: scaled tangent axes in view (2DGS)
  Eigen::Matrix3d conic = Eigen::Matrix3d::Zero();  // 3DGS: 2x2 inverse covariance in top-left
  Eigen::Vector2d mean_px;
  double opacity = 0, depth = 0;
  double rgb[3] = {0, 0, 0};
  int tx0 = 0, tx1 = 0, ty0 = 0, ty1 = 0;
};

}  // namespace

RenderResult ReferenceRender(const GaussianCloud& cloud, const PinholeCamera& camera,
                             const RenderOptions& options) {
  const bool surfel = cloud.num_scales == 2;
  const int W = camera.width, H = camera.height, tiles_x = (W + 15) / 16, tiles_y = (H + 15) / 16;
  const double fx = camera.fx, fy = camera.fy, cx = camera.cx - 0.5, cy = camera.cy - 0.5;
  const Eigen::Matrix3d Rcw = camera.camera_from_world.rotation;
  const Eigen::Vector3d tcw = camera.camera_from_world.translation;
  const Eigen::Vector3d center = camera.CenterInWorld();
  const size_t n = cloud.size();
  const int sh_degree = std::min(options.max_sh_degree, cloud.sh_degree);
  std::vector<RefSplat> splats(n);
  for (size_t i = 0; i < n; ++i) {
    RefSplat& s = splats[i];
    const Eigen::Vector3d pos(cloud.positions[3 * i], cloud.positions[3 * i + 1],
                              cloud.positions[3 * i + 2]);
    s.p_view = Rcw * pos + tcw;
    if (s.p_view.z() <= options.near_plane) continue;
    const float* q = &cloud.rotations[4 * i];
    const Eigen::Matrix3d R =
        Eigen::Quaterniond(q[0], q[1], q[2], q[3]).normalized().toRotationMatrix();
    s.opacity = 1.0 / (1.0 + std::exp(-static_cast<double>(cloud.opacity_logits[i])));
    s.depth = s.p_view.z();
    double radius = 0;
    if (surfel) {
      s.a = Rcw * R.col(0) * std::exp(static_cast<double>(cloud.log_scales[2 * i])) *
            options.scale_modifier;
      s.b = Rcw * R.col(1) * std::exp(static_cast<double>(cloud.log_scales[2 * i + 1])) *
            options.scale_modifier;
      s.normal_view = Rcw * R.col(2);
      const double c = -s.p_view.dot(s.normal_view);
      if (c == 0) continue;
      if (c < 0) s.normal_view = -s.normal_view;
      Eigen::Matrix3d K;
      K << fx, 0, cx, 0, fy, cy, 0, 0, 1;
      Eigen::Matrix3d M;
      M << s.a, s.b, s.p_view;
      M = K * M;
      const Eigen::Vector3d tu = M.row(0), tv = M.row(1), tw = M.row(2);
      const Eigen::Vector3d t(9, 9, -1);
      const double d = t.dot(tw.cwiseProduct(tw));
      if (d == 0) continue;
      const Eigen::Vector3d f = t / d;
      s.mean_px = {f.dot(tu.cwiseProduct(tw)), f.dot(tv.cwiseProduct(tw))};
      const double hx =
          std::sqrt(std::max(1e-4, s.mean_px.x() * s.mean_px.x() - f.dot(tu.cwiseProduct(tu))));
      const double hy =
          std::sqrt(std::max(1e-4, s.mean_px.y() * s.mean_px.y() - f.dot(tv.cwiseProduct(tv))));
      radius = std::ceil(std::max({hx, hy, 3.0 * 0.707106}));
    } else {
      Eigen::Vector3d sc;
      for (int k = 0; k < 3; ++k)
        sc[k] = std::exp(static_cast<double>(cloud.log_scales[3 * i + k])) * options.scale_modifier;
      const Eigen::Matrix3d cov = R * sc.cwiseAbs2().asDiagonal() * R.transpose();
      const Eigen::Vector3d& t = s.p_view;
      const double limx = 1.3 * 0.5 * W / fx, limy = 1.3 * 0.5 * H / fy;
      const double txc = std::clamp(t.x() / t.z(), -limx, limx) * t.z();
      const double tyc = std::clamp(t.y() / t.z(), -limy, limy) * t.z();
      Eigen::Matrix<double, 2, 3> J;
      J << fx / t.z(), 0, -fx * txc / (t.z() * t.z()), 0, fy / t.z(), -fy * tyc / (t.z() * t.z());
      Eigen::Matrix2d c2 = J * Rcw * cov * Rcw.transpose() * J.transpose();
      c2(0, 0) += 0.3;
      c2(1, 1) += 0.3;
      if (c2.determinant() == 0) continue;
      s.conic.topLeftCorner<2, 2>() = c2.inverse();
      const double mid = 0.5 * (c2(0, 0) + c2(1, 1));
      const double l1 = mid + std::sqrt(std::max(0.1, mid * mid - c2.determinant()));
      radius = std::ceil(3.0 * std::sqrt(l1));
      s.mean_px = {fx * t.x() / t.z() + cx, fy * t.y() / t.z() + cy};
      int k = 0;
      sc.minCoeff(&k);
      s.normal_view = Rcw * R.col(k);
      if (s.normal_view.dot(t) > 0) s.normal_view = -s.normal_view;
    }
    s.tx0 = std::clamp(static_cast<int>((s.mean_px.x() - radius) / 16), 0, tiles_x);
    s.ty0 = std::clamp(static_cast<int>((s.mean_px.y() - radius) / 16), 0, tiles_y);
    s.tx1 = std::clamp(static_cast<int>((s.mean_px.x() + radius + 15) / 16), 0, tiles_x);
    s.ty1 = std::clamp(static_cast<int>((s.mean_px.y() + radius + 15) / 16), 0, tiles_y);
    if ((s.tx1 - s.tx0) * (s.ty1 - s.ty0) == 0) continue;
    s.visible = true;
    const Eigen::Vector3d dir = (pos - center).normalized();
    float rgb[3];
    EvalShColor(sh_degree, &cloud.sh[static_cast<size_t>(cloud.sh_stride()) * i],
                static_cast<float>(dir.x()), static_cast<float>(dir.y()),
                static_cast<float>(dir.z()), rgb);
    for (int c = 0; c < 3; ++c) s.rgb[c] = rgb[c];
  }

  RenderResult out;
  out.width = W;
  out.height = H;
  const size_t P = static_cast<size_t>(W) * H;
  const int D = options.feature_dim;
  out.color.assign(3 * P, 0);
  out.alpha.assign(P, 0);
  out.depth.assign(P, 0);
  out.median_depth.assign(P, 0);
  out.normal.assign(3 * P, 0);
  out.features.assign(P * D, 0);
  out.num_contributors.assign(P, 0);
  out.visible.assign(n, 0);
  for (size_t i = 0; i < n; ++i) out.visible[i] = splats[i].visible;
  out.trace.offsets.push_back(0);
  for (int y = 0; y < H; ++y) {
    for (int x = 0; x < W; ++x) {
      const int tx = x / 16, ty = y / 16;
      std::vector<size_t> list;
      for (size_t i = 0; i < n; ++i) {
        const RefSplat& s = splats[i];
        if (s.visible && tx >= s.tx0 && tx < s.tx1 && ty >= s.ty0 && ty < s.ty1) list.push_back(i);
      }
      std::stable_sort(list.begin(), list.end(), [&](size_t a, size_t b) {
        return static_cast<float>(splats[a].depth) < static_cast<float>(splats[b].depth);
      });
      double T = 1, C[3] = {0, 0, 0}, Dacc = 0, median = 0, N[3] = {0, 0, 0};
      std::vector<double> E(D, 0.0);
      const size_t pix = static_cast<size_t>(y) * W + x;
      const Eigen::Vector3d ray((x - cx) / fx, (y - cy) / fy, 1.0);
      for (size_t i : list) {
        const RefSplat& s = splats[i];
        const Eigen::Vector2d d = s.mean_px - Eigen::Vector2d(x, y);
        double power, depth;
        if (surfel) {
          Eigen::Matrix3d A;
          A << s.a, s.b, -ray;
          const Eigen::Vector3d uvt = A.fullPivLu().solve(-s.p_view);
          const double rho3d = uvt[0] * uvt[0] + uvt[1] * uvt[1];
          const double rho2d = 2.0 * d.squaredNorm();
          depth = rho3d <= rho2d ? uvt[2] : s.p_view.z();
          if (depth < options.near_plane) continue;
          power = -0.5 * std::min(rho3d, rho2d);
        } else {
          power = -0.5 * d.dot(s.conic.topLeftCorner<2, 2>() * d);
          depth = s.depth;
        }
        if (power > 0) continue;
        const double alpha = std::min(0.99, s.opacity * std::exp(power));
        if (alpha < 1.0 / 255.0) continue;
        if (T * (1 - alpha) < 1e-4) break;
        const double w = alpha * T;
        for (int c = 0; c < 3; ++c) C[c] += w * s.rgb[c];
        Dacc += w * depth;
        for (int c = 0; c < 3; ++c) N[c] += w * s.normal_view[c];
        for (int k = 0; k < D; ++k) E[k] += w * options.features[i * D + k];
        if (T > 0.5) median = depth;
        out.trace.entries.push_back({static_cast<uint32_t>(i), static_cast<float>(w)});
        if (options.trace.transmittance) out.trace.transmittance.push_back(static_cast<float>(T));
        ++out.num_contributors[pix];
        T *= 1 - alpha;
      }
      out.trace.pixels.push_back(static_cast<uint32_t>(pix));
      out.trace.offsets.push_back(out.trace.entries.size());
      for (int c = 0; c < 3; ++c)
        out.color[3 * pix + c] = static_cast<float>(C[c] + T * options.background[c]);
      out.alpha[pix] = static_cast<float>(1 - T);
      out.depth[pix] = T < 1 ? static_cast<float>(Dacc / (1 - T)) : 0.0f;
      out.median_depth[pix] = static_cast<float>(median);
      const Eigen::Vector3d nw = Rcw.transpose() * Eigen::Vector3d(N[0], N[1], N[2]);
      for (int c = 0; c < 3; ++c) out.normal[3 * pix + c] = static_cast<float>(nw[c]);
      for (int k = 0; k < D; ++k) out.features[pix * D + k] = static_cast<float>(E[k]);
    }
  }
  return out;
}

}  // namespace instascene::testing
