#include "common/store/s3_location.h"

#include <openssl/hmac.h>

#include <cstdlib>
#include <fstream>

#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "common/core/status.h"
#include "common/store/digest.h"

namespace instascene::store {
namespace {

bool IsUnreserved(char c) {
  return absl::ascii_isalnum(static_cast<unsigned char>(c)) || c == '-' || c == '_' || c == '.' ||
         c == '~';
}

absl::Status ValidateBucket(absl::string_view b) {
  bool ok = b.size() >= 3 && b.size() <= 63;
  for (char c : b)
    ok = ok && (absl::ascii_islower(static_cast<unsigned char>(c)) ||
                absl::ascii_isdigit(static_cast<unsigned char>(c)) || c == '.' || c == '-');
  ok = ok && absl::ascii_isalnum(static_cast<unsigned char>(b.front())) &&
       absl::ascii_isalnum(static_cast<unsigned char>(b.back()));
  if (!ok)
    return absl::InvalidArgumentError(
        absl::StrCat("s3 URI: bucket '", b.substr(0, 80),
                     "' is not a valid bucket name (3-63 characters: a-z 0-9 . -)"));
  return absl::OkStatus();
}

absl::Status ValidatePrefix(absl::string_view p) {
  if (p.size() > 512) return absl::InvalidArgumentError("s3 URI: prefix longer than 512 bytes");
  for (char c : p)
    if (!IsUnreserved(c) && c != '/')
      return absl::InvalidArgumentError(absl::StrCat("s3 URI: prefix '", p.substr(0, 80),
                                                     "' may only hold A-Z a-z 0-9 - _ . ~ and /"));
  for (absl::string_view segment : absl::StrSplit(p, '/'))
    if (segment.empty() || segment == "." || segment == "..")
      return absl::InvalidArgumentError(
          absl::StrCat("s3 URI: prefix '", p.substr(0, 80), "' has an empty, . or .. segment"));
  return absl::OkStatus();
}

std::string Trim(absl::string_view s) { return std::string(absl::StripAsciiWhitespace(s)); }

std::string Hmac(absl::string_view key, absl::string_view data) {
  unsigned char out[EVP_MAX_MD_SIZE];
  unsigned int len = 0;
  HMAC(EVP_sha256(), key.data(), static_cast<int>(key.size()),
       reinterpret_cast<const unsigned char*>(data.data()), data.size(), out, &len);
  return std::string(reinterpret_cast<char*>(out), len);
}

std::string Hex(absl::string_view bytes) {
  static constexpr char kHex[] = "0123456789abcdef";
  std::string out;
  for (char c : bytes) {
    out += kHex[static_cast<unsigned char>(c) >> 4];
    out += kHex[static_cast<unsigned char>(c) & 15];
  }
  return out;
}

}  // namespace

std::string SignS3RequestV4(const std::string& method, const std::string& canonical_uri,
                            const std::string& canonical_query,
                            const std::map<std::string, std::string>& headers,
                            const std::string& region, const S3Credentials& credentials) {
  std::string canonical_headers, signed_headers;
  for (const auto& [name, value] : headers) {  // std::map: sorted by name
    absl::StrAppend(&canonical_headers, name, ":", value, "\n");
    absl::StrAppend(&signed_headers, signed_headers.empty() ? "" : ";", name);
  }
  const std::string amz_date = headers.at("x-amz-date");
  const std::string date = amz_date.substr(0, 8);
  const std::string canonical_request =
      absl::StrCat(method, "\n", canonical_uri, "\n", canonical_query, "\n", canonical_headers,
                   "\n", signed_headers, "\n", headers.at("x-amz-content-sha256"));
  const std::string scope = absl::StrCat(date, "/", region, "/s3/aws4_request");
  const std::string to_sign = absl::StrCat("AWS4-HMAC-SHA256\n", amz_date, "\n", scope, "\n",
                                           ComputeDigest(canonical_request).hash);
  std::string key = Hmac(absl::StrCat("AWS4", credentials.secret_access_key), date);
  key = Hmac(key, region);
  key = Hmac(key, "s3");
  key = Hmac(key, "aws4_request");
  return absl::StrCat("AWS4-HMAC-SHA256 Credential=", credentials.access_key_id, "/", scope,
                      ", SignedHeaders=", signed_headers, ", Signature=", Hex(Hmac(key, to_sign)));
}

std::string AwsUriEncode(absl::string_view text, bool keep_slash) {
  static constexpr char kHex[] = "0123456789ABCDEF";
  std::string out;
  for (char c : text) {
    if (IsUnreserved(c) || (keep_slash && c == '/')) {
      out += c;
    } else {
      const auto u = static_cast<unsigned char>(c);
      out += '%';
      out += kHex[u >> 4];
      out += kHex[u & 15];
    }
  }
  return out;
}

namespace {

// The URI's query parameters (endpoint, region, addressing, query_slash) into `loc`; addressing
// as given (checked by the caller).
absl::Status ApplyQuery(absl::string_view query, S3Location* loc, std::string* addressing) {
  for (absl::string_view kv : absl::StrSplit(query, '&', absl::SkipEmpty())) {
    const size_t eq = kv.find('=');
    const absl::string_view key = kv.substr(0, eq);
    const std::string value =
        eq == absl::string_view::npos ? std::string() : std::string(kv.substr(eq + 1));
    if (key == "endpoint") {
      loc->endpoint = std::string(absl::StripSuffix(value, "/"));
    } else if (key == "region") {
      loc->region = value;
    } else if (key == "addressing") {
      *addressing = value;
    } else if (key == "query_slash") {
      if (value != "literal" && value != "encoded")
        return absl::InvalidArgumentError("s3 URI: query_slash must be literal or encoded");
      loc->query_slash_literal = value == "literal";
    } else {
      return absl::InvalidArgumentError(
          absl::StrCat("s3 URI: unknown parameter '", key.substr(0, 40),
                       "' (known: endpoint, region, addressing, query_slash)"));
    }
  }
  return absl::OkStatus();
}

// A region name: 1-64 lower-case letters, digits and dashes.
absl::Status ValidateRegion(const std::string& region) {
  if (region.empty() || region.size() > 64 ||
      !std::all_of(region.begin(), region.end(), [](char c) {
        return absl::ascii_islower(static_cast<unsigned char>(c)) ||
               absl::ascii_isdigit(static_cast<unsigned char>(c)) || c == '-';
      }))
    return absl::InvalidArgumentError(
        absl::StrCat("s3 URI: region '", region.substr(0, 40), "' is not a region name"));
  return absl::OkStatus();
}

}  // namespace

absl::StatusOr<S3Location> S3Location::Parse(absl::string_view uri) {
  if (!absl::StartsWith(uri, "s3://"))
    return absl::InvalidArgumentError(absl::StrCat(
        "expected s3://BUCKET[/PREFIX][?endpoint=...&region=...], not '", uri.substr(0, 80), "'"));
  absl::string_view rest = uri.substr(5);
  absl::string_view query;
  if (const size_t q = rest.find('?'); q != absl::string_view::npos) {
    query = rest.substr(q + 1);
    rest = rest.substr(0, q);
  }
  S3Location loc;
  const size_t slash = rest.find('/');
  loc.bucket = std::string(rest.substr(0, slash));
  RETURN_IF_ERROR(ValidateBucket(loc.bucket));
  if (slash != absl::string_view::npos) {
    absl::string_view prefix = absl::StripSuffix(rest.substr(slash + 1), "/");
    if (!prefix.empty()) {
      RETURN_IF_ERROR(ValidatePrefix(prefix));
      loc.prefix = absl::StrCat(prefix, "/");
    }
  }
  std::string addressing;
  RETURN_IF_ERROR(ApplyQuery(query, &loc, &addressing));
  RETURN_IF_ERROR(ValidateRegion(loc.region));
  const bool aws = loc.endpoint.empty();
  if (aws) loc.endpoint = absl::StrCat("https://s3.", loc.region, ".amazonaws.com");
  const size_t scheme = loc.endpoint.find("://");
  if (!(absl::StartsWith(loc.endpoint, "http://") || absl::StartsWith(loc.endpoint, "https://")) ||
      loc.endpoint.find('/', scheme + 3) != std::string::npos || loc.endpoint.size() == scheme + 3)
    return absl::InvalidArgumentError(absl::StrCat("s3 URI: endpoint '", loc.endpoint.substr(0, 80),
                                                   "' must be http(s)://HOST[:PORT]"));
  if (addressing.empty()) {
    loc.path_style = !aws;
  } else if (addressing == "path" || addressing == "virtual") {
    loc.path_style = addressing == "path";
  } else {
    return absl::InvalidArgumentError("s3 URI: addressing must be path or virtual");
  }
  return loc;
}

std::string S3Location::ToString() const {
  return absl::StrCat("s3://", bucket, "/", prefix, "?endpoint=", endpoint, "&region=", region,
                      "&addressing=", path_style ? "path" : "virtual",
                      query_slash_literal ? "&query_slash=literal" : "");
}

std::string S3Location::Url(absl::string_view key) const {
  const std::string path = key.empty() ? "" : AwsUriEncode(key, true);
  if (path_style) return absl::StrCat(endpoint, "/", bucket, key.empty() ? "" : "/", path);
  const size_t scheme = endpoint.find("://") + 3;
  return absl::StrCat(endpoint.substr(0, scheme), bucket, ".", endpoint.substr(scheme), "/", path);
}

absl::StatusOr<S3Credentials> S3Credentials::FromFile(const std::string& path,
                                                      const std::string& profile) {
  std::ifstream in(path);
  if (!in)
    return absl::FailedPreconditionError(
        absl::StrCat("S3 credentials file ", path, " cannot be read"));
  S3Credentials c;
  std::string line, section;
  bool found = false;
  while (std::getline(in, line)) {
    const std::string t = Trim(line);
    if (t.empty() || t[0] == '#' || t[0] == ';') continue;
    if (t.front() == '[' && t.back() == ']') {
      section = Trim(absl::StripPrefix(absl::string_view(t).substr(1, t.size() - 2), "profile "));
      found = found || section == profile;
      continue;
    }
    if (section != profile) continue;
    const size_t eq = t.find('=');
    if (eq == std::string::npos) continue;
    const std::string key = absl::AsciiStrToLower(Trim(t.substr(0, eq)));
    const std::string value = Trim(t.substr(eq + 1));
    if (key == "aws_access_key_id") c.access_key_id = value;
    if (key == "aws_secret_access_key") c.secret_access_key = value;
    if (key == "aws_session_token") c.session_token = value;
  }
  if (!found)
    return absl::FailedPreconditionError(
        absl::StrCat("S3 credentials file ", path, " has no profile [", profile, "]"));
  if (c.access_key_id.empty() || c.secret_access_key.empty())
    return absl::FailedPreconditionError(
        absl::StrCat("S3 credentials file ", path, ", profile [", profile,
                     "]: aws_access_key_id and aws_secret_access_key are both required"));
  return c;
}

absl::StatusOr<S3Credentials> S3Credentials::Load() {
  const char* id = std::getenv("AWS_ACCESS_KEY_ID");
  const char* secret = std::getenv("AWS_SECRET_ACCESS_KEY");
  if ((id != nullptr && *id != 0) || (secret != nullptr && *secret != 0)) {
    if (id == nullptr || *id == 0 || secret == nullptr || *secret == 0)
      return absl::FailedPreconditionError(
          "S3 credentials: AWS_ACCESS_KEY_ID and AWS_SECRET_ACCESS_KEY must be set together");
    S3Credentials c{id, secret, ""};
    if (const char* token = std::getenv("AWS_SESSION_TOKEN")) c.session_token = token;
    return c;
  }
  std::string path;
  if (const char* file = std::getenv("AWS_SHARED_CREDENTIALS_FILE"); file != nullptr && *file)
    path = file;
  else if (const char* home = std::getenv("HOME"); home != nullptr && *home)
    path = absl::StrCat(home, "/.aws/credentials");
  const char* profile = std::getenv("AWS_PROFILE");
  if (path.empty() || !std::ifstream(path))
    return absl::FailedPreconditionError(
        "no S3 credentials: set AWS_ACCESS_KEY_ID and AWS_SECRET_ACCESS_KEY, or write them to "
        "the shared credentials file (AWS_SHARED_CREDENTIALS_FILE or ~/.aws/credentials)");
  return FromFile(path, profile != nullptr && *profile ? profile : "default");
}

}  // namespace instascene::store
