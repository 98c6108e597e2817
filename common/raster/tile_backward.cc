#include "common/raster/tile_backward.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>

#include "absl/strings/str_cat.h"
#include "common/core/parallel.h"
#include "common/core/status.h"
#include "common/raster/projection.h"
#include "common/raster/rasterizer.h"
#include "common/raster/splat_chain.h"

namespace instascene {
namespace {

// One band of rows: its own sparse accumulators (touched splats in first-touch order).
struct Band {
  std::vector<uint32_t> touched;
  std::vector<SplatGrad> grads;  // parallel to touched
  std::vector<int32_t> slot;     // per Gaussian: its index in touched, or -1

  SplatGrad& At(uint32_t g) {
    if (slot[g] < 0) {
      slot[g] = static_cast<int32_t>(touched.size());
      touched.push_back(g);
      grads.push_back(SplatGrad{});
    }
    return grads[slot[g]];
  }
};

// The image adjoints at one pixel (0 where an image has none); the normal's in the camera frame.
struct PixelAdjoint {
  double color[3] = {0, 0, 0}, normal[3] = {0, 0, 0}, alpha = 0, median = 0;
};
PixelAdjoint AdjointAt(const ImageAdjoints& adjoints, size_t i, const float* cam_from_world) {
  PixelAdjoint a;
  if (!adjoints.color.empty()) {
    for (int c = 0; c < 3; ++c) a.color[c] = adjoints.color[3 * i + c];
  }
  if (!adjoints.normal.empty()) {  // world -> camera frame: dL/dn_cam = R_cw dL/dn_world
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c)
        a.normal[r] += cam_from_world[3 * r + c] * adjoints.normal[3 * i + c];
    }
  }
  a.alpha = adjoints.alpha.empty() ? 0.0 : adjoints.alpha[i];
  a.median = adjoints.median_depth.empty() ? 0.0 : adjoints.median_depth[i];
  return a;
}

// dL/d power and dL/d depth of splat s at pixel (x, y) into its plane, centre and depth sums:
// the per-pixel planes, intersection and branch exactly as the forward computed them
// (tile_blend.h, float); the derivatives are taken in float too and summed in double.
void FootprintBackward(const ProjectedSplat& s, int x, int y, float d_power, double d_depth,
                       SplatGrad& grad) {
  const float rx = static_cast<float>(x - s.origin_px[0]);
  const float ry = static_cast<float>(y - s.origin_px[1]);
  const float k[3] = {rx * s.tw[0] + s.tu[0], rx * s.tw[1] + s.tu[1], rx * s.tw[2] + s.tu[2]};
  const float l[3] = {ry * s.tw[0] + s.tv[0], ry * s.tw[1] + s.tv[1], ry * s.tw[2] + s.tv[2]};
  const float pz = k[0] * l[1] - k[1] * l[0];
  const float inv = 1.0f / pz;
  const float u = (k[1] * l[2] - k[2] * l[1]) * inv, v = (k[2] * l[0] - k[0] * l[2]) * inv;
  const float dx = s.mean_px[0] - static_cast<float>(x);
  const float dy = s.mean_px[1] - static_cast<float>(y);
  if (!(u * u + v * v <= 2.0f * (dx * dx + dy * dy))) {  // 2D: power = -(dx^2 + dy^2)
    grad.mean[0] += d_power * -2.0f * dx;
    grad.mean[1] += d_power * -2.0f * dy;
    grad.tw[2] += d_depth;  // depth = Tw_z, the centre's
    return;
  }
  // 3D: power = -(u^2 + v^2) / 2, depth = u Tw_x + v Tw_y + Tw_z, u = nu / pz, v = nv / pz.
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

// One pixel's traced list [first, last) walked back to front (the alpha-compositing adjoint).
void PixelBackward(const ContributorTrace& trace, uint64_t first, uint64_t last, int x, int y,
                   const ProjectedSplat* splats, const double bg[3], const PixelAdjoint& adj,
                   std::vector<double>& transmittance, Band& out) {
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
  // Back to front: "after" = the colour (normal) behind contributor k (background included; the
  // normal's is 0).
  double after[3] = {T_final * bg[0], T_final * bg[1], T_final * bg[2]};
  double after_n[3] = {0, 0, 0};
  for (uint64_t e = last; e-- > first;) {
    const uint32_t g = trace.entries[e].gaussian;
    const ProjectedSplat& s = splats[g];
    const double T = transmittance[e - first];
    const double w = trace.entries[e].weight;
    const double alpha = w / T;
    SplatGrad& grad = out.At(g);
    // C = sum c_j a_j T_j + T_N bg: dC/da_k = c_k T_k - after_k / (1 - a_k);
    // A = 1 - T_N: dA/da_k = T_N / (1 - a_k). The normal is a channel like C.
    double dl_dalpha = adj.alpha * T_final / (1.0 - alpha);
    for (int c = 0; c < 3; ++c) {
      grad.rgb[c] += w * adj.color[c];
      dl_dalpha += adj.color[c] * (s.rgb[c] * T - after[c] / (1.0 - alpha));
      after[c] += w * s.rgb[c];
      grad.normal[c] += w * adj.normal[c];
      dl_dalpha += adj.normal[c] * (s.normal_view[c] * T - after_n[c] / (1.0 - alpha));
      after_n[c] += w * s.normal_view[c];
    }
    // The 0.99 clamp passes no gradient to alpha (w / T is 0.99 up to float rounding there);
    // otherwise alpha = opacity * G.
    const bool clamped = alpha > kAlphaMax - 1e-5;
    const double d_depth = e == median ? adj.median : 0.0;
    if (clamped && d_depth == 0.0) continue;
    if (!clamped) grad.opacity += dl_dalpha * alpha / s.opacity;
    const float d_power =  // d alpha / d power
        clamped ? 0.0f : static_cast<float>(dl_dalpha * alpha);
    FootprintBackward(s, x, y, d_power, d_depth, grad);
  }
}

// The bands' sums in band order (independent of the thread count); `touched` marks the splats
// any band touched.
std::vector<SplatGrad> SumBands(const std::vector<Band>& bands, size_t n,
                                std::vector<uint8_t>* touched) {
  std::vector<SplatGrad> total(n, SplatGrad{});
  touched->assign(n, 0);
  for (const Band& band : bands) {
    for (size_t k = 0; k < band.touched.size(); ++k) {
      SplatGrad& t = total[band.touched[k]];
      const SplatGrad& b = band.grads[k];
      (*touched)[band.touched[k]] = 1;
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
  return total;
}

absl::Status CheckForward(const GaussianCloud& cloud, const PinholeCamera& camera,
                          const RenderResult& forward, const ImageAdjoints& adjoints) {
  if (cloud.num_scales != 2) return absl::InvalidArgumentError("backward: needs a 2DGS cloud");
  const size_t pixels = static_cast<size_t>(camera.width) * camera.height;
  const ContributorTrace& trace = forward.trace;
  if (forward.width != camera.width || forward.height != camera.height ||
      trace.pixels.size() != pixels || trace.offsets.size() != pixels + 1 ||
      forward.visible.size() != cloud.size()) {
    return absl::InvalidArgumentError(
        "backward: the forward is not a full trace with transmittance of this cloud and camera");
  }
  if ((!adjoints.color.empty() && adjoints.color.size() != 3 * pixels) ||
      (!adjoints.alpha.empty() && adjoints.alpha.size() != pixels) ||
      (!adjoints.normal.empty() && adjoints.normal.size() != 3 * pixels) ||
      (!adjoints.median_depth.empty() && adjoints.median_depth.size() != pixels)) {
    return absl::InvalidArgumentError("backward: loss gradients do not match the image");
  }
  return absl::OkStatus();
}

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

namespace {

// The splats exactly as the forward blended them: the forward's own when it left them in the
// workspace, else projected again into `own` (the same function, the same result).
const ProjectedSplat* ForwardSplats(const GaussianCloud& cloud, const RenderOptions& options,
                                    const ProjectionParams& params,
                                    std::vector<ProjectedSplat>* own) {
  const size_t n = cloud.size();
  if (options.workspace != nullptr && options.workspace->splats.size() == n) {
    return options.workspace->splats.data();
  }
  own->resize(n);
  std::vector<uint8_t> visible(n);
  ProjectSurfels(cloud, 0, n, params, own->data(), visible.data());
  return own->data();
}

// Each band of kTileSize image rows' gradients per splat, the bands in parallel.
std::vector<Band> BandGradients(const ContributorTrace& trace, const PinholeCamera& camera,
                                const RenderOptions& options, const ProjectionParams& params,
                                const ProjectedSplat* splats, size_t n,
                                const ImageAdjoints& adjoints) {
  const double bg[3] = {options.background[0], options.background[1], options.background[2]};
  const int bands = (camera.height + kTileSize - 1) / kTileSize;
  std::vector<Band> band_grads(bands);
  RunWithThreads(options.num_threads, [&] {
    tbb::parallel_for(0, bands, [&](int band) {
      Band& out = band_grads[band];
      out.slot.assign(n, -1);
      std::vector<double> transmittance;
      const int y_end = std::min(camera.height, (band + 1) * kTileSize);
      for (int y = band * kTileSize; y < y_end; ++y) {
        for (int x = 0; x < camera.width; ++x) {
          const size_t i = static_cast<size_t>(y) * camera.width + x;
          const uint64_t first = trace.offsets[i], last = trace.offsets[i + 1];
          if (first == last) continue;
          PixelBackward(trace, first, last, x, y, splats, bg,
                        AdjointAt(adjoints, i, params.rotation), transmittance, out);
        }
      }
      out.slot = {};
    });
  });
  return band_grads;
}

}  // namespace

absl::StatusOr<SurfelGradients> TileBackward(const GaussianCloud& cloud,
                                             const PinholeCamera& camera,
                                             const RenderOptions& options,
                                             const RenderResult& forward,
                                             const ImageAdjoints& adjoints) {
  RETURN_IF_ERROR(CheckForward(cloud, camera, forward, adjoints));
  const ProjectionParams params = MakeProjectionParams(camera, options, cloud.sh_degree);
  const size_t n = cloud.size();
  std::vector<ProjectedSplat> own;
  const ProjectedSplat* splats = ForwardSplats(cloud, options, params, &own);
  const std::vector<Band> band_grads =
      BandGradients(forward.trace, camera, options, params, splats, n, adjoints);
  std::vector<uint8_t> touched;
  const std::vector<SplatGrad> total = SumBands(band_grads, n, &touched);
  SurfelGradients out = SurfelGradients::Zeros(cloud);
  RunWithThreads(options.num_threads, [&] {
    tbb::parallel_for(0, static_cast<int>(n), [&](int gi) {
      const size_t g = static_cast<size_t>(gi);
      if (touched[g]) ChainSplatGradient(cloud, g, splats[g], params, total[g], &out);
    });
  });
  return out;
}

}  // namespace instascene
