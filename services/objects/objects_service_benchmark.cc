// The Objects service as a robot or a viewer meets it: GetObject over loopback gRPC against an
// `instascene serve`-like server (the Objects service resolving the scene through the scheduler's
// GetScene over the in-process channel, as the embedded default does), on the `medium` synthetic
// scene (300k Gaussians, 100 views at 640x480, 20 objects) with its ground truth as the stored
// segmentation. Reports per-query latency percentiles with the index loaded (every view's label
// map rendered; clicks at object pixels, 3D points on objects), and the first query after a cold
// start (scene and labels read from the store, the point index built; label maps are rendered in
// the background afterwards, or by the first click in a view).
#include <benchmark/benchmark.h>

#include <algorithm>
#include <random>

#include "common/core/testing/temp_dir.h"
#include "common/core/timer.h"
#include "common/eval/result.h"
#include "common/rpc/server.h"
#include "common/rpc/status.h"
#include "common/scene/image_io.h"
#include "common/store/manifest.h"
#include "common/synth/scene_writer.h"
#include "instascene/v1/scheduler.grpc.pb.h"
#include "services/objects/objects_service.h"

namespace instascene::objects {
namespace {

// The scheduler's GetScene for one scene (the rest of the scheduler plays no part in a query).
class OneSceneScheduler final : public v1::Scheduler::Service {
 public:
  explicit OneSceneScheduler(v1::Scene scene) : scene_(std::move(scene)) {}
  grpc::Status GetScene(grpc::ServerContext*, const v1::GetSceneRequest* request,
                        v1::Scene* response) override {
    if (request->scene() != scene_.name())
      return grpc::Status(grpc::StatusCode::NOT_FOUND, "no such scene");
    *response = scene_;
    return grpc::Status::OK;
  }

 private:
  v1::Scene scene_;
};

struct Fixture {
  instascene::testing::ScopedTempDir temp{"objects_bench"};
  std::unique_ptr<store::FilesystemBlobStore> store;
  ClutterScene truth;
  v1::Scene scene;
  std::vector<v1::ObjectSelector> clicks, points;
  std::vector<std::string> views;

  Fixture() {
    store = std::move(*store::FilesystemBlobStore::Open(temp.Sub("store"), {}));
    truth = std::move(*GenerateClutterScene(*ClutterPreset("medium")));
    const std::string dir = temp.Sub("scene");
    if (!WriteClutterScene(truth, dir, SceneWriteOptions{}).ok()) std::abort();
    auto up = store::UploadManifest(*store, *store::SceneManifestFromDirectory(dir), dir);
    SegmentationResult gt = *ReadResult(dir + "/gt", truth.cloud.size());
    const std::string seg = temp.Sub("segment");
    if (!up.ok() || !WriteResult(seg, gt, truth.cloud).ok()) std::abort();
    auto seg_up = store::UploadManifest(*store, *store::ManifestFromDirectory(seg, "segment"), seg);
    scene.set_name("medium");
    v1::StageOutput* o = scene.add_outputs();
    o->set_kind("segment");
    o->set_item(-1);
    rpc::ToProto(seg_up->manifest, o->mutable_output_manifest());
    rpc::ToProto(up->manifest, o->mutable_scene_manifest());
    // Queries: clicks at object pixels of the ground-truth masks, points on object surfels.
    std::mt19937 rng(7);
    Scene s = *ReadScene(dir);
    for (const SceneView& v : s.views) views.push_back(v.name);
    for (int i = 0; clicks.size() < 1000 && i < 100000; ++i) {
      const int v = static_cast<int>(rng() % s.views.size());
      const LabelMap mask = *ReadLabelMap(dir + "/gt/masks/" + s.views[v].name + ".png");
      for (int k = 0; k < 50; ++k) {
        const size_t p = rng() % mask.labels.size();
        if (mask.labels[p] == 0) continue;
        v1::ObjectSelector c;
        c.mutable_click()->set_view(s.views[v].name);
        c.mutable_click()->set_x(static_cast<int>(p % mask.width));
        c.mutable_click()->set_y(static_cast<int>(p / mask.width));
        clicks.push_back(c);
      }
    }
    for (int i = 0; i < 1000; ++i) {
      const SynthObject& so = truth.objects[rng() % truth.objects.size()];
      const size_t g = so.first_gaussian + rng() % so.num_gaussians;
      v1::ObjectSelector p;
      p.mutable_point()->set_x(truth.cloud.positions[3 * g] + 0.003);
      p.mutable_point()->set_y(truth.cloud.positions[3 * g + 1]);
      p.mutable_point()->set_z(truth.cloud.positions[3 * g + 2]);
      points.push_back(p);
    }
  }
};

// Built on first use, destroyed by main (its temporary folder with it) after the benchmarks.
std::unique_ptr<Fixture>& SharedSlot() {
  static std::unique_ptr<Fixture> f;
  return f;
}

Fixture& Shared() {
  if (!SharedSlot()) SharedSlot() = std::make_unique<Fixture>();
  return *SharedSlot();
}

// A server like the embedded default's: scheduler + Objects service, queried over loopback TCP.
struct Serving {
  OneSceneScheduler scheduler;
  std::unique_ptr<ObjectsService> objects;
  std::unique_ptr<rpc::Server> server;
  std::unique_ptr<v1::Objects::Stub> stub;
  std::shared_ptr<grpc::Channel> in_process;
  std::mutex mutex;

  explicit Serving(Fixture& f) : scheduler(f.scene) {
    objects = std::make_unique<ObjectsService>(
        f.store.get(), [this](const std::string& name) -> absl::StatusOr<v1::Scene> {
          std::shared_ptr<grpc::Channel> channel;
          {
            std::lock_guard<std::mutex> lock(mutex);
            channel = in_process;
          }
          v1::GetSceneRequest request;
          request.set_scene(name);
          v1::Scene answer;
          grpc::ClientContext context;
          const grpc::Status s =
              v1::Scheduler::NewStub(channel)->GetScene(&context, request, &answer);
          if (!s.ok()) return rpc::FromGrpcStatus(s);
          return answer;
        });
    server = std::move(*rpc::Server::Start({"127.0.0.1:0"}, {&scheduler, objects.get()},
                                           {"instascene.v1.Scheduler", "instascene.v1.Objects"}));
    {
      std::lock_guard<std::mutex> lock(mutex);
      in_process = server->InProcessChannel();
    }
    stub = v1::Objects::NewStub(rpc::Connect(server->address()));
  }
  ~Serving() { server->Drain(std::chrono::milliseconds(100)); }

  bool Query(const v1::ObjectSelector& selector) {
    v1::GetObjectRequest request;
    request.set_scene("medium");
    *request.mutable_selector() = selector;
    v1::Object answer;
    grpc::ClientContext context;
    return stub->GetObject(&context, request, &answer).ok();
  }
};

void Percentiles(benchmark::State& state, std::vector<double> ms) {
  std::sort(ms.begin(), ms.end());
  auto at = [&](double q) {
    return ms[std::min(ms.size() - 1, static_cast<size_t>(q * ms.size()))];
  };
  state.counters["p50_ms"] = at(0.50);
  state.counters["p99_ms"] = at(0.99);
  state.counters["max_ms"] = ms.back();
}

void Warm(benchmark::State& state, const std::vector<v1::ObjectSelector>& queries) {
  Fixture& f = Shared();
  Serving serving(f);
  // The index fully loaded: a click in every view waits for (or renders) its label map.
  for (const std::string& view : f.views) {
    v1::ObjectSelector click;
    click.mutable_click()->set_view(view);
    serving.Query(click);
  }
  std::vector<double> ms;
  size_t i = 0, found = 0;
  for (auto _ : state) {
    Stopwatch watch;
    found += serving.Query(queries[i++ % queries.size()]);
    ms.push_back(watch.ElapsedMs());
  }
  Percentiles(state, ms);
  state.counters["found_share"] = static_cast<double>(found) / static_cast<double>(ms.size());
}

void BM_ClickQueryIndexLoaded(benchmark::State& state) { Warm(state, Shared().clicks); }
BENCHMARK(BM_ClickQueryIndexLoaded)->Iterations(2000)->Unit(benchmark::kMicrosecond);

void BM_PointQueryIndexLoaded(benchmark::State& state) { Warm(state, Shared().points); }
BENCHMARK(BM_PointQueryIndexLoaded)->Iterations(2000)->Unit(benchmark::kMicrosecond);

// The first query of a fresh server (by id): the index is loaded before it is answered.
void BM_FirstQueryAfterColdStart(benchmark::State& state) {
  Fixture& f = Shared();
  for (auto _ : state) {
    state.PauseTiming();
    auto serving = std::make_unique<Serving>(f);
    state.ResumeTiming();
    v1::ObjectSelector id;
    id.set_id(1);
    if (!serving->Query(id)) state.SkipWithError("cold query failed");
    state.PauseTiming();
    serving.reset();
    state.ResumeTiming();
  }
}
BENCHMARK(BM_FirstQueryAfterColdStart)->Iterations(1)->Unit(benchmark::kMillisecond);

void RemoveShared() { SharedSlot().reset(); }

}  // namespace
}  // namespace instascene::objects

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  instascene::objects::RemoveShared();  // nothing left in the temporary folder
  return 0;
}
