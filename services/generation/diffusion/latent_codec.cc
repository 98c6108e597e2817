#include "services/generation/diffusion/latent_codec.h"

#include <algorithm>

#include "absl/strings/str_cat.h"

namespace instascene::generation::diffusion {

std::string IdentityCodec::name() const {
  return absl::StrCat("identity (area average to ", n_, "x", n_, ", [-1, 1])");
}

absl::StatusOr<std::vector<float>> IdentityCodec::Encode(const std::vector<float>& rgb, int width,
                                                         int height) const {
  if (width <= 0 || height <= 0 || rgb.size() != static_cast<size_t>(width) * height * 3)
    return absl::InvalidArgumentError(absl::StrCat("identity codec: an image of ", rgb.size(),
                                                   " values is not ", width, "x", height, "x3"));
  const int n = n_;
  std::vector<float> latent(static_cast<size_t>(3) * n * n, 0.0f);
  std::vector<int> count(static_cast<size_t>(n) * n, 0);
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) {
      const size_t cell = static_cast<size_t>(y * n / height) * n + x * n / width;
      ++count[cell];
      for (int c = 0; c < 3; ++c)
        latent[c * n * n + cell] += rgb[(static_cast<size_t>(y) * width + x) * 3 + c];
    }
  }
  for (int c = 0; c < 3; ++c) {
    for (size_t cell = 0; cell < count.size(); ++cell)
      latent[c * n * n + cell] = 2.0f * latent[c * n * n + cell] / std::max(1, count[cell]) - 1.0f;
  }
  return latent;
}

absl::StatusOr<std::vector<float>> IdentityCodec::Decode(const std::vector<float>& latent,
                                                         int width, int height) const {
  const int n = n_;
  if (width <= 0 || height <= 0 || latent.size() != static_cast<size_t>(3) * n * n)
    return absl::InvalidArgumentError(absl::StrCat("identity codec: a latent of ", latent.size(),
                                                   " values is not 3x", n, "x", n));
  std::vector<float> rgb(static_cast<size_t>(width) * height * 3);
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) {
      const int cell = (y * n / height) * n + x * n / width;
      for (int c = 0; c < 3; ++c)
        rgb[(static_cast<size_t>(y) * width + x) * 3 + c] =
            std::clamp(0.5f * (latent[c * n * n + cell] + 1.0f), 0.0f, 1.0f);
    }
  }
  return rgb;
}

}  // namespace instascene::generation::diffusion
