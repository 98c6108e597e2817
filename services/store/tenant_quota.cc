#include "services/store/tenant_quota.h"

#include "absl/strings/str_cat.h"
#include "common/core/status.h"

namespace instascene::store_service {

absl::Status TenantQuota::Admit(const std::string& tenant, const store::Digest& digest,
                                const std::function<absl::StatusOr<bool>()>& holds) {
  const int64_t quota = store_->options().tenant_quota_bytes;
  if (quota == 0) return absl::OkStatus();
  int64_t held_bytes = 0;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    const auto now = std::chrono::steady_clock::now();
    auto it = usage_.find(tenant);
    if (it == usage_.end() || now - it->second.read > refresh_) {
      ASSIGN_OR_RETURN(const int64_t bytes, store_->TenantBytes(tenant));
      it = usage_.insert_or_assign(tenant, Usage{bytes, now, {}}).first;
    }
    Usage& usage = it->second;
    if (usage.admitted.count(digest.hash)) return absl::OkStatus();
    if (usage.bytes + digest.size_bytes <= quota) {
      usage.bytes += digest.size_bytes;
      usage.admitted.insert(digest.hash);
      return absl::OkStatus();
    }
    held_bytes = usage.bytes;
  }
  ASSIGN_OR_RETURN(const bool held, holds());  // outside the lock: a store call
  if (held) return absl::OkStatus();           // re-sending what it holds adds nothing
  return absl::ResourceExhaustedError(absl::StrCat(
      "tenant ", tenant, " holds ", held_bytes, " bytes; blob ", digest.ToString(),
      " would pass its quota of ", quota,
      " bytes (the store's --tenant-quota-bytes): delete scenes (`instascene delete`), and "
      "the store's garbage collection frees what no job reaches"));
}

}  // namespace instascene::store_service
