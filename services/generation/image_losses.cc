#include "services/generation/image_losses.h"

#include <algorithm>
#include <array>
#include <cmath>

#include <tbb/parallel_for.h>

namespace instascene::generation {
namespace {

constexpr int kRadius = 5;  // 11-tap window
constexpr double kC1 = 0.01 * 0.01, kC2 = 0.03 * 0.03;

std::array<double, 2 * kRadius + 1> Window() {
  std::array<double, 2 * kRadius + 1> g{};
  double sum = 0;
  for (int k = -kRadius; k <= kRadius; ++k) {
    g[k + kRadius] = std::exp(-(k * k) / (2.0 * 1.5 * 1.5));
    sum += g[k + kRadius];
  }
  for (double& v : g) v /= sum;
  return g;
}

// Separable "same" convolution with zero padding of one plane (the window is symmetric, so this
// operator is its own adjoint).
std::vector<double> Blur(const std::vector<double>& plane, int width, int height) {
  static const std::array<double, 2 * kRadius + 1> g = Window();
  std::vector<double> tmp(plane.size(), 0.0), out(plane.size(), 0.0);
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) {
      double s = 0;
      for (int k = -kRadius; k <= kRadius; ++k) {
        const int xx = x + k;
        if (xx >= 0 && xx < width) s += g[k + kRadius] * plane[static_cast<size_t>(y) * width + xx];
      }
      tmp[static_cast<size_t>(y) * width + x] = s;
    }
  }
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) {
      double s = 0;
      for (int k = -kRadius; k <= kRadius; ++k) {
        const int yy = y + k;
        if (yy >= 0 && yy < height) s += g[k + kRadius] * tmp[static_cast<size_t>(yy) * width + x];
      }
      out[static_cast<size_t>(y) * width + x] = s;
    }
  }
  return out;
}

}  // namespace

double MaskedL1(const std::vector<float>& render, const std::vector<float>& target,
                const std::vector<uint8_t>& mask, double weight, std::vector<float>* d_render) {
  const size_t pixels = render.size() / 3;
  size_t count = 0;
  for (size_t i = 0; i < pixels; ++i) count += mask.empty() || mask[i] != 0;
  if (count == 0) return 0.0;
  const double scale = 1.0 / (3.0 * count);
  double sum = 0;
  for (size_t i = 0; i < pixels; ++i) {
    if (!mask.empty() && mask[i] == 0) continue;
    for (int c = 0; c < 3; ++c) {
      const double diff = render[3 * i + c] - target[3 * i + c];
      sum += std::abs(diff);
      if (diff != 0)
        (*d_render)[3 * i + c] += static_cast<float>(weight * scale * (diff > 0 ? 1 : -1));
    }
  }
  return sum * scale;
}

namespace {

// The box of pixels where render and target differ, grown by two window radii and clipped;
// false when they are equal everywhere.
struct PixelBox {
  int x0, y0, w, h;
};
bool DifferingBox(const std::vector<float>& render, const std::vector<float>& target, int width,
                  int height, PixelBox* box) {
  int x0 = width, x1 = -1, y0 = height, y1 = -1;
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) {
      const size_t i = static_cast<size_t>(y) * width + x;
      if (render[3 * i] != target[3 * i] || render[3 * i + 1] != target[3 * i + 1] ||
          render[3 * i + 2] != target[3 * i + 2]) {
        x0 = std::min(x0, x);
        x1 = std::max(x1, x);
        y0 = std::min(y0, y);
        y1 = std::max(y1, y);
      }
    }
  }
  if (x1 < 0) return false;
  x0 = std::max(0, x0 - 2 * kRadius);
  y0 = std::max(0, y0 - 2 * kRadius);
  x1 = std::min(width - 1, x1 + 2 * kRadius);
  y1 = std::min(height - 1, y1 + 2 * kRadius);
  *box = {x0, y0, x1 - x0 + 1, y1 - y0 + 1};
  return true;
}

// Channel c of the box: the sum of its SSIM map, and d(-weight * norm * SSIM)/d render added to
// d_render.
double ChannelSsim(const std::vector<float>& render, const std::vector<float>& target, int width,
                   const PixelBox& b, int c, double scale, std::vector<float>* d_render) {
  const int w = b.w, h = b.h;
  const size_t box = static_cast<size_t>(w) * h;
  std::vector<double> x(box), y(box), xx(box), yy(box), xy(box);
  for (int r = 0; r < h; ++r) {
    for (int q = 0; q < w; ++q) {
      const size_t i = static_cast<size_t>(b.y0 + r) * width + b.x0 + q,
                   j = static_cast<size_t>(r) * w + q;
      x[j] = render[3 * i + c];
      y[j] = target[3 * i + c];
      xx[j] = x[j] * x[j];
      yy[j] = y[j] * y[j];
      xy[j] = x[j] * y[j];
    }
  }
  const std::vector<double> mx = Blur(x, w, h), my = Blur(y, w, h), mxx = Blur(xx, w, h),
                            myy = Blur(yy, w, h), mxy = Blur(xy, w, h);
  // S = A1 A2 / (B1 B2); its partials with respect to the blurred moments m_x, m_xx, m_xy.
  double sum = 0;
  std::vector<double> d_mx(box), d_mxx(box), d_mxy(box);
  for (size_t i = 0; i < box; ++i) {
    const double sxx = mxx[i] - mx[i] * mx[i], syy = myy[i] - my[i] * my[i],
                 sxy = mxy[i] - mx[i] * my[i];
    const double a1 = 2 * mx[i] * my[i] + kC1, a2 = 2 * sxy + kC2;
    const double b1 = mx[i] * mx[i] + my[i] * my[i] + kC1, b2 = sxx + syy + kC2;
    const double s = a1 * a2 / (b1 * b2);
    sum += s;
    const double ds_dmu = 2 * my[i] * a2 / (b1 * b2) - s * 2 * mx[i] / b1;  // direct
    const double ds_dsxx = -s / b2, ds_dsxy = 2 * a1 / (b1 * b2);
    d_mx[i] = ds_dmu + ds_dsxx * (-2 * mx[i]) + ds_dsxy * (-my[i]);
    d_mxx[i] = ds_dsxx;
    d_mxy[i] = ds_dsxy;
  }
  const std::vector<double> g_mx = Blur(d_mx, w, h), g_mxx = Blur(d_mxx, w, h),
                            g_mxy = Blur(d_mxy, w, h);
  for (int r = 0; r < h; ++r) {
    for (int q = 0; q < w; ++q) {
      const size_t i = static_cast<size_t>(b.y0 + r) * width + b.x0 + q,
                   j = static_cast<size_t>(r) * w + q;
      const double d_ssim = g_mx[j] + 2 * x[j] * g_mxx[j] + y[j] * g_mxy[j];
      (*d_render)[3 * i + c] += static_cast<float>(-scale * d_ssim);
    }
  }
  return sum;
}

}  // namespace

double Dssim(const std::vector<float>& render, const std::vector<float>& target, int width,
             int height, double weight, std::vector<float>* d_render) {
  const size_t pixels = static_cast<size_t>(width) * height;
  if (pixels == 0) return 0.0;
  const double norm = 1.0 / (3.0 * pixels);
  // Where render and target are equal over a whole window, SSIM is 1 and its gradient 0 (equality
  // is its maximum), zero padding included: only the box of differing pixels grown by two window
  // radii needs computing; the pixels outside it add exactly 1 each.
  PixelBox b;
  if (!DifferingBox(render, target, width, height, &b)) return 0.0;
  const size_t box = static_cast<size_t>(b.w) * b.h;
  // The box touches the image border only where it is the border, so its zero padding is the
  // image's own there, and elsewhere it lies over equal values (see above).
  double ssim_sum = 3.0 * static_cast<double>(pixels - box);
  // The three channels are independent: one task each, their sums added in channel order.
  double channel_sum[3] = {0, 0, 0};
  tbb::parallel_for(0, 3, [&](int c) {
    channel_sum[c] = ChannelSsim(render, target, width, b, c, weight * norm, d_render);
  });
  for (double sum : channel_sum) ssim_sum += sum;
  return 1.0 - ssim_sum * norm;
}

double AlphaBce(const std::vector<float>& alpha, const std::vector<uint8_t>& mask, double weight,
                std::vector<float>* d_alpha) {
  constexpr double kEps = 1e-6;
  const size_t pixels = alpha.size();
  if (pixels == 0) return 0.0;
  double sum = 0;
  for (size_t i = 0; i < pixels; ++i) {
    const bool inside = mask[i] != 0;
    const double raw = alpha[i];
    const double a = std::clamp(raw, kEps, 1.0 - kEps);
    sum += inside ? -std::log(a) : -std::log(1.0 - a);
    if (raw > kEps && raw < 1.0 - kEps) {
      const double d = inside ? -1.0 / a : 1.0 / (1.0 - a);
      (*d_alpha)[i] += static_cast<float>(weight * d / pixels);
    }
  }
  return sum / pixels;
}

}  // namespace instascene::generation
