// services/generation/manifest_options.h: the options a completed object's manifest.json records,
// written, and read back into the options it was made with, so that an evaluation rebuilds what
// the complete stage did (the closed crop meshed like the completion, the ring views it scored). A
// key a manifest lacks was written before that option existed: it reads as what the stage did then
// (mostly: off), not as today's default. Stateless; thread-safe.
#pragma once

#include <vector>

#include <nlohmann/json.hpp>

#include "services/generation/free_space.h"
#include "services/generation/object_frame.h"
#include "services/generation/object_mesh.h"
#include "services/generation/viewpoints.h"

namespace instascene::generation {

// The object's frame. Throws nlohmann::json::exception when `frame` or one of its keys is
// missing (the caller turns it into a status).
ObjectFrame FrameFromManifest(const nlohmann::json& m);

// The free-space carving's options (the defaults for manifests before 2026-12-05).
FreeSpaceOptions FreeSpaceFromManifest(const nlohmann::json& m);
// ... as the manifest's "free_space" records them.
nlohmann::json FreeSpaceToManifest(const FreeSpaceOptions& f);

// The meshing options: each step a manifest does not record was off when it was written.
MeshingOptions MeshingFromManifest(const nlohmann::json& m);
// ... as the manifest's "meshing" records them.
nlohmann::json MeshingToManifest(const MeshingOptions& m);

// The ring of generated views and, per view, whether it was a known one.
RingOptions RingFromManifest(const nlohmann::json& m, std::vector<bool>* known);

}  // namespace instascene::generation
