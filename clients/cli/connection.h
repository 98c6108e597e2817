// clients/cli/connection.h: how the client commands (submit, watch, jobs, fetch, cancel, object,
// objects) authenticate and secure their connection. The token comes from, in this order:
// --token-file, $INSTASCENE_TOKEN, $INSTASCENE_TOKEN_FILE, and the admin token `instascene serve`
// writes on first start into ./instascene-data/auth/admin.token (its default data folder), so the
// embedded default needs no step on the machine that runs it.
#pragma once

#include <CLI/CLI.hpp>

#include <memory>
#include <string>

#include "absl/status/statusor.h"
#include "instascene/client/client.h"

namespace instascene::cli {

// The scheduler's address the client commands connect to by default (`instascene serve`'s).
inline constexpr char kDefaultServer[] = "127.0.0.1:50051";

struct ConnectionFlags {
  std::string token_file, tls_ca, tls_cert, tls_key, tls_server_name;
};

void AddConnectionFlags(CLI::App* command, ConnectionFlags* flags);
absl::StatusOr<client::ClientOptions> ClientOptionsFor(const ConnectionFlags& flags,
                                                       const std::string& server,
                                                       const std::string& store = "");

// Connects through the C++ client library (deadlines, retries while UNAVAILABLE).
absl::StatusOr<std::unique_ptr<client::Client>> ConnectClient(const ConnectionFlags& flags,
                                                              const std::string& server,
                                                              const std::string& store = "");

}  // namespace instascene::cli
