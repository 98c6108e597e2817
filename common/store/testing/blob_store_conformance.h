// common/store/testing/blob_store_conformance.h: the behaviour every BlobStore backend must have
// (filesystem, remote over gRPC, S3), as one parameterised GoogleTest suite. A backend's test
// instantiates it with a factory of `BlobStoreBackend`s:
//   INSTANTIATE_TEST_SUITE_P(Filesystem, BlobStoreConformanceTest,
//                            ::testing::Values(BlobStoreBackendFactory{"filesystem", ...}),
//                            BackendName);
// and links the `instascene_blob_store_conformance` object library.
#pragma once

#include <gtest/gtest.h>

#include <functional>
#include <memory>
#include <string>

#include "absl/status/statusor.h"
#include "common/store/blob_store.h"

namespace instascene::store::testing {

// Fresh, empty storage for one test.
class BlobStoreBackend {
 public:
  virtual ~BlobStoreBackend() = default;
  // A store over this backend's storage. A second call models a restarted process: the test
  // destroys the previous store first, and the new one sees what the old one made durable.
  virtual absl::StatusOr<std::unique_ptr<BlobStore>> Open(const StoreOptions& options) = 0;
  // After a restart, an interrupted upload resumes at most this many bytes before the point the
  // client had reached (0: exactly there; S3: what was buffered below a part is resent).
  virtual int64_t resume_loss_bytes() const { return 0; }
  // Whether tenant-private uploads are offered (the store service's own backends: filesystem,
  // S3); grants are offered by every backend.
  virtual bool tenant_uploads() const { return true; }
};

// Makes a backend over fresh storage for each test (named for test names and output).
struct BlobStoreBackendFactory {
  std::string name;
  std::function<std::unique_ptr<BlobStoreBackend>()> make;
  friend void PrintTo(const BlobStoreBackendFactory& f, std::ostream* os) { *os << f.name; }
};

inline std::string BackendName(const ::testing::TestParamInfo<BlobStoreBackendFactory>& info) {
  return info.param.name;
}

class BlobStoreConformanceTest : public ::testing::TestWithParam<BlobStoreBackendFactory> {
 protected:
  void SetUp() override { backend_ = GetParam().make(); }
  std::unique_ptr<BlobStore> Open(const StoreOptions& options = {});

  std::unique_ptr<BlobStoreBackend> backend_;
};

}  // namespace instascene::store::testing
