// services/store/tenant_quota.h: the store service's bound on the bytes granted to one tenant
// (StoreOptions::tenant_quota_bytes, `--tenant-quota-bytes`): its uploads and its jobs' outputs.
// A tenant's usage is read from the store's grants (BlobStore::TenantBytes) at most once per
// `refresh` and raised by every blob admitted since (once per blob: a resumed upload is not
// counted twice; a blob the tenant held already may count again until the next read, which only
// matters near the quota, where it is checked), so a scene's hundreds of uploads cost one listing.
// Outputs the scheduler grants count from the next read. Several store replicas each add their own
// admissions between reads: across replicas the bound can be passed by what they admit in one
// interval. Thread-safe.
#pragma once

#include <chrono>
#include <functional>
#include <map>
#include <mutex>
#include <set>
#include <string>

#include "absl/status/status.h"
#include "common/store/blob_store.h"

namespace instascene::store_service {

class TenantQuota {
 public:
  explicit TenantQuota(store::BlobStore* store,
                       std::chrono::seconds refresh = std::chrono::seconds(30))
      : store_(store), refresh_(refresh) {}

  // OK when `tenant` may upload `digest`, which then counts; ResourceExhausted naming the tenant,
  // its usage, the blob and the quota when it would pass the quota and `holds` (asked only then,
  // so the common upload pays no extra store call) says the tenant does not hold the blob
  // already. OK for every blob when the quota is 0.
  absl::Status Admit(const std::string& tenant, const store::Digest& digest,
                     const std::function<absl::StatusOr<bool>()>& holds);

 private:
  struct Usage {
    int64_t bytes = 0;
    std::chrono::steady_clock::time_point read;
    std::set<std::string> admitted;  // hashes counted since the read
  };

  store::BlobStore* store_;  // not owned
  const std::chrono::seconds refresh_;
  std::mutex mutex_;
  std::map<std::string, Usage> usage_;
};

}  // namespace instascene::store_service
