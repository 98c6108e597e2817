#include "services/worker/input_cache.h"

#include <algorithm>
#include <filesystem>

#include "absl/strings/str_cat.h"

namespace instascene::worker {
namespace fs = std::filesystem;

void TouchCacheEntry(const std::string& directory) {
  std::error_code ec;
  fs::last_write_time(directory, fs::file_time_type::clock::now(), ec);
}

absl::StatusOr<EvictionReport> EvictCache(const std::vector<std::string>& roots,
                                          int64_t budget_bytes, const std::set<std::string>& keep) {
  struct Entry {
    fs::file_time_type used;
    std::string path;
    int64_t bytes = 0;
  };
  std::vector<Entry> entries;
  EvictionReport report;
  std::set<std::string> keep_normal;
  for (const std::string& k : keep) keep_normal.insert(fs::path(k).lexically_normal().string());
  for (const std::string& root : roots) {
    std::error_code ec;
    if (!fs::is_directory(root, ec)) continue;
    for (const auto& dir : fs::directory_iterator(root, ec)) {
      if (!dir.is_directory(ec)) continue;
      Entry e{dir.last_write_time(ec), dir.path().lexically_normal().string(), 0};
      for (auto it = fs::recursive_directory_iterator(dir.path(), ec);
           it != fs::recursive_directory_iterator(); it.increment(ec)) {
        if (ec) break;
        if (it->is_regular_file(ec)) e.bytes += static_cast<int64_t>(it->file_size(ec));
      }
      report.bytes_before += e.bytes;
      entries.push_back(std::move(e));
    }
    if (ec) return absl::UnavailableError(absl::StrCat(root, ": ", ec.message()));
  }
  report.bytes_after = report.bytes_before;
  if (budget_bytes <= 0 || report.bytes_before <= budget_bytes) return report;
  std::sort(entries.begin(), entries.end(), [](const Entry& a, const Entry& b) {
    return a.used != b.used ? a.used < b.used : a.path < b.path;
  });
  for (const Entry& e : entries) {
    if (report.bytes_after <= budget_bytes) break;
    if (keep_normal.count(e.path)) continue;
    std::error_code ec;
    fs::remove_all(e.path, ec);
    if (ec) return absl::UnavailableError(absl::StrCat(e.path, ": cannot evict: ", ec.message()));
    report.bytes_after -= e.bytes;
    report.evicted.push_back(e.path);
  }
  return report;
}

}  // namespace instascene::worker
