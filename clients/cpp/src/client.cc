#include "instascene/client/client.h"

#include <filesystem>
#include <mutex>
#include <thread>

#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "common/core/status.h"
#include "common/rpc/server.h"
#include "common/rpc/status.h"
#include "common/store/manifest.h"
#include "instascene/client/services.h"
#include "services/store/remote_blob_store.h"

namespace instascene::client {
namespace fs = std::filesystem;

struct Client::Impl {
  ClientOptions options;
  std::shared_ptr<grpc::Channel> channel, store_channel, objects_channel;
  std::unique_ptr<v1::Scheduler::Stub> scheduler;
  std::unique_ptr<v1::Objects::Stub> objects;
  std::mutex store_mutex;
  std::unique_ptr<store_service::RemoteBlobStore> store;  // connected on first use

  std::string Address(const std::string& service) const {
    if (service == "store" && !options.store.empty()) return options.store;
    if (service == "objects" && !options.objects.empty()) return options.objects;
    return options.server;
  }

  absl::StatusOr<store::BlobStore*> Store() {
    std::lock_guard<std::mutex> lock(store_mutex);
    if (store) return store.get();
    absl::Status last;
    auto backoff = options.initial_backoff;
    for (int attempt = 0; attempt < options.max_attempts; ++attempt) {
      if (attempt > 0) {
        std::this_thread::sleep_for(backoff);
        backoff *= 2;
      }
      auto connected = store_service::RemoteBlobStore::Connect(
          store_channel, static_cast<int>(options.deadline.count()));
      if (connected.ok()) {
        store = std::move(*connected);
        return store.get();
      }
      last = connected.status();
      if (!absl::IsUnavailable(last) && !absl::IsDeadlineExceeded(last)) break;
    }
    return absl::UnavailableError(
        absl::StrCat("store ", Address("store"), " unreachable: ", last.message()));
  }
};

ObjectSelector ObjectSelector::Id(uint32_t id) {
  ObjectSelector s;
  s.kind = Kind::kId;
  s.id = id;
  return s;
}
ObjectSelector ObjectSelector::Point(const Vec3& point, double max_distance) {
  ObjectSelector s;
  s.kind = Kind::kPoint;
  s.point = point;
  s.max_distance = max_distance;
  return s;
}
ObjectSelector ObjectSelector::Click(const std::string& view, int x, int y) {
  ObjectSelector s;
  s.kind = Kind::kClick;
  s.view = view;
  s.x = x;
  s.y = y;
  return s;
}
ObjectSelector ObjectSelector::Ray(const Vec3& origin, const Vec3& direction) {
  ObjectSelector s;
  s.kind = Kind::kRay;
  s.origin = origin;
  s.direction = direction;
  return s;
}

namespace {

void ToProto(const Vec3& v, v1::Vector3* out) {
  out->set_x(v.x);
  out->set_y(v.y);
  out->set_z(v.z);
}
Vec3 FromProto(const v1::Vector3& v) { return {v.x(), v.y(), v.z()}; }

void ToProto(const ObjectSelector& s, v1::ObjectSelector* out) {
  switch (s.kind) {
    case ObjectSelector::Kind::kId:
      out->set_id(s.id);
      break;
    case ObjectSelector::Kind::kPoint:
      ToProto(s.point, out->mutable_point());
      out->set_max_distance(s.max_distance);
      break;
    case ObjectSelector::Kind::kClick:
      out->mutable_click()->set_view(s.view);
      out->mutable_click()->set_x(s.x);
      out->mutable_click()->set_y(s.y);
      break;
    case ObjectSelector::Kind::kRay:
      ToProto(s.origin, out->mutable_ray()->mutable_origin());
      ToProto(s.direction, out->mutable_ray()->mutable_direction());
      break;
  }
}

// "queued", "running", "succeeded", ... (the enum name without its prefix, lower case).
std::string StateName(v1::JobState state) {
  std::string name = v1::JobState_Name(state);
  if (absl::StartsWith(name, "JOB_STATE_")) name = name.substr(10);
  return absl::AsciiStrToLower(name);
}

ObjectInfo FromProto(const v1::Object& o) {
  ObjectInfo info;
  info.scene = o.scene();
  info.id = o.id();
  info.source = o.source();
  info.units = o.units();
  info.meters_per_unit = o.meters_per_unit();
  info.world_from_object.translation = FromProto(o.world_from_object().translation());
  info.world_from_object.qx = o.world_from_object().qx();
  info.world_from_object.qy = o.world_from_object().qy();
  info.world_from_object.qz = o.world_from_object().qz();
  info.world_from_object.qw = o.world_from_object().qw();
  info.extent = FromProto(o.extent());
  info.completion = o.completion();
  info.completed_share = o.completed_share();
  info.gaussians = o.gaussians();
  info.manifest_json = o.manifest_json();
  for (const v1::Artefact& a : o.artefacts())
    info.artefacts.push_back(
        {a.path(), a.digest().hash(), a.digest().size_bytes(), a.media_type()});
  info.query_microseconds = o.query_microseconds();
  info.index_loaded = o.index_loaded();
  return info;
}

}  // namespace

Client::Client(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
Client::~Client() = default;
const ClientOptions& Client::options() const { return impl_->options; }

absl::StatusOr<std::unique_ptr<Client>> Client::Connect(const ClientOptions& options) {
  if (options.server.empty()) return absl::InvalidArgumentError("no server address");
  if (options.max_attempts < 1 || options.max_attempts > 100)
    return absl::InvalidArgumentError("max_attempts must be in [1, 100]");
  if (options.deadline.count() <= 0) return absl::InvalidArgumentError("deadline must be > 0");
  auto impl = std::make_unique<Impl>();
  impl->options = options;
  rpc::ChannelOptions channel;
  channel.token = options.token;
  channel.tls_ca_file = options.tls_ca_file;
  channel.tls_cert_file = options.tls_cert_file;
  channel.tls_key_file = options.tls_key_file;
  channel.tls_server_name = options.tls_server_name;
  ASSIGN_OR_RETURN(impl->channel, rpc::Connect(options.server, channel));
  impl->store_channel = impl->channel;
  if (!options.store.empty()) {
    ASSIGN_OR_RETURN(impl->store_channel, rpc::Connect(options.store, channel));
  }
  impl->objects_channel = impl->channel;
  if (!options.objects.empty()) {
    ASSIGN_OR_RETURN(impl->objects_channel, rpc::Connect(options.objects, channel));
  }
  impl->scheduler = v1::Scheduler::NewStub(impl->channel);
  impl->objects = v1::Objects::NewStub(impl->objects_channel);
  return std::unique_ptr<Client>(new Client(std::move(impl)));
}

v1::Scheduler::Stub& SchedulerStub(Client& client) { return *client.impl().scheduler; }
v1::Objects::Stub& ObjectsStub(Client& client) { return *client.impl().objects; }

absl::Status Call(Client& client, const std::string& service,
                  const std::function<grpc::Status(grpc::ClientContext*)>& call) {
  const ClientOptions& o = client.options();
  auto backoff = o.initial_backoff;
  grpc::Status status;
  for (int attempt = 0; attempt < o.max_attempts; ++attempt) {
    if (attempt > 0) {
      std::this_thread::sleep_for(backoff);
      backoff *= 2;
    }
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() + o.deadline);
    status = call(&context);
    if (status.error_code() != grpc::StatusCode::UNAVAILABLE) break;
  }
  return StatusOf(client, service, status);
}

absl::Status StatusOf(Client& client, const std::string& service, const grpc::Status& status) {
  if (status.error_code() == grpc::StatusCode::UNAVAILABLE ||
      status.error_code() == grpc::StatusCode::DEADLINE_EXCEEDED)
    return absl::UnavailableError(absl::StrCat(service, " ", client.impl().Address(service),
                                               " unreachable: ", status.error_message(),
                                               " (is `instascene serve` running?)"));
  return rpc::FromGrpcStatus(status);
}

absl::StatusOr<std::vector<ObjectInfo>> Client::ListObjects(const std::string& scene) {
  std::vector<ObjectInfo> out;
  std::string token;
  do {
    v1::ListObjectsRequest request;
    request.set_scene(scene);
    request.set_limit(1000);
    request.set_page_token(token);
    v1::ListObjectsResponse page;
    RETURN_IF_ERROR(Call(*this, "objects", [&](grpc::ClientContext* c) {
      return impl_->objects->ListObjects(c, request, &page);
    }));
    for (const v1::Object& o : page.objects()) out.push_back(FromProto(o));
    token = page.next_page_token();
  } while (!token.empty());
  return out;
}

absl::StatusOr<ObjectInfo> Client::GetObject(const std::string& scene,
                                             const ObjectSelector& selector) {
  v1::GetObjectRequest request;
  request.set_scene(scene);
  ToProto(selector, request.mutable_selector());
  v1::Object answer;
  RETURN_IF_ERROR(Call(*this, "objects", [&](grpc::ClientContext* c) {
    return impl_->objects->GetObject(c, request, &answer);
  }));
  return FromProto(answer);
}

absl::StatusOr<Transfer> Client::DownloadObject(const ObjectInfo& object, const std::string& dir) {
  ASSIGN_OR_RETURN(store::BlobStore * blobs, impl_->Store());
  Transfer t;
  for (const Artefact& a : object.artefacts) {
    // Paths come from the server: only safe relative ones are written.
    RETURN_IF_ERROR(store::ValidateRelativePath(a.path));
    const store::Digest digest{a.sha256, a.bytes};
    const fs::path target = fs::path(dir) / a.path;
    std::error_code ec;
    fs::create_directories(target.parent_path(), ec);
    if (ec)
      return absl::UnavailableError(
          absl::StrCat(target.parent_path().string(), ": ", ec.message()));
    RETURN_IF_ERROR(blobs->GetFile(digest, target.string()));
    t.files += 1;
    t.bytes += a.bytes;
    t.paths.push_back(target.string());
  }
  return t;
}

absl::StatusOr<SubmitResult> Client::Submit(const SubmitRequest& r,
                                            const ProgressCallback& upload_progress) {
  ASSIGN_OR_RETURN(store::Manifest manifest, store::SceneManifestFromDirectory(r.scene_dir));
  ASSIGN_OR_RETURN(store::BlobStore * blobs, impl_->Store());
  ASSIGN_OR_RETURN(store::UploadReport upload,
                   store::UploadManifest(*blobs, manifest, r.scene_dir, upload_progress));
  v1::SubmitPipelineRequest request;
  rpc::ToProto(upload.manifest, request.mutable_scene_manifest());
  SubmitResult result;
  result.scene =
      r.name.empty() ? fs::path(r.scene_dir).lexically_normal().filename().string() : r.name;
  if (result.scene.empty())  // "dir/" normalises to an empty filename
    result.scene = fs::path(r.scene_dir).lexically_normal().parent_path().filename().string();
  request.set_scene(result.scene);
  request.set_parameters_json(r.parameters_json);
  request.set_priority(r.priority);
  for (const std::string& stage : r.stages) request.add_stages(stage);
  v1::SubmitPipelineResponse response;
  // Submission is idempotent (same scene, parameters and stages: the same jobs), so retrying is
  // safe.
  RETURN_IF_ERROR(Call(*this, "scheduler", [&](grpc::ClientContext* c) {
    return impl_->scheduler->SubmitPipeline(c, request, &response);
  }));
  result.scene_manifest = upload.manifest.ToString();
  result.files_sent = upload.files_sent;
  result.bytes_sent = upload.bytes_sent;
  result.files_skipped = upload.files_skipped;
  for (int i = 0; i < response.jobs_size(); ++i) {
    const v1::Job& j = response.jobs(i);
    result.jobs.push_back(
        {j.id(), j.kind(), "", j.item(), i < response.created_size() && response.created(i)});
    result.jobs.back().state = StateName(j.state());
  }
  return result;
}

absl::StatusOr<std::vector<StageOutput>> Client::SceneOutputs(const std::string& scene) {
  v1::GetSceneRequest request;
  request.set_scene(scene);
  v1::Scene answer;
  RETURN_IF_ERROR(Call(*this, "scheduler", [&](grpc::ClientContext* c) {
    return impl_->scheduler->GetScene(c, request, &answer);
  }));
  std::vector<StageOutput> out;
  for (const v1::StageOutput& o : answer.outputs())
    out.push_back({o.kind(), o.item(), o.job_id(), o.output_manifest().hash(),
                   o.output_manifest().size_bytes()});
  return out;
}

absl::StatusOr<Transfer> Client::FetchOutput(const StageOutput& output, const std::string& dir) {
  ASSIGN_OR_RETURN(store::BlobStore * blobs, impl_->Store());
  const store::Digest digest{output.manifest_sha256, output.manifest_bytes};
  ASSIGN_OR_RETURN(store::Manifest manifest, store::ReadManifest(*blobs, digest));
  RETURN_IF_ERROR(store::MaterializeManifest(*blobs, manifest, dir));
  Transfer t;
  t.files = static_cast<int64_t>(manifest.files.size());
  t.bytes = manifest.TotalBytes();
  for (const auto& [path, d] : manifest.files) t.paths.push_back((fs::path(dir) / path).string());
  return t;
}

}  // namespace instascene::client
