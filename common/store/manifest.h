// common/store/manifest.h: manifests, the directories of the store. A manifest is a small canonical
// JSON blob mapping relative file paths to digests (plus free metadata); a scene upload, every
// stage's result and every object are one manifest. Functions here work on any BlobStore.
//
//   {"format": "instascene.manifest/1", "kind": "scene", "files": {"scene.json": "hash/size", ...},
//    "metadata": {...}}
// Thread-safe: stateless functions.
#pragma once

#include <map>
#include <string>

#include <nlohmann/json.hpp>

#include "absl/status/statusor.h"
#include "common/store/blob_store.h"

namespace instascene::store {

inline constexpr char kManifestFormat[] = "instascene.manifest/1";

struct Manifest {
  std::string kind;                     // "scene", "decompose", "train", "segment", ...
  std::map<std::string, Digest> files;  // relative path -> blob
  nlohmann::json metadata = nlohmann::json::object();

  std::vector<Digest> Digests() const;  // the files' blobs (deduplicated, sorted)
  int64_t TotalBytes() const;
};

std::string SerializeManifest(const Manifest& manifest);  // canonical: same manifest, same bytes
// `source` names the manifest in errors. Checks the format, safe relative paths and digests.
absl::StatusOr<Manifest> ParseManifest(absl::string_view bytes, absl::string_view source);

// A safe relative path: not empty, not absolute, no "." / ".." components, no backslashes.
absl::Status ValidateRelativePath(absl::string_view path);

// Every regular file under `directory` (recursively), digested. `skip` prefixes are left out.
absl::StatusOr<Manifest> ManifestFromDirectory(const std::string& directory,
                                               const std::string& kind,
                                               const std::vector<std::string>& skip = {});
// The upload form of a scene directory: scene.json and exactly the files it references (the splat,
// images, masks); ground truth and anything else stay local.
absl::StatusOr<Manifest> SceneManifestFromDirectory(const std::string& scene_directory);
// The same upload form from a client's list of files (path -> digest, e.g. a browser's folder) and
// the text of its scene.json: exactly the files scene.json references; a reference not among
// `files` is INVALID_ARGUMENT naming it.
absl::StatusOr<Manifest> SceneManifestFromFiles(absl::string_view scene_json,
                                                const std::map<std::string, Digest>& files);
// What one submitted scene may hold; over a limit is RESOURCE_EXHAUSTED naming it.
struct SceneLimits {
  int64_t max_views = 4096;
  int64_t max_pixels_per_view = int64_t{8192} * 8192;  // 67 MP
  int64_t max_total_pixels = int64_t{1} << 32;         // over every view
  int64_t max_gaussians = 20'000'000;
};

// Checks that a scene manifest is a scene: scene.json present and valid, every file it references
// in the manifest, and within `limits` (views, pixels per view and in all, Gaussians: the count is
// read from the splat's PLY header in the store, without loading it).
absl::Status ValidateSceneManifest(BlobStore& store, const Manifest& manifest,
                                   const SceneLimits& limits = {});

// Uploads the files of `manifest` (found under `directory`) that the store lacks, then the manifest
// blob itself; returns the manifest's digest. `progress` counts bytes actually sent.
struct UploadReport {
  Digest manifest;
  int64_t files_sent = 0, bytes_sent = 0, files_skipped = 0;
};
absl::StatusOr<UploadReport> UploadManifest(BlobStore& store, const Manifest& manifest,
                                            const std::string& directory,
                                            const TransferProgress& progress = nullptr);
absl::StatusOr<Manifest> ReadManifest(BlobStore& store, const Digest& digest);
// Writes every file of a manifest under `directory` (verified downloads).
absl::Status MaterializeManifest(BlobStore& store, const Manifest& manifest,
                                 const std::string& directory);

}  // namespace instascene::store
