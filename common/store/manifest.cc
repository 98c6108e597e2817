#include "common/store/manifest.h"

#include <algorithm>
#include <filesystem>
#include <set>

#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "common/core/status.h"
#include "common/scene/scene.h"
#include "common/splat/ply.h"
#include "common/splat/splat_formats.h"

namespace instascene::store {
namespace fs = std::filesystem;

std::vector<Digest> Manifest::Digests() const {
  std::set<Digest> unique;
  for (const auto& [path, digest] : files) unique.insert(digest);
  return {unique.begin(), unique.end()};
}

int64_t Manifest::TotalBytes() const {
  int64_t total = 0;
  for (const Digest& d : Digests()) total += d.size_bytes;
  return total;
}

std::string SerializeManifest(const Manifest& manifest) {
  nlohmann::json files = nlohmann::json::object();
  for (const auto& [path, digest] : manifest.files) files[path] = digest.ToString();
  // nlohmann::json objects are sorted by key: the dump is canonical.
  const nlohmann::json j = {{"format", kManifestFormat},
                            {"kind", manifest.kind},
                            {"files", files},
                            {"metadata", manifest.metadata}};
  return j.dump();
}

absl::Status ValidateRelativePath(absl::string_view path) {
  if (path.empty()) return absl::InvalidArgumentError("empty path");
  if (path.front() == '/' || absl::StrContains(path, '\\'))
    return absl::InvalidArgumentError(
        absl::StrCat("path '", path, "' is not a safe relative path"));
  for (absl::string_view part : absl::StrSplit(path, '/')) {
    if (part.empty() || part == "." || part == "..")
      return absl::InvalidArgumentError(
          absl::StrCat("path '", path, "' is not a safe relative path"));
  }
  return absl::OkStatus();
}

absl::StatusOr<Manifest> ParseManifest(absl::string_view bytes, absl::string_view source) {
  const nlohmann::json j = nlohmann::json::parse(bytes.begin(), bytes.end(), nullptr, false);
  auto bad = [&](absl::string_view why) {
    return absl::InvalidArgumentError(absl::StrCat(source, ": malformed manifest: ", why));
  };
  if (j.is_discarded() || !j.is_object()) return bad("not a JSON object");
  if (!j.contains("format") || !j["format"].is_string() || j["format"] != kManifestFormat)
    return bad(absl::StrCat("format is not \"", kManifestFormat, "\""));
  if (!j.contains("kind") || !j["kind"].is_string()) return bad("\"kind\" missing");
  if (!j.contains("files") || !j["files"].is_object()) return bad("\"files\" missing");
  Manifest m;
  m.kind = j["kind"].get<std::string>();
  for (const auto& [path, value] : j["files"].items()) {
    if (absl::Status s = ValidateRelativePath(path); !s.ok()) return bad(s.message());
    if (!value.is_string()) return bad(absl::StrCat("file '", path, "' has no digest string"));
    absl::StatusOr<Digest> d = ParseDigest(value.get<std::string>());
    if (!d.ok()) return bad(absl::StrCat("file '", path, "': ", d.status().message()));
    m.files[path] = *d;
  }
  if (j.contains("metadata")) m.metadata = j["metadata"];
  return m;
}

absl::StatusOr<Manifest> ManifestFromDirectory(const std::string& directory,
                                               const std::string& kind,
                                               const std::vector<std::string>& skip) {
  Manifest m;
  m.kind = kind;
  std::error_code ec;
  if (!fs::is_directory(directory, ec))
    return absl::NotFoundError(absl::StrCat(directory, ": not a directory"));
  for (auto it = fs::recursive_directory_iterator(directory, ec);
       it != fs::recursive_directory_iterator(); it.increment(ec)) {
    if (ec) return absl::UnavailableError(absl::StrCat(directory, ": ", ec.message()));
    if (!it->is_regular_file()) continue;
    const std::string rel = fs::relative(it->path(), directory).generic_string();
    if (std::any_of(skip.begin(), skip.end(),
                    [&](const std::string& p) { return absl::StartsWith(rel, p); }))
      continue;
    ASSIGN_OR_RETURN(m.files[rel], DigestFile(it->path().string()));
  }
  return m;
}

namespace {
std::vector<std::string> SceneReferences(const Scene& scene) {
  std::vector<std::string> refs = {"scene.json", scene.gaussians};
  for (const SceneView& v : scene.views) {
    if (!v.image.empty()) refs.push_back(v.image);
    if (!v.mask.empty()) refs.push_back(v.mask);
  }
  return refs;
}
}  // namespace

absl::StatusOr<Manifest> SceneManifestFromDirectory(const std::string& scene_directory) {
  ASSIGN_OR_RETURN(Scene scene, ReadScene(scene_directory));
  Manifest m;
  m.kind = "scene";
  std::error_code ec;
  const fs::path root = fs::canonical(scene_directory, ec);
  for (const std::string& rel : SceneReferences(scene)) {
    // Only regular files inside the scene folder: a FIFO or a device would hang or never end, a
    // symlink out of the folder would upload a file the user did not mean to share.
    const fs::path path = scene.Path(rel);
    const fs::path target = fs::canonical(path, ec);
    if (ec) return absl::NotFoundError(absl::StrCat(path.string(), ": ", ec.message()));
    if (!fs::is_regular_file(target))
      return absl::InvalidArgumentError(
          absl::StrCat(path.string(), ": not a regular file (scene files must be plain files)"));
    const std::string inside = target.lexically_relative(root).string();
    if (inside.empty() || inside.rfind("..", 0) == 0)
      return absl::InvalidArgumentError(absl::StrCat(
          path.string(), ": resolves to ", target.string(), ", outside the scene folder"));
    ASSIGN_OR_RETURN(m.files[rel], DigestFile(target.string()));
  }
  m.metadata["views"] = scene.views.size();
  return m;
}

absl::StatusOr<Manifest> SceneManifestFromFiles(absl::string_view scene_json,
                                                const std::map<std::string, Digest>& files) {
  ASSIGN_OR_RETURN(Scene scene, ParseSceneJson(scene_json, "scene.json"));
  Manifest m;
  m.kind = "scene";
  for (const std::string& rel : SceneReferences(scene)) {
    RETURN_IF_ERROR(ValidateRelativePath(rel));
    auto it = files.find(rel);
    if (it == files.end())
      return absl::InvalidArgumentError(
          absl::StrCat("scene.json refers to '", rel, "', which is not among the ", files.size(),
                       " files given (paths relative to the scene folder)"));
    RETURN_IF_ERROR(ValidateDigest(it->second));
    m.files[rel] = it->second;
  }
  m.metadata["views"] = scene.views.size();
  return m;
}

absl::Status ValidateSceneManifest(BlobStore& store, const Manifest& manifest,
                                   const SceneLimits& limits) {
  auto bad = [](absl::string_view why) {
    return absl::InvalidArgumentError(absl::StrCat("malformed scene manifest: ", why));
  };
  if (manifest.kind != "scene") return bad(absl::StrCat("kind is \"", manifest.kind, "\""));
  auto it = manifest.files.find("scene.json");
  if (it == manifest.files.end()) return bad("no scene.json");
  ASSIGN_OR_RETURN(std::vector<Digest> missing, store.FindMissing(manifest.Digests()));
  if (!missing.empty())
    return absl::FailedPreconditionError(
        absl::StrCat("scene manifest refers to ", missing.size(),
                     " blobs the store lacks (first: ", missing[0].ToString(), "); upload them"));
  ASSIGN_OR_RETURN(std::string text, store.Read(it->second));
  absl::StatusOr<Scene> scene = ParseSceneJson(text, "scene.json");
  if (!scene.ok()) return bad(scene.status().message());
  for (const std::string& rel : SceneReferences(*scene)) {
    if (!manifest.files.count(rel))
      return bad(absl::StrCat("scene.json refers to '", rel, "', which is not in the manifest"));
  }
  auto too_large = [](const std::string& what) {
    return absl::ResourceExhaustedError(absl::StrCat("scene too large: ", what));
  };
  if (static_cast<int64_t>(scene->views.size()) > limits.max_views)
    return too_large(absl::StrCat(scene->views.size(), " views (at most ", limits.max_views, ")"));
  int64_t total = 0;
  for (const SceneView& v : scene->views) {
    const int64_t pixels = int64_t{v.camera.width} * v.camera.height;
    if (pixels > limits.max_pixels_per_view)
      return too_large(absl::StrCat("view '", v.name, "' has ", pixels, " pixels (at most ",
                                    limits.max_pixels_per_view, ")"));
    total += pixels;
  }
  if (total > limits.max_total_pixels)
    return too_large(
        absl::StrCat(total, " pixels in all views (at most ", limits.max_total_pixels, ")"));
  // The Gaussian count from the splat's header (the first MiB holds any sane header).
  const Digest splat = manifest.files.at(scene->gaussians);
  ASSIGN_OR_RETURN(std::string head,
                   store.Read(splat, 0, std::min<int64_t>(splat.size_bytes, 1 << 20)));
  absl::StatusOr<int64_t> count = SplatCount(head, splat.size_bytes, scene->gaussians);
  if (!count.ok()) return bad(count.status().message());
  if (*count > limits.max_gaussians)
    return too_large(absl::StrCat(*count, " Gaussians (at most ", limits.max_gaussians, ")"));
  return absl::OkStatus();
}

absl::StatusOr<UploadReport> UploadManifest(BlobStore& store, const Manifest& manifest,
                                            const std::string& directory,
                                            const TransferProgress& progress) {
  UploadReport report;
  ASSIGN_OR_RETURN(std::vector<Digest> missing, store.FindMissing(manifest.Digests()));
  const std::set<Digest> to_send(missing.begin(), missing.end());
  int64_t total = 0;
  for (const Digest& d : to_send) total += d.size_bytes;
  std::set<Digest> sent;
  for (const auto& [rel, digest] : manifest.files) {
    if (!to_send.count(digest) || sent.count(digest)) {
      ++report.files_skipped;
      continue;
    }
    const int64_t before = report.bytes_sent;
    RETURN_IF_ERROR(Annotate(store.PutFile(digest, (fs::path(directory) / rel).string(),
                                           [&](int64_t done, int64_t) {
                                             if (progress) progress(before + done, total);
                                           }),
                             rel));
    sent.insert(digest);
    ++report.files_sent;
    report.bytes_sent += digest.size_bytes;
  }
  const std::string bytes = SerializeManifest(manifest);
  report.manifest = ComputeDigest(bytes);
  RETURN_IF_ERROR(store.Put(report.manifest, bytes));
  return report;
}

absl::StatusOr<Manifest> ReadManifest(BlobStore& store, const Digest& digest) {
  if (digest.size_bytes > (int64_t{64} << 20))
    return absl::InvalidArgumentError(
        absl::StrCat("manifest ", digest.ToString(), " is larger than 64 MiB"));
  ASSIGN_OR_RETURN(std::string bytes, store.Read(digest));
  return ParseManifest(bytes, absl::StrCat("manifest ", digest.ToString()));
}

absl::Status MaterializeManifest(BlobStore& store, const Manifest& manifest,
                                 const std::string& directory) {
  for (const auto& [rel, digest] : manifest.files) {
    RETURN_IF_ERROR(ValidateRelativePath(rel));
    const fs::path target = fs::path(directory) / rel;
    std::error_code ec;
    fs::create_directories(target.parent_path(), ec);
    if (ec)
      return absl::UnavailableError(
          absl::StrCat(target.parent_path().string(), ": ", ec.message()));
    if (fs::exists(target, ec) &&
        static_cast<int64_t>(fs::file_size(target, ec)) == digest.size_bytes) {
      absl::StatusOr<Digest> have = DigestFile(target.string());
      if (have.ok() && *have == digest) continue;
    }
    RETURN_IF_ERROR(Annotate(store.GetFile(digest, target.string()), rel));
  }
  return absl::OkStatus();
}

}  // namespace instascene::store
