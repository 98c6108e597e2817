#include "common/auth/identity.h"

#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"

namespace instascene::auth {

std::string StoredScene(const Identity& who, absl::string_view name) {
  if (!who.scoped() || name.empty()) return std::string(name);
  return absl::StrCat(who.tenant, ":", name);
}

bool MaySee(const Identity& who, absl::string_view stored_scene) {
  return !who.scoped() || absl::StartsWith(stored_scene, absl::StrCat(who.tenant, ":"));
}

std::string ShownScene(const Identity& who, absl::string_view stored_scene) {
  if (!who.scoped() || !MaySee(who, stored_scene)) return std::string(stored_scene);
  return std::string(stored_scene.substr(who.tenant.size() + 1));
}

std::string SceneTenant(absl::string_view stored_scene) {
  const size_t colon = stored_scene.find(':');
  if (colon == absl::string_view::npos) return "";
  const absl::string_view tenant = stored_scene.substr(0, colon);
  return ValidateTenant(tenant).ok() ? std::string(tenant) : "";
}

}  // namespace instascene::auth
