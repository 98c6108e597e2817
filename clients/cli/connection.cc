#include "clients/cli/connection.h"

#include <cstdlib>
#include <filesystem>

#include "absl/strings/str_cat.h"
#include "common/auth/tokens.h"
#include "common/core/status.h"

namespace instascene::cli {

void AddConnectionFlags(CLI::App* command, ConnectionFlags* flags) {
  command->add_option("--token-file", flags->token_file,
                      "File holding the bearer token (default: $INSTASCENE_TOKEN, "
                      "$INSTASCENE_TOKEN_FILE, then instascene-data/auth/admin.token)");
  command->add_option(
      "--tls-ca", flags->tls_ca,
      "TLS: the CA (PEM) that signed the server's certificate (default: plaintext)");
  command->add_option("--tls-client-cert", flags->tls_cert,
                      "Mutual TLS: this client's certificate (PEM)");
  command->add_option("--tls-client-key", flags->tls_key, "Mutual TLS: this client's key (PEM)");
  command->add_option("--tls-server-name", flags->tls_server_name,
                      "TLS: the name the server's certificate carries, when not the host");
}

absl::StatusOr<client::ClientOptions> ClientOptionsFor(const ConnectionFlags& flags,
                                                       const std::string& server,
                                                       const std::string& store) {
  client::ClientOptions options;
  options.server = server;
  options.store = store;
  options.tls_ca_file = flags.tls_ca;
  options.tls_cert_file = flags.tls_cert;
  options.tls_key_file = flags.tls_key;
  options.tls_server_name = flags.tls_server_name;
  const char* env_token = std::getenv("INSTASCENE_TOKEN");
  const char* env_file = std::getenv("INSTASCENE_TOKEN_FILE");
  constexpr char kServeDefault[] = "instascene-data/auth/admin.token";
  std::string file;
  if (!flags.token_file.empty()) {
    file = flags.token_file;
  } else if (env_token != nullptr && *env_token != '\0') {
    std::string id, secret;
    if (absl::Status s = auth::SplitToken(env_token, &id, &secret); !s.ok())
      return absl::InvalidArgumentError(absl::StrCat("$INSTASCENE_TOKEN: ", s.message()));
    options.token = env_token;
  } else if (env_file != nullptr && *env_file != '\0') {
    file = env_file;
  } else if (std::error_code ec; std::filesystem::exists(kServeDefault, ec)) {
    file = kServeDefault;
  }
  if (!file.empty()) {
    ASSIGN_OR_RETURN(options.token, auth::ReadTokenFile(file));
  }
  return options;
}

absl::StatusOr<std::unique_ptr<client::Client>> ConnectClient(const ConnectionFlags& flags,
                                                              const std::string& server,
                                                              const std::string& store) {
  ASSIGN_OR_RETURN(client::ClientOptions options, ClientOptionsFor(flags, server, store));
  return client::Client::Connect(options);
}

}  // namespace instascene::cli
