// services/training/stage.h: the `train` and `segment` stages with their run functions (link the
// training library).
//   train    scene + decompose output -> features + coarse labels (result format)
//   segment  scene + train output     -> final labels, instances/*.ply, instances.json; its items
//            are the instances, in instances.json order
#pragma once

#include "services/pipeline/stage.h"

namespace instascene::training {

pipeline::StageDefinition TrainStage();
pipeline::StageDefinition SegmentStage();

}  // namespace instascene::training
