#include "services/generation/diffusion/onnx_denoiser.h"

#include <cmath>
#include <filesystem>

#include <nlohmann/json.hpp>

#include "absl/strings/str_cat.h"
#include "common/core/file_io.h"
#include "common/core/status.h"

namespace instascene::generation::diffusion {
namespace {

absl::Status ConfigError(const std::string& path, const std::string& what) {
  return absl::InvalidArgumentError(absl::StrCat("ONNX denoiser config ", path, ": ", what));
}

// A float32 [1, C, H, W] blob (or [1, n] for n values when `dims` has one entry).
cv::Mat Blob(const std::vector<int>& dims, float fill) {
  std::vector<int> sizes = {1};
  sizes.insert(sizes.end(), dims.begin(), dims.end());
  return cv::Mat(static_cast<int>(sizes.size()), sizes.data(), CV_32F, cv::Scalar(fill));
}

}  // namespace

namespace {

// o[key] into *out: a non-empty string of at most 256 bytes; absent is an error when required.
absl::Status StringField(const std::string& path, const nlohmann::json& o, const char* key,
                         bool required, std::string* out) {
  if (!o.contains(key)) {
    return required ? ConfigError(path, absl::StrCat("\"", key, "\" is missing"))
                    : absl::OkStatus();
  }
  if (!o[key].is_string() || o[key].get<std::string>().empty() ||
      o[key].get<std::string>().size() > 256)
    return ConfigError(path, absl::StrCat("\"", key, "\" must be a non-empty string"));
  *out = o[key].get<std::string>();
  return absl::OkStatus();
}

// "latent_shape": [C, H, W], positive, at most kMaxValuesPerLatent values in all.
absl::Status ReadLatentShape(const std::string& path, const nlohmann::json& j,
                             std::vector<int>* shape) {
  if (!j.contains("latent_shape") || !j["latent_shape"].is_array() || j["latent_shape"].size() != 3)
    return ConfigError(path, "\"latent_shape\" must be [C, H, W]");
  int64_t values = 1;
  for (const nlohmann::json& d : j["latent_shape"]) {
    if (!d.is_number_integer() || d.get<int64_t>() <= 0 || d.get<int64_t>() > kMaxValuesPerLatent)
      return ConfigError(path, "\"latent_shape\" must hold positive integers");
    values *= d.get<int64_t>();
    if (values > kMaxValuesPerLatent)
      return ConfigError(
          path, absl::StrCat("\"latent_shape\" holds more than ", kMaxValuesPerLatent, " values"));
    shape->push_back(d.get<int>());
  }
  return absl::OkStatus();
}

// "inputs": the model's input names (latent required; the rest optional, none unknown).
absl::Status ReadInputNames(const std::string& path, const nlohmann::json& j,
                            OnnxDenoiserConfig* c) {
  if (!j.contains("inputs") || !j["inputs"].is_object())
    return ConfigError(path, "\"inputs\" must be an object");
  const nlohmann::json& in = j["inputs"];
  for (const auto& [key, value] : in.items()) {
    if (key != "latent" && key != "alpha_bar" && key != "timestep" && key != "condition_latent" &&
        key != "target_from_condition")
      return ConfigError(path, absl::StrCat("unknown input \"", key.substr(0, 40),
                                            "\" (latent, alpha_bar, timestep, condition_latent, "
                                            "target_from_condition)"));
  }
  RETURN_IF_ERROR(StringField(path, in, "latent", true, &c->latent_input));
  RETURN_IF_ERROR(StringField(path, in, "alpha_bar", false, &c->alpha_bar_input));
  RETURN_IF_ERROR(StringField(path, in, "timestep", false, &c->timestep_input));
  RETURN_IF_ERROR(StringField(path, in, "condition_latent", false, &c->condition_input));
  RETURN_IF_ERROR(StringField(path, in, "target_from_condition", false, &c->pose_input));
  return absl::OkStatus();
}

}  // namespace

absl::StatusOr<OnnxDenoiserConfig> ReadOnnxDenoiserConfig(const std::string& path) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec))
    return absl::NotFoundError(absl::StrCat("ONNX denoiser config ", path, ": no such file"));
  absl::StatusOr<std::string> text = ReadFileBounded(path, kMaxOnnxConfigBytes);
  if (!text.ok()) return ConfigError(path, std::string(text.status().message()));
  const nlohmann::json j = nlohmann::json::parse(*text, nullptr, /*allow_exceptions=*/false);
  if (!j.is_object()) return ConfigError(path, "not a JSON object");
  OnnxDenoiserConfig c;
  std::string model;
  RETURN_IF_ERROR(StringField(path, j, "model", true, &model));
  RETURN_IF_ERROR(StringField(path, j, "name", false, &c.name));
  RETURN_IF_ERROR(StringField(path, j, "output", true, &c.output));
  const std::filesystem::path model_path(model);
  c.model_path = model_path.is_absolute()
                     ? model
                     : (std::filesystem::path(path).parent_path() / model_path).string();
  if (c.name.empty()) c.name = model_path.filename().string();
  RETURN_IF_ERROR(ReadLatentShape(path, j, &c.latent_shape));
  RETURN_IF_ERROR(ReadInputNames(path, j, &c));
  return c;
}

OnnxDenoiser::OnnxDenoiser(OnnxDenoiserConfig config, NoiseSchedule schedule, cv::dnn::Net net)
    : config_(std::move(config)), schedule_(std::move(schedule)), net_(std::move(net)) {
  latent_values_ = 1;
  for (int d : config_.latent_shape) latent_values_ *= d;
}

absl::StatusOr<std::unique_ptr<OnnxDenoiser>> OnnxDenoiser::Load(OnnxDenoiserConfig config,
                                                                 NoiseSchedule schedule) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(config.model_path, ec))
    return absl::NotFoundError(
        absl::StrCat("ONNX denoiser model ", config.model_path, ": no such file"));
  cv::dnn::Net net;
  try {
    net = cv::dnn::readNetFromONNX(config.model_path);
  } catch (const cv::Exception& e) {
    return absl::FailedPreconditionError(absl::StrCat("ONNX denoiser model ", config.model_path,
                                                      ": OpenCV cannot load it: ", e.what()));
  }
  if (net.empty())
    return absl::FailedPreconditionError(
        absl::StrCat("ONNX denoiser model ", config.model_path, ": OpenCV loaded no layers"));
  net.setPreferableBackend(cv::dnn::DNN_BACKEND_OPENCV);
  net.setPreferableTarget(cv::dnn::DNN_TARGET_CPU);
  std::unique_ptr<OnnxDenoiser> d(
      new OnnxDenoiser(std::move(config), std::move(schedule), std::move(net)));
  // One run on zeros proves the names and the output size now, not in the middle of a job.
  const std::vector<float> zeros(d->latent_values_, 0.0f);
  absl::StatusOr<std::vector<float>> probe = d->PredictNoise(NoiseQuery{&zeros, 0, 0, -1});
  if (!probe.ok()) return probe.status();
  return d;
}

absl::StatusOr<std::vector<float>> OnnxDenoiser::PredictNoise(const NoiseQuery& q) const {
  if (q.latent == nullptr || static_cast<int>(q.latent->size()) != latent_values_)
    return absl::InvalidArgumentError(absl::StrCat("ONNX denoiser ", config_.name, ": a latent of ",
                                                   q.latent ? q.latent->size() : 0,
                                                   " values; the model takes ", latent_values_));
  if (q.timestep < 0 || q.timestep >= schedule_.size())
    return absl::OutOfRangeError(
        absl::StrCat("ONNX denoiser ", config_.name, ": timestep ", q.timestep));
  if (q.condition_latent != nullptr &&
      static_cast<int>(q.condition_latent->size()) != latent_values_)
    return absl::InvalidArgumentError(absl::StrCat("ONNX denoiser ", config_.name,
                                                   ": a condition latent of ",
                                                   q.condition_latent->size(), " values"));
  std::lock_guard<std::mutex> lock(mu_);
  try {
    return Run(q);
  } catch (const cv::Exception& e) {
    return absl::FailedPreconditionError(
        absl::StrCat("ONNX denoiser ", config_.name, " (", config_.model_path, "): ", e.what()));
  }
}

absl::StatusOr<std::vector<float>> OnnxDenoiser::Run(const NoiseQuery& q) const {
  cv::Mat latent = Blob(config_.latent_shape, 0.0f);
  std::copy(q.latent->begin(), q.latent->end(), latent.ptr<float>());
  net_.setInput(latent, config_.latent_input);
  if (!config_.alpha_bar_input.empty()) {
    net_.setInput(
        Blob(config_.latent_shape, static_cast<float>(schedule_.alphas_cumprod[q.timestep])),
        config_.alpha_bar_input);
  }
  if (!config_.timestep_input.empty())
    net_.setInput(Blob(config_.latent_shape, static_cast<float>(q.timestep)),
                  config_.timestep_input);
  if (!config_.condition_input.empty()) {
    cv::Mat c = Blob(config_.latent_shape, 0.0f);  // zeros: the null condition
    if (q.condition >= 0 && q.condition_latent != nullptr)
      std::copy(q.condition_latent->begin(), q.condition_latent->end(), c.ptr<float>());
    net_.setInput(c, config_.condition_input);
  }
  if (!config_.pose_input.empty()) {
    cv::Mat p = Blob({16}, 0.0f);
    if (q.condition >= 0 && q.target_from_condition != nullptr) {
      for (int k = 0; k < 16; ++k)
        p.ptr<float>()[k] = static_cast<float>((*q.target_from_condition)[k]);
    }
    net_.setInput(p, config_.pose_input);
  }
  const cv::Mat out = net_.forward(config_.output);
  if (out.type() != CV_32F || static_cast<int64_t>(out.total()) != latent_values_)
    return absl::InvalidArgumentError(absl::StrCat(
        "ONNX denoiser ", config_.name, ": output \"", config_.output, "\" has ", out.total(),
        " values of type ", out.type(), "; the latent has ", latent_values_, " float32 values"));
  const cv::Mat dense = out.isContinuous() ? out : out.clone();
  const float* p = dense.ptr<float>();
  return std::vector<float>(p, p + latent_values_);
}

}  // namespace instascene::generation::diffusion
