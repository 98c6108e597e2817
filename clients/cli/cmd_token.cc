// `instascene token create | revoke | list`: the admin command for bearer tokens. It edits the
// token file a server checks calls against (default: the one `instascene serve --data DIR` uses,
// DIR/auth/tokens.json); servers pick up the change at their next call, without a restart.
#include <chrono>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <memory>

#include <nlohmann/json.hpp>

#include "clients/cli/cli.h"
#include "common/auth/tokens.h"
#include "common/core/status.h"

namespace instascene::cli {
namespace {

std::string TokenFilePath(const std::string& tokens, const std::string& data) {
  if (!tokens.empty()) return tokens;
  return (std::filesystem::path(data) / "auth" / "tokens.json").string();
}

std::string Time(int64_t unix_ms) {
  if (unix_ms == 0) return "-";
  const std::time_t t = static_cast<std::time_t>(unix_ms / 1000);
  std::tm tm{};
  gmtime_r(&t, &tm);
  char buffer[32];
  std::strftime(buffer, sizeof buffer, "%Y-%m-%dT%H:%M:%SZ", &tm);
  return buffer;
}

struct TokenArgs {
  std::string data = "instascene-data", tokens, role = "client", tenant, note, out, id;
  bool json = false;
};

absl::Status CreateTokenCommand(const TokenArgs& a) {
  ASSIGN_OR_RETURN(auth::Role role, auth::ParseRole(a.role));
  const std::string path = TokenFilePath(a.tokens, a.data);
  auth::TokenRecord record;
  ASSIGN_OR_RETURN(std::string secret, auth::CreateToken(path, role, a.tenant, a.note, &record));
  if (!a.out.empty()) {
    RETURN_IF_ERROR(auth::WriteTokenFile(a.out, secret));
    secret.clear();
  }
  if (a.json) {
    nlohmann::json out = {
        {"id", record.id}, {"role", auth::RoleName(record.role)}, {"tenant", record.tenant}};
    if (!secret.empty()) out["token"] = secret;
    if (!a.out.empty()) out["token_file"] = a.out;
    PrintJsonLine(out.dump());
  } else if (!secret.empty()) {
    std::printf("%s\n", secret.c_str());
    std::fprintf(stderr, "token %s (%s%s%s) created in %s; it is shown only this once\n",
                 record.id.c_str(), auth::RoleName(record.role),
                 record.tenant.empty() ? "" : ", tenant ", record.tenant.c_str(), path.c_str());
  } else {
    std::printf("token %s written to %s\n", record.id.c_str(), a.out.c_str());
  }
  return absl::OkStatus();
}

absl::Status RevokeTokenCommand(const TokenArgs& a) {
  const std::string path = TokenFilePath(a.tokens, a.data);
  RETURN_IF_ERROR(auth::RevokeToken(path, a.id));
  std::printf("token %s revoked in %s\n", a.id.c_str(), path.c_str());
  return absl::OkStatus();
}

absl::Status ListTokensCommand(const TokenArgs& a) {
  const std::string path = TokenFilePath(a.tokens, a.data);
  ASSIGN_OR_RETURN(auth::TokenFile file, auth::LoadTokenFile(path));
  std::printf("%-13s %-7s %-16s %-21s %-21s %s\n", "ID", "ROLE", "TENANT", "CREATED", "REVOKED",
              "NOTE");
  nlohmann::json all = nlohmann::json::array();
  for (const auth::TokenRecord& t : file.tokens) {
    std::printf("%-13s %-7s %-16s %-21s %-21s %s\n", t.id.c_str(), auth::RoleName(t.role),
                t.tenant.empty() ? "-" : t.tenant.c_str(), Time(t.created_unix_ms).c_str(),
                Time(t.revoked_unix_ms).c_str(), t.note.c_str());
    all.push_back({{"id", t.id},
                   {"role", auth::RoleName(t.role)},
                   {"tenant", t.tenant},
                   {"note", t.note},
                   {"created_unix_ms", t.created_unix_ms},
                   {"revoked", t.revoked_unix_ms != 0}});
  }
  if (a.json) PrintJsonLine(nlohmann::json{{"tokens", all}}.dump());
  return absl::OkStatus();
}

// Sets `cmd` to run `run` on the shared arguments.
void Runs(CLI::App* cmd, Action* action, std::shared_ptr<TokenArgs> args,
          absl::Status (*run)(const TokenArgs&)) {
  cmd->callback([args, action, run] { *action = [args, run] { return run(*args); }; });
}

}  // namespace

void AddTokenCommand(CLI::App& app, Action* action) {
  CLI::App* token = app.add_subcommand(
      "token", "Bearer tokens of a server's tenants (create, revoke, list); stored hashed");
  token->require_subcommand(1);
  auto args = std::make_shared<TokenArgs>();
  auto add_file_flags = [args](CLI::App* cmd) {
    cmd->add_option("--data", args->data, "The server's data directory (its DATA/auth/tokens.json)")
        ->capture_default_str();
    cmd->add_option("--tokens", args->tokens, "The token file itself (overrides --data)");
  };

  CLI::App* create = token->add_subcommand(
      "create", "Create a token and print it once (the file keeps only its SHA-256)");
  add_file_flags(create);
  create->add_option("--role", args->role, "client (one tenant's scenes), worker or admin")
      ->capture_default_str();
  create->add_option("--tenant", args->tenant,
                     "The tenant of a client token: 1-32 of a-z, 0-9 and '-'");
  create->add_option("--note", args->note, "Who or what holds it (shown by list)");
  create->add_option("--out", args->out,
                     "Write the token to this file (mode 0600) instead of printing it");
  create->add_flag("--json", args->json, "Print {\"id\", \"token\", ...} as one JSON line");
  Runs(create, action, args, CreateTokenCommand);

  CLI::App* revoke = token->add_subcommand("revoke", "Revoke a token by its id (see list)");
  add_file_flags(revoke);
  revoke->add_option("id", args->id, "The token's id (12 hex digits)")->required();
  Runs(revoke, action, args, RevokeTokenCommand);

  CLI::App* list = token->add_subcommand("list", "List the tokens (never their secrets)");
  add_file_flags(list);
  list->add_flag("--json", args->json, "Print {\"tokens\": [...]} as the last stdout line");
  Runs(list, action, args, ListTokensCommand);
}

}  // namespace instascene::cli
