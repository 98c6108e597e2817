// services/generation/diffusion/onnx_denoiser.h: a Denoiser that runs an ONNX model file with
// OpenCV's DNN module (issue 18; `--denoiser onnx:FILE.json`). A site supplies the model and a
// small JSON naming its inputs and output:
//   {"model": "denoiser.onnx",          // relative to the JSON's folder (or absolute)
//    "name": "my-model",                // optional, for messages and manifests
//    "latent_shape": [3, 32, 32],       // C, H, W of one latent (at most kMaxValuesPerLatent)
//    "inputs": {"latent": "x",          // required: the noisy latent, float32 [1, C, H, W]
//               "alpha_bar": "a",       // optional: a_t of the schedule, filled to [1, C, H, W]
//               "timestep": "t",        // optional: the timestep as a float, filled to [1, C, H,
//               W] "condition_latent": "c",        // optional: the condition's clean latent
//                                               // [1, C, H, W]; zeros when unconditional
//               "target_from_condition": "p"},  // optional: [1, 16] row-major; zeros when
//                                               // unconditional
//    "output": "eps"}                   // the predicted noise, [1, C, H, W] (any shape of C*H*W)
// Per-step scalars arrive filled to the latent's shape because OpenCV 4.6's importer runs
// same-shape element-wise graphs but not a scalar input gathered from a table (the usual
// timestep embedding); a model that needs its own embedding computes it from the filled tensor.
// Loading runs the model once on zeros, so wrong names and output sizes fail at load with the
// file and the name. OpenCV's network is not reentrant: predictions are serialised. Thread-safe.
#pragma once

#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include <opencv2/dnn.hpp>

#include "services/generation/diffusion/ddim.h"
#include "services/generation/diffusion/denoiser.h"

namespace instascene::generation::diffusion {

inline constexpr int64_t kMaxOnnxConfigBytes = 64 * 1024;

struct OnnxDenoiserConfig {
  std::string model_path;  // resolved against the JSON's folder
  std::string name;
  std::vector<int> latent_shape;
  std::string latent_input, alpha_bar_input, timestep_input, condition_input, pose_input;
  std::string output;
};

// InvalidArgument naming the file and the field for a malformed config; NotFound when it is
// missing.
absl::StatusOr<OnnxDenoiserConfig> ReadOnnxDenoiserConfig(const std::string& json_path);

class OnnxDenoiser : public Denoiser {
 public:
  // FailedPrecondition naming the model when OpenCV cannot load or run it.
  static absl::StatusOr<std::unique_ptr<OnnxDenoiser>> Load(OnnxDenoiserConfig config,
                                                            NoiseSchedule schedule);
  absl::StatusOr<std::vector<float>> PredictNoise(const NoiseQuery& query) const override;
  const OnnxDenoiserConfig& config() const { return config_; }
  int latent_values() const { return latent_values_; }

 private:
  OnnxDenoiser(OnnxDenoiserConfig config, NoiseSchedule schedule, cv::dnn::Net net);
  absl::StatusOr<std::vector<float>> Run(const NoiseQuery& query) const;

  OnnxDenoiserConfig config_;
  NoiseSchedule schedule_;
  int latent_values_ = 0;
  mutable std::mutex mu_;
  mutable cv::dnn::Net net_;
};

}  // namespace instascene::generation::diffusion
