// services/objects/stage.h: the runnable `export` stage: <out>/<id>/ per object (export.h) and
// <out>/objects.json, the catalogue (id, folder, pose, size, units, completion, collision parts).
#pragma once

#include "services/objects/stage_params.h"
#include "services/pipeline/stage.h"

namespace instascene::objects {

pipeline::StageDefinition ExportStage();

}  // namespace instascene::objects
