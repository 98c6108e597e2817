// services/generation/image_losses.h: the image losses of the joint refinement (ALGORITHM.md 7.9)
// with their gradients with respect to the rendered image: masked L1, D-SSIM (1 - SSIM with the
// 2DGS training window: 11x11 Gaussian, sigma 1.5, C1 = 0.01^2, C2 = 0.03^2, zero padding as
// PyTorch's conv2d(padding=5) has it) and the binary cross-entropy of alpha against a mask.
// Each returns the loss value and adds `weight` times its gradient into the given buffers.
// Images are HxWx3 (or HxW for alpha), float in [0, 1]. Stateless, thread-safe.
#pragma once

#include <cstdint>
#include <vector>

namespace instascene::generation {

// Mean over the masked pixels (mask[i] != 0; every pixel when `mask` is empty) and the 3
// channels of |render - target|; 0 when the mask is empty of pixels.
double MaskedL1(const std::vector<float>& render, const std::vector<float>& target,
                const std::vector<uint8_t>& mask, double weight, std::vector<float>* d_render);

// 1 - mean SSIM over pixels and channels.
double Dssim(const std::vector<float>& render, const std::vector<float>& target, int width,
             int height, double weight, std::vector<float>* d_render);

// Mean over pixels of -[m log a + (1 - m) log(1 - a)], m = mask != 0, a clamped to
// [1e-6, 1 - 1e-6] (no gradient where clamped).
double AlphaBce(const std::vector<float>& alpha, const std::vector<uint8_t>& mask, double weight,
                std::vector<float>* d_alpha);

}  // namespace instascene::generation
