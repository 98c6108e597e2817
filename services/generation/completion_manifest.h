// services/generation/completion_manifest.h: a completed object's manifest.json (format
// kObjectFormat): its pose and frame, oriented box, the prior's verdict and report, the
// Gaussians' provenance counts, the viewpoint ring, the options it was made with
// (manifest_options.h), the mesh and the refinement.
#pragma once

#include <nlohmann/json.hpp>

#include "services/generation/completion.h"

namespace instascene::generation {

nlohmann::json CompletionManifest(const CompletedObject& o, const CompletionOptions& options);

}  // namespace instascene::generation
