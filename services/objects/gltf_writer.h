// services/objects/gltf_writer.h: a binary glTF 2.0 (.glb) of one coloured triangle mesh with its
// geometry compressed by Draco (KHR_draco_mesh_compression, encoded with Google's Draco library,
// the extension's reference implementation). Positions in metres, glTF's frame (+Y up); the caller
// converts. Vertex colours are linear RGB (COLOR_0, normalised bytes) under a white material.
// Deterministic.
#pragma once

#include <string>

#include "absl/status/statusor.h"
#include "common/geometry/triangle_mesh.h"

namespace instascene::objects {

struct GlbOptions {
  std::string name = "object";
  int position_bits = 14;  // Draco quantisation of positions (2^-14 of the extent)
};

struct GlbResult {
  std::string bytes;    // the .glb file
  std::string draco;    // the Draco stream inside it (also written as mesh.drc)
  size_t vertices = 0;  // as Draco decodes them
  size_t triangles = 0;
};

absl::StatusOr<GlbResult> EncodeDracoGlb(const TriangleMesh& mesh, const GlbOptions& options = {});

// Decodes a Draco stream (tests and the triangle-count check of the export).
absl::StatusOr<TriangleMesh> DecodeDraco(const std::string& bytes);

}  // namespace instascene::objects
