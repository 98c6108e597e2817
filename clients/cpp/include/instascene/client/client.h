// instascene/client/client.h: the C++ client of an InstaScene backend, for robots and tools.
//
//   auto client = instascene::client::Client::Connect({.server = "10.0.0.5:50051"});
//   auto cup = (*client)->GetObject("kitchen", ObjectSelector::Point({0.42, -0.1, 0.78}));
//   // cup->world_from_object, cup->extent (metres when the scene is metric), cup->artefacts
//   auto files = (*client)->DownloadObject(*cup, "/tmp/cup");  // visual.glb, object.urdf, ...
//
// Every call has a deadline (ClientOptions::deadline) and is retried with exponential backoff
// while the server is UNAVAILABLE (restarting, draining, not yet up); other errors come back at
// once as the server's status (NOT_FOUND: no such scene or nothing at that point; ...). Downloads
// go through the content store and are verified against their SHA-256 digests before they appear
// under their final names. A Client is thread-safe; connect once and share it.
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "absl/status/statusor.h"

namespace instascene::client {

struct ClientOptions {
  std::string server = "127.0.0.1:50051";     // scheduler and Objects service (`instascene serve`)
  std::string store;                          // the content store's address ("" = server)
  std::string objects;                        // the Objects service's address ("" = server)
  std::chrono::milliseconds deadline{30000};  // per call (per attempt)
  int max_attempts = 4;                       // attempts while UNAVAILABLE (>= 1)
  std::chrono::milliseconds initial_backoff{200};  // doubled after each failed attempt
  // Authentication: the bearer token sent with every call ("isk_...", from
  // `instascene token create`; "" = none, for servers run with --no-auth).
  std::string token;
  // TLS (all "" = plaintext): the CA that signed the servers' certificates, and for mutual TLS
  // this client's certificate and key (PEM files); the name the certificates must carry when it
  // differs from the address's host.
  std::string tls_ca_file, tls_cert_file, tls_key_file, tls_server_name;
};

struct Vec3 {
  double x = 0, y = 0, z = 0;
};

// x_world = R(q) * x_object + translation, in the object's `units`.
struct Pose {
  Vec3 translation;
  double qx = 0, qy = 0, qz = 0, qw = 1;  // unit quaternion
};

struct Artefact {
  std::string path;    // relative: "visual.glb", "collision/hull.stl", "object.urdf", ...
  std::string sha256;  // lower-case hex digest of its bytes
  int64_t bytes = 0;
  std::string media_type;  // "model/gltf-binary", "model/stl", "application/xml", ...
};

struct ObjectInfo {
  std::string scene;
  uint32_t id = 0;
  // "export" (robot-ready artefacts), "complete" (completed object, not exported) or "segment"
  // (the raw per-instance splat only).
  std::string source;
  std::string units;           // "metres" or "scene units (unscaled)"
  double meters_per_unit = 0;  // 0 when the scene has no metric scale
  Pose world_from_object;
  Vec3 extent;             // bounding-box size in the object frame, in `units`
  std::string completion;  // "completed", "abstained (closed crop)", "raw crop ..."
  double completed_share = 0;
  int64_t gaussians = 0;
  std::string manifest_json;  // the per-object manifest (instascene.export/1), when exported
  std::vector<Artefact> artefacts;
  double query_microseconds = 0;
  bool index_loaded = false;  // false when this query loaded the scene's index first
};

// Which object: by id, the object nearest a 3D point (world, scene units; within max_distance,
// 0 = the service's default of 2 % of the scene), the object drawn at a pixel of a view, or the
// object a ray meets.
class ObjectSelector {
 public:
  static ObjectSelector Id(uint32_t id);
  static ObjectSelector Point(const Vec3& point, double max_distance = 0);
  static ObjectSelector Click(const std::string& view, int x, int y);
  static ObjectSelector Ray(const Vec3& origin, const Vec3& direction);

  enum class Kind { kId, kPoint, kClick, kRay };
  Kind kind = Kind::kId;
  uint32_t id = 0;
  Vec3 point, origin, direction;
  double max_distance = 0;
  std::string view;
  int x = 0, y = 0;
};

// One stage output of a scene (the scheduler's latest per stage and item).
struct StageOutput {
  std::string kind;   // "decompose", "segment", "complete", "export", ...
  int64_t item = -1;  // per-item stages (complete: one per object); -1 otherwise
  std::string job_id;
  std::string manifest_sha256;
  int64_t manifest_bytes = 0;
};

struct Transfer {
  int64_t files = 0, bytes = 0;
  std::vector<std::string> paths;  // what was written, absolute or relative to the call's `dir`
};

// Called with bytes done and bytes in all.
using ProgressCallback = std::function<void(int64_t done, int64_t total)>;

struct SubmitRequest {
  std::string scene_dir;  // a scene folder (scene.json, splat, images, masks)
  std::string name;       // scene name ("" = the folder's name)
  std::string parameters_json = "{}";
  std::vector<std::string> stages;  // empty = the default pipeline
  int priority = 0;
};

struct SubmittedJob {
  std::string id, kind, state;
  int64_t item = -1;
  bool created = false;  // false: an identical job existed (nothing recomputed)
};

struct SubmitResult {
  std::string scene;
  std::string scene_manifest;  // digest as "sha256/bytes"
  int64_t files_sent = 0, bytes_sent = 0, files_skipped = 0;
  std::vector<SubmittedJob> jobs;
};

class Client {
 public:
  // Connects (lazily: the first call waits for the server within its deadline and retries).
  static absl::StatusOr<std::unique_ptr<Client>> Connect(const ClientOptions& options);
  ~Client();
  Client(const Client&) = delete;
  Client& operator=(const Client&) = delete;

  // Objects (the Objects service).
  absl::StatusOr<std::vector<ObjectInfo>> ListObjects(const std::string& scene);
  absl::StatusOr<ObjectInfo> GetObject(const std::string& scene, const ObjectSelector& selector);
  // Writes every artefact of `object` under `dir` (sub-folders as in their paths) and its
  // manifest.json, each verified against its digest; returns what was written.
  absl::StatusOr<Transfer> DownloadObject(const ObjectInfo& object, const std::string& dir);

  // Scenes and results (the scheduler and the store).
  absl::StatusOr<SubmitResult> Submit(const SubmitRequest& request,
                                      const ProgressCallback& upload_progress = nullptr);
  absl::StatusOr<std::vector<StageOutput>> SceneOutputs(const std::string& scene);
  // Writes every file of one stage output under `dir` (verified).
  absl::StatusOr<Transfer> FetchOutput(const StageOutput& output, const std::string& dir);

  // The connection, for the protocol-level calls of services.h (jobs, watch, cancel, ...).
  struct Impl;
  Impl& impl() { return *impl_; }
  const ClientOptions& options() const;

 private:
  explicit Client(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace instascene::client
