// services/generation/diffusion/latent_codec.h: the image encoder / decoder around the denoiser
// (the VAE of a latent diffusion model such as MVD-Fusion), as an interface. The diffusion prior
// encodes every known (condition) view, samples latents for the unknown ones and decodes them; a
// site serving a real model puts its VAE behind this interface (or inside its Denoiser service and
// uses the identity here). The default is the identity: RGB area-averaged to the latent grid and
// mapped to [-1, 1], decoded by nearest upsampling. Implementations are thread-compatible.
#pragma once

#include <string>
#include <vector>

#include "absl/status/statusor.h"

namespace instascene::generation::diffusion {

class LatentCodec {
 public:
  virtual ~LatentCodec() = default;
  virtual std::string name() const = 0;
  // Values per latent (the size the denoiser sees).
  virtual int latent_values() const = 0;
  // `rgb`: height x width x 3 in [0, 1]. Returns latent_values() values.
  virtual absl::StatusOr<std::vector<float>> Encode(const std::vector<float>& rgb, int width,
                                                    int height) const = 0;
  // A latent back to height x width x 3 RGB in [0, 1].
  virtual absl::StatusOr<std::vector<float>> Decode(const std::vector<float>& latent, int width,
                                                    int height) const = 0;
};

// The identity codec on an n x n grid: channel-major 3 x n x n latents in [-1, 1].
class IdentityCodec : public LatentCodec {
 public:
  explicit IdentityCodec(int n) : n_(n) {}
  std::string name() const override;
  int latent_values() const override { return 3 * n_ * n_; }
  absl::StatusOr<std::vector<float>> Encode(const std::vector<float>& rgb, int width,
                                            int height) const override;
  absl::StatusOr<std::vector<float>> Decode(const std::vector<float>& latent, int width,
                                            int height) const override;

 private:
  int n_;
};

}  // namespace instascene::generation::diffusion
