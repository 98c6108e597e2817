// services/gateway/scene_upload.cc: a scene folder uploaded from a browser. The page digests every
// file of the folder (or zip) it was given and uploads scene.json; then
//   POST /api/v1/scene-manifests {"files": {"scene.json": {"hash": H, "size_bytes": N}, ...}}
// reads that scene.json from the store (as the caller), keeps exactly the files it references (the
// upload form `instascene submit` sends: ground truth and anything else stay in the browser),
// stores the scene manifest and answers which of those files the caller still has to upload:
//   {"scene_manifest": {...}, "files": {path: digest}, "missing": [path, ...], "missing_bytes": N}
// The page then uploads the missing blobs (resumable PUTs) and submits the pipeline with the
// manifest's digest; the scheduler validates the scene at submission as for any client.
#include <map>
#include <set>
#include <string>

#include <nlohmann/json.hpp>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "common/core/status.h"
#include "common/rpc/status.h"
#include "common/store/manifest.h"
#include "services/gateway/http_util.h"

namespace instascene::gateway {
namespace {

constexpr size_t kMaxFiles = 3 * 4096 + 16;  // scene.json, splat, image + mask per view
constexpr int64_t kMaxSceneJsonBytes = int64_t{16} << 20;
constexpr int64_t kWriteChunk = int64_t{1} << 20;

// The caller's blob, whole (small blobs only: `digest` is bounded by the caller).
grpc::Status ReadBlob(const httplib::Request& req, Stubs& stubs, const v1::Digest& digest,
                      std::string* out) {
  grpc::ClientContext context;
  Prepare(req, &context);
  v1::ReadRequest read;
  *read.mutable_digest() = digest;
  auto reader = stubs.store->Read(&context, read);
  v1::ReadResponse chunk;
  out->clear();
  while (reader->Read(&chunk)) out->append(chunk.data());
  return reader->Finish();
}

grpc::Status WriteBlob(const httplib::Request& req, Stubs& stubs, const std::string& bytes,
                       const v1::Digest& digest) {
  grpc::ClientContext context;
  Prepare(req, &context);
  v1::WriteResponse response;
  auto writer = stubs.store->Write(&context, &response);
  int64_t offset = 0;
  do {
    v1::WriteRequest w;
    *w.mutable_digest() = digest;
    const int64_t n = std::min<int64_t>(kWriteChunk, static_cast<int64_t>(bytes.size()) - offset);
    w.set_write_offset(offset);
    w.set_data(bytes.substr(static_cast<size_t>(offset), static_cast<size_t>(n)));
    offset += n;
    w.set_finish_write(offset == static_cast<int64_t>(bytes.size()));
    if (!writer->Write(w)) break;
  } while (offset < static_cast<int64_t>(bytes.size()));
  writer->WritesDone();
  return writer->Finish();
}

// {"hash": H, "size_bytes": N} (size as a number or, as protobuf's JSON writes int64, a string).
absl::StatusOr<store::Digest> JsonDigest(const nlohmann::json& j, const std::string& path) {
  const std::string where = absl::StrCat("files[\"", path.substr(0, 200), "\"]");
  if (!j.is_object() || !j.contains("hash") || !j["hash"].is_string() || !j.contains("size_bytes"))
    return absl::InvalidArgumentError(absl::StrCat(where, ": expected {\"hash\", \"size_bytes\"}"));
  store::Digest d;
  d.hash = j["hash"].get<std::string>();
  const nlohmann::json& size = j["size_bytes"];
  if (size.is_number_integer()) {
    d.size_bytes = size.get<int64_t>();
  } else if (!size.is_string() || !absl::SimpleAtoi(size.get<std::string>(), &d.size_bytes)) {
    return absl::InvalidArgumentError(absl::StrCat(where, ".size_bytes: not an integer"));
  }
  if (absl::Status s = store::ValidateDigest(d); !s.ok())
    return absl::InvalidArgumentError(absl::StrCat(where, ": ", s.message()));
  return d;
}

absl::StatusOr<std::map<std::string, store::Digest>> ParseFiles(const std::string& body) {
  const nlohmann::json j = nlohmann::json::parse(body, nullptr, /*allow_exceptions=*/false);
  if (j.is_discarded() || !j.is_object() || !j.contains("files") || !j["files"].is_object())
    return absl::InvalidArgumentError(
        "request body: expected {\"files\": {PATH: {\"hash\": H, \"size_bytes\": N}, ...}}");
  if (j["files"].size() > kMaxFiles)
    return absl::ResourceExhaustedError(
        absl::StrCat("request body: ", j["files"].size(), " files, at most ", kMaxFiles));
  std::map<std::string, store::Digest> files;
  for (const auto& [path, digest] : j["files"].items()) {
    if (absl::Status s = store::ValidateRelativePath(path); !s.ok())
      return absl::InvalidArgumentError(
          absl::StrCat("files: path '", path.substr(0, 200), "': ", s.message()));
    ASSIGN_OR_RETURN(files[path], JsonDigest(digest, path));
  }
  return files;
}

// The answer to a manifest's creation: its digest, every file's digest, and which files (and
// how many bytes) the store still misses.
nlohmann::json ManifestAnswer(const store::Digest& digest, const store::Manifest& manifest,
                              const v1::FindMissingBlobsResponse& found) {
  std::set<std::string> missing_hashes;
  for (const v1::Digest& d : found.missing()) missing_hashes.insert(d.hash());
  nlohmann::json answer = {
      {"scene_manifest", {{"hash", digest.hash}, {"size_bytes", digest.size_bytes}}},
      {"files", nlohmann::json::object()},
      {"missing", nlohmann::json::array()}};
  int64_t missing_bytes = 0;
  for (const auto& [path, d] : manifest.files) {
    answer["files"][path] = {{"hash", d.hash}, {"size_bytes", d.size_bytes}};
    if (missing_hashes.count(d.hash)) {
      answer["missing"].push_back(path);
      missing_bytes += d.size_bytes;
    }
  }
  answer["missing_bytes"] = missing_bytes;
  return answer;
}

void CreateSceneManifest(const httplib::Request& req, httplib::Response& res, Stubs& stubs) {
  absl::StatusOr<std::map<std::string, store::Digest>> files = ParseFiles(req.body);
  if (!files.ok()) return SendError(res, rpc::ToGrpcStatus(files.status()));
  auto scene_json = files->find("scene.json");
  if (scene_json == files->end())
    return SendError(res, grpc::StatusCode::INVALID_ARGUMENT,
                     "files: no scene.json at the folder's top level");
  if (scene_json->second.size_bytes > kMaxSceneJsonBytes)
    return SendError(res, grpc::StatusCode::RESOURCE_EXHAUSTED,
                     absl::StrCat("scene.json: ", scene_json->second.size_bytes, " bytes, at most ",
                                  kMaxSceneJsonBytes));
  std::string text;
  if (grpc::Status s = ReadBlob(req, stubs, rpc::ToProto(scene_json->second), &text); !s.ok()) {
    if (s.error_code() == grpc::StatusCode::NOT_FOUND)
      return SendError(res, grpc::StatusCode::FAILED_PRECONDITION,
                       absl::StrCat("scene.json (", scene_json->second.ToString(),
                                    ") is not in the store: upload it first"));
    return SendError(res, s);
  }
  absl::StatusOr<store::Manifest> manifest = store::SceneManifestFromFiles(text, *files);
  if (!manifest.ok()) return SendError(res, rpc::ToGrpcStatus(manifest.status()));
  const std::string bytes = store::SerializeManifest(*manifest);
  const store::Digest digest = store::ComputeDigest(bytes);
  if (grpc::Status s = WriteBlob(req, stubs, bytes, rpc::ToProto(digest)); !s.ok())
    return SendError(res, s);
  v1::FindMissingBlobsRequest find;
  for (const store::Digest& d : manifest->Digests()) *find.add_digests() = rpc::ToProto(d);
  v1::FindMissingBlobsResponse found;
  {
    grpc::ClientContext context;
    Prepare(req, &context);
    if (grpc::Status s = stubs.store->FindMissingBlobs(&context, find, &found); !s.ok())
      return SendError(res, s);
  }
  const nlohmann::json answer = ManifestAnswer(digest, *manifest, found);
  res.set_content(answer.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace) + "\n",
                  "application/json");
}

}  // namespace

void AddSceneUploadRoutes(httplib::Server& http, std::shared_ptr<Stubs> stubs) {
  http.Post("/api/v1/scene-manifests",
            [stubs](const httplib::Request& req, httplib::Response& res) {
              CreateSceneManifest(req, res, *stubs);
            });
}

}  // namespace instascene::gateway
