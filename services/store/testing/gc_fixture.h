// services/store/testing/gc_fixture.h: what the garbage collector's tests (filesystem and S3) set
// up alike: blobs and manifests in a store, and jobs of a SQLite queue that reach them.
#pragma once

#include <gtest/gtest.h>

#include <map>
#include <memory>
#include <string>

#include "common/core/testing/temp_dir.h"
#include "common/store/blob_store.h"
#include "common/store/manifest.h"
#include "services/scheduler/sqlite_queue_store.h"

namespace instascene::store_service::testing {

class GcFixture : public ::testing::Test {
 protected:
  virtual store::BlobStore& blobs() = 0;

  void OpenQueue() {
    auto queue = scheduler::OpenSqliteJobQueue((temp_.path() / "jobs.db").string(), {});
    ASSERT_TRUE(queue.ok()) << queue.status();
    queue_ = std::move(*queue);
  }
  store::Digest Blob(const std::string& bytes) {
    const store::Digest d = store::ComputeDigest(bytes);
    EXPECT_TRUE(blobs().Put(d, bytes).ok());
    return d;
  }
  // A manifest of `files` (name -> bytes), stored with its files.
  store::Digest StoredManifest(const std::string& kind,
                               const std::map<std::string, std::string>& files) {
    store::Manifest m;
    m.kind = kind;
    for (const auto& [name, bytes] : files) m.files[name] = Blob(bytes);
    return Blob(store::SerializeManifest(m));
  }
  // A job of scene `scene` that ran on the manifest `scene_manifest` and succeeded with `output`.
  void SucceededJob(const std::string& scene, const store::Digest& scene_manifest,
                    const store::Digest& output) {
    ASSERT_TRUE(queue_->Submit(Request(scene, scene_manifest)).ok());
    auto lease = queue_->LeaseNext({"decompose"}, "w");
    ASSERT_TRUE(lease.ok() && lease->has_value());
    ASSERT_TRUE(queue_->Complete((*lease)->job.id, (*lease)->token, output).ok());
  }
  static scheduler::SubmitRequest Request(const std::string& scene,
                                          const store::Digest& scene_manifest) {
    scheduler::SubmitRequest request;
    request.scene = scene;
    request.scene_manifest = scene_manifest;
    request.stages = {{"decompose", {{"p", 1}}, {}}};
    return request;
  }

  instascene::testing::ScopedTempDir temp_{"gc"};
  std::unique_ptr<scheduler::JobQueue> queue_;
};

}  // namespace instascene::store_service::testing
