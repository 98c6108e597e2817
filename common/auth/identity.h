// common/auth/identity.h: who a caller is (role and tenant), and how a tenant's scene names map to
// the names the scheduler stores. A client's scene "kitchen" is stored as "acme:kitchen" (its
// tenant, a colon, its name); clients never see the prefix, admins and workers see and use the
// stored names. Tenants cannot contain ':', so the mapping is unambiguous.
#pragma once

#include <string>

#include "absl/strings/string_view.h"
#include "common/auth/tokens.h"

namespace instascene::auth {

struct Identity {
  std::string token_id;  // the token's id ("" when authentication is off, or a process token)
  std::string tenant;    // "" = every tenant (worker, admin)
  Role role = Role::kAdmin;

  bool scoped() const { return !tenant.empty(); }  // limited to one tenant's scenes and blobs
  static Identity Unrestricted() { return Identity{}; }
};

// The stored name of a caller's scene ("" stays "": no scene given).
std::string StoredScene(const Identity& who, absl::string_view name);
// Whether the caller may see a stored scene, and the name it knows it by.
bool MaySee(const Identity& who, absl::string_view stored_scene);
std::string ShownScene(const Identity& who, absl::string_view stored_scene);
// The tenant a stored scene belongs to ("" for scenes admins submitted without a prefix).
std::string SceneTenant(absl::string_view stored_scene);

}  // namespace instascene::auth
