// services/training/stage_params.h: the `train` and `segment` stages as every binary can link
// them: specs and their one parameter codec each. Light: no rasterizer, no image library.
#pragma once

#include <string>

#include "services/pipeline/stage.h"
#include "services/training/options.h"

namespace instascene::training {

// What a train job takes: the feature field's options and the method.
struct TrainStageOptions : TrainingOptions {
  std::string method = "contrastive";  // or "vote" (training-free baseline)
};

struct SegmentStageOptions {
  double threshold = 0.9;  // tau_seg (paper), against the un-normalised mean
  absl::Status Validate() const;
};

const pipeline::ParamCodec<TrainStageOptions>& TrainCodec();
const pipeline::ParamCodec<SegmentStageOptions>& SegmentCodec();
pipeline::StageSpec TrainSpec();    // input: decompose
pipeline::StageSpec SegmentSpec();  // input: train; fans out (one item per instance)

}  // namespace instascene::training
