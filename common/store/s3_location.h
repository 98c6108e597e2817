// common/store/s3_location.h: where an S3 bucket is (`S3Location`:
// `s3://BUCKET[/PREFIX][?endpoint=URL&region=R&addressing=path|virtual]`), who may use it
// (`S3Credentials`: AWS_ACCESS_KEY_ID / AWS_SECRET_ACCESS_KEY / AWS_SESSION_TOKEN, else the shared
// credentials file; never from flags, never logged) and the SigV4 rules requests are addressed and
// signed by (`AwsUriEncode`, `SignS3RequestV4`). The client (s3_client.h) sends them. Stateless
// and thread-safe.
#pragma once

#include <map>
#include <string>

#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"

namespace instascene::store {

struct S3Location {
  std::string endpoint;  // scheme://host[:port], no trailing slash
  std::string bucket;
  std::string prefix;  // "" or "a/b/" (always ends with '/')
  std::string region = "us-east-1";
  bool path_style = true;  // endpoint/bucket/key; false: bucket.host/key (virtual-hosted)
  // '/' in query values (list prefixes) is sent and signed as %2F, as SigV4 specifies (AWS, MinIO,
  // Ceph RGW). `query_slash=literal` sends it unencoded, for servers that canonicalise it so
  // (moto, whose signature check rejects even AWS's own SDK on %2F).
  bool query_slash_literal = false;

  // Defaults: endpoint https://s3.REGION.amazonaws.com with virtual-hosted addressing; any other
  // endpoint (MinIO, Ceph RGW, a test server) path-style unless `addressing=virtual`.
  static absl::StatusOr<S3Location> Parse(absl::string_view uri);
  std::string ToString() const;  // the canonical s3:// form (holds no secret)
  // The URL of a key ("" = the bucket itself), without a query string.
  std::string Url(absl::string_view key) const;
};

struct S3Credentials {
  std::string access_key_id;
  std::string secret_access_key;
  std::string session_token;  // optional (temporary credentials)

  static absl::StatusOr<S3Credentials> Load();
  // Reads one profile of an AWS shared credentials file (INI).
  static absl::StatusOr<S3Credentials> FromFile(const std::string& path,
                                                const std::string& profile);
};

// The SigV4 Authorization header of an S3 request (own signer, OpenSSL HMAC): curl 7.88's signer
// sorts header names wrongly when one is a prefix of another (x-amz-copy-source and
// x-amz-copy-source-range; fixed in curl 8), so such requests are signed here. `headers` are
// lower-case names with trimmed values and must include host, x-amz-content-sha256, x-amz-date.
std::string SignS3RequestV4(const std::string& method, const std::string& canonical_uri,
                            const std::string& canonical_query,
                            const std::map<std::string, std::string>& headers,
                            const std::string& region, const S3Credentials& credentials);

// Percent-encodes per the SigV4 rules (unreserved characters kept; '/' kept when `keep_slash`).
std::string AwsUriEncode(absl::string_view text, bool keep_slash);

}  // namespace instascene::store
