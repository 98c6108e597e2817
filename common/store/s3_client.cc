#include "common/store/s3_client.h"

#include <curl/curl.h>

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <ctime>
#include <pugixml.hpp>
#include <thread>

#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "common/core/status.h"
#include "common/store/digest.h"

namespace instascene::store {
namespace {

std::string Trim(absl::string_view s) { return std::string(absl::StripAsciiWhitespace(s)); }

size_t WriteBody(char* data, size_t size, size_t count, void* user) {
  static_cast<std::string*>(user)->append(data, size * count);
  return size * count;
}

size_t WriteHeader(char* data, size_t size, size_t count, void* user) {
  auto* headers = static_cast<std::map<std::string, std::string>*>(user);
  const absl::string_view line(data, size * count);
  if (absl::StartsWith(line, "HTTP/")) {
    headers->clear();  // a new response (after 100-continue)
  } else if (const size_t colon = line.find(':'); colon != absl::string_view::npos) {
    (*headers)[absl::AsciiStrToLower(Trim(line.substr(0, colon)))] = Trim(line.substr(colon + 1));
  }
  return size * count;
}

struct SlistFree {
  void operator()(curl_slist* list) const { curl_slist_free_all(list); }
};
using Slist = std::unique_ptr<curl_slist, SlistFree>;

void Append(Slist& list, const std::string& line) {
  curl_slist* grown = curl_slist_append(list.get(), line.c_str());
  if (grown != nullptr) {
    (void)list.release();
    list.reset(grown);
  }
}

std::string Describe(const S3Request& r, const S3Location& loc) {
  return absl::StrCat(r.method, " s3://", loc.bucket, "/", r.key);
}

// Whether curl 7.88 would sign these headers in the wrong order (a name that prefixes another).
bool CurlMisordersHeaders(const std::vector<std::string>& headers) {
  std::vector<std::string> names;
  for (const std::string& h : headers)
    names.push_back(absl::AsciiStrToLower(h.substr(0, h.find(':'))));
  for (const std::string& a : names)
    for (const std::string& b : names)
      if (a != b && absl::StartsWith(b, a)) return true;
  return false;
}

// SigV4's canonical query string: sorted by key, keys and values URI-encoded.
std::string CanonicalQuery(std::vector<std::pair<std::string, std::string>> query,
                           bool slash_literal) {
  std::sort(query.begin(), query.end());
  std::vector<std::string> params;
  for (const auto& [k, v] : query)
    params.push_back(absl::StrCat(AwsUriEncode(k, false), "=", AwsUriEncode(v, slash_literal)));
  return absl::StrJoin(params, "&");
}

// The request's header lines: its own, the payload's hash, the session token, a content type.
std::vector<std::string> RequestHeaders(const S3Request& r, const S3Credentials& credentials) {
  std::vector<std::string> lines = r.headers;
  lines.push_back(absl::StrCat("x-amz-content-sha256: ", ComputeDigest(r.body).hash));
  if (!credentials.session_token.empty())
    lines.push_back(absl::StrCat("x-amz-security-token: ", credentials.session_token));
  // Never curl's default form type for a body: servers may parse (and swallow) it as a form.
  if (r.method != "GET" && r.method != "HEAD" &&
      std::none_of(r.headers.begin(), r.headers.end(), [](const std::string& h) {
        return absl::StartsWithIgnoreCase(h, "content-type:");
      }))
    lines.push_back("Content-Type: application/octet-stream");
  return lines;
}

// Signs the request itself (x-amz-date and Authorization appended to `lines`), where curl would
// sign its headers in another order than it sends them.
void SignHeaders(const std::string& method, const std::string& url,
                 const std::string& canonical_query, const std::string& region,
                 const S3Credentials& credentials, std::vector<std::string>* out_lines) {
  std::vector<std::string>& lines = *out_lines;
  char amz_date[32];
  const std::time_t now = std::time(nullptr);
  std::tm utc{};
  gmtime_r(&now, &utc);
  std::strftime(amz_date, sizeof(amz_date), "%Y%m%dT%H%M%SZ", &utc);
  lines.push_back(absl::StrCat("x-amz-date: ", amz_date));
  std::map<std::string, std::string> signed_headers;
  for (const std::string& h : lines) {
    const size_t colon = h.find(':');
    signed_headers[absl::AsciiStrToLower(h.substr(0, colon))] = Trim(h.substr(colon + 1));
  }
  const size_t host_start = url.find("://") + 3;
  const size_t path_start = url.find('/', host_start);
  signed_headers["host"] = url.substr(host_start, path_start - host_start);
  const std::string path = url.substr(path_start, url.find('?') - path_start);
  lines.push_back(absl::StrCat(
      "Authorization: ",
      SignS3RequestV4(method, path, canonical_query, signed_headers, region, credentials)));
}

// The request's method on the handle; a body goes as "POST fields" under the real method, so
// that curl signs its hash. The handle refers to r.body until the request is performed.
void SetMethodAndBody(CURL* curl, const S3Request& r) {
  if (r.method == "HEAD") {
    curl_easy_setopt(curl, CURLOPT_NOBODY, 1L);
  } else if (r.method == "GET") {
    curl_easy_setopt(curl, CURLOPT_HTTPGET, 1L);
  } else {
    curl_easy_setopt(curl, CURLOPT_CUSTOMREQUEST, r.method.c_str());
    curl_easy_setopt(curl, CURLOPT_POSTFIELDSIZE_LARGE, static_cast<curl_off_t>(r.body.size()));
    curl_easy_setopt(curl, CURLOPT_POSTFIELDS, r.body.empty() ? "" : r.body.data());
  }
}

}  // namespace

S3Client::S3Client(S3Location location, S3Credentials credentials, S3ClientOptions options)
    : location_(std::move(location)),
      credentials_(std::move(credentials)),
      options_(std::move(options)) {
  static std::once_flag once;
  std::call_once(once, [] { curl_global_init(CURL_GLOBAL_DEFAULT); });
}

S3Client::~S3Client() {
  for (void* h : pool_) curl_easy_cleanup(static_cast<CURL*>(h));
}

void* S3Client::AcquireHandle() {
  {
    std::lock_guard<std::mutex> lock(pool_mutex_);
    if (!pool_.empty()) {
      void* h = pool_.back();
      pool_.pop_back();
      return h;
    }
  }
  return curl_easy_init();
}

void S3Client::ReleaseHandle(void* handle) {
  std::lock_guard<std::mutex> lock(pool_mutex_);
  pool_.push_back(handle);
}

absl::StatusOr<S3Response> S3Client::SendOnce(const S3Request& r) {
  CURL* curl = static_cast<CURL*>(AcquireHandle());
  if (curl == nullptr) return absl::ResourceExhaustedError("curl_easy_init failed");
  curl_easy_reset(curl);
  std::string url = location_.Url(r.key);
  // curl signs the query string exactly as sent, so it is sent in canonical form (s3_store_test
  // checks curl's signature against SignS3RequestV4 on a captured request).
  const std::string canonical_query = CanonicalQuery(r.query, location_.query_slash_literal);
  if (!canonical_query.empty()) absl::StrAppend(&url, "?", canonical_query);
  const std::string sigv4 = absl::StrCat("aws:amz:", location_.region, ":s3");
  std::vector<std::string> lines = RequestHeaders(r, credentials_);
  const bool own_signature = CurlMisordersHeaders(lines);
  if (own_signature)
    SignHeaders(r.method, url, canonical_query, location_.region, credentials_, &lines);
  Slist headers, resolve;
  for (const std::string& h : lines) Append(headers, h);
  for (const std::string& entry : options_.resolve) Append(resolve, entry);

  S3Response response;
  curl_easy_setopt(curl, CURLOPT_URL, url.c_str());
  curl_easy_setopt(curl, CURLOPT_NOSIGNAL, 1L);
  if (!own_signature) {
    curl_easy_setopt(curl, CURLOPT_AWS_SIGV4, sigv4.c_str());
    curl_easy_setopt(curl, CURLOPT_USERNAME, credentials_.access_key_id.c_str());
    curl_easy_setopt(curl, CURLOPT_PASSWORD, credentials_.secret_access_key.c_str());
  }
  curl_easy_setopt(curl, CURLOPT_HTTPHEADER, headers.get());
  if (resolve) curl_easy_setopt(curl, CURLOPT_RESOLVE, resolve.get());
  curl_easy_setopt(curl, CURLOPT_CONNECTTIMEOUT_MS, static_cast<long>(options_.connect_timeout_ms));
  curl_easy_setopt(curl, CURLOPT_TIMEOUT_MS, static_cast<long>(options_.request_timeout_ms));
  // Large bodies go with "Expect: 100-continue"; servers that never answer it cost no wait. (The
  // header cannot be suppressed with "Expect:": curl would sign the empty header it then omits.)
  curl_easy_setopt(curl, CURLOPT_EXPECT_100_TIMEOUT_MS, 10L);
  curl_easy_setopt(curl, CURLOPT_WRITEFUNCTION, &WriteBody);
  curl_easy_setopt(curl, CURLOPT_WRITEDATA, &response.body);
  curl_easy_setopt(curl, CURLOPT_HEADERFUNCTION, &WriteHeader);
  curl_easy_setopt(curl, CURLOPT_HEADERDATA, &response.headers);
  SetMethodAndBody(curl, r);
  const CURLcode rc = curl_easy_perform(curl);
  curl_easy_getinfo(curl, CURLINFO_RESPONSE_CODE, &response.status);
  curl_easy_setopt(curl, CURLOPT_HTTPHEADER, nullptr);
  curl_easy_setopt(curl, CURLOPT_RESOLVE, nullptr);
  ReleaseHandle(curl);
  if (rc != CURLE_OK)
    return absl::UnavailableError(absl::StrCat("S3 ", Describe(r, location_), " at ",
                                               location_.endpoint, ": ", curl_easy_strerror(rc)));
  return response;
}

absl::StatusOr<S3Response> S3Client::Send(const S3Request& request) {
  absl::StatusOr<S3Response> result;
  int backoff = options_.initial_backoff_ms;
  for (int attempt = 1;; ++attempt) {
    result = SendOnce(request);
    const bool retry = !result.ok() || result->status == 500 || result->status == 502 ||
                       result->status == 503 || result->status == 504;
    if (!retry || attempt >= options_.max_attempts) return result;
    std::this_thread::sleep_for(std::chrono::milliseconds(backoff));  // backoff, not a poll
    backoff *= 2;
  }
}

absl::Status S3Client::ToStatus(const S3Request& r, const S3Response& response) const {
  std::string detail = absl::StrCat("HTTP ", response.status);
  pugi::xml_document doc;
  if (!response.body.empty() && doc.load_buffer(response.body.data(), response.body.size())) {
    const pugi::xml_node e = doc.child("Error");
    if (e) absl::StrAppend(&detail, " ", e.child_value("Code"), ": ", e.child_value("Message"));
  }
  const std::string message = absl::StrCat("S3 ", Describe(r, location_), ": ", detail);
  switch (response.status) {
    case 404:
      return absl::NotFoundError(message);
    case 401:
    case 403:
      return absl::PermissionDeniedError(message);
    case 409:
    case 412:
      return absl::FailedPreconditionError(message);
    case 416:
      return absl::OutOfRangeError(message);
    case 429:
      return absl::ResourceExhaustedError(message);
    default:
      if (response.status >= 500) return absl::UnavailableError(message);
      return absl::InvalidArgumentError(message);
  }
}

absl::StatusOr<S3Response> S3Client::Call(const S3Request& request) {
  ASSIGN_OR_RETURN(S3Response response, Send(request));
  if (response.status < 200 || response.status >= 300) return ToStatus(request, response);
  // CompleteMultipartUpload and copies can fail after a 200 with an <Error> body.
  if (request.method != "GET" && absl::StrContains(response.body, "<Error>")) {
    response.status = 500;
    return ToStatus(request, response);
  }
  return response;
}

}  // namespace instascene::store
