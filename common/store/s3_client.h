// common/store/s3_client.h: a small client of the S3 REST API over libcurl, with curl's built-in
// AWS SigV4 signing (CURLOPT_AWS_SIGV4; Debian's libs3 predates SigV4). Only the calls the blob
// store needs: objects (HEAD/GET with ranges/PUT/DELETE/copy), multipart uploads (create, part,
// part-copy, list parts, complete, abort, list uploads) and ListObjectsV2.
//
// Where the bucket is, the credentials and the SigV4 signing rules: s3_location.h.
//
// Every request carries `x-amz-content-sha256` (the payload's SHA-256, which AWS checks against the
// body), uploads also `Content-MD5` (which every S3 implementation checks before storing), and each
// is retried on transport errors and HTTP 500/502/503/504 with exponential backoff.
// Errors map to absl codes (404 NotFound, 403 PermissionDenied, 416 OutOfRange, 5xx Unavailable,
// other 4xx InvalidArgument/FailedPrecondition) with the S3 error code and message. Thread-safe
// (a pool of curl handles keeps connections alive).
#pragma once

#include <chrono>
#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "common/store/s3_location.h"

namespace instascene::store {

struct S3ClientOptions {
  int connect_timeout_ms = 10000;
  int64_t request_timeout_ms = 600000;
  int max_attempts = 4;          // per request (1 = no retry)
  int initial_backoff_ms = 100;  // doubles per retry
  // curl's host:port:address overrides (CURLOPT_RESOLVE), for split-horizon DNS and for testing
  // virtual-hosted addressing against a local server.
  std::vector<std::string> resolve;
};

struct S3Request {
  std::string method = "GET";                              // GET HEAD PUT POST DELETE
  std::string key;                                         // "" = the bucket
  std::vector<std::pair<std::string, std::string>> query;  // sorted and encoded when sent
  std::vector<std::string> headers;                        // "Name: value"
  absl::string_view body;
};

struct S3Response {
  long status = 0;
  std::string body;
  std::map<std::string, std::string> headers;  // lower-case names
};

class S3Client {
 public:
  S3Client(S3Location location, S3Credentials credentials, S3ClientOptions options = {});
  ~S3Client();
  S3Client(const S3Client&) = delete;
  S3Client& operator=(const S3Client&) = delete;

  const S3Location& location() const { return location_; }

  // One request with retries; any HTTP status comes back (errors only for transport failures).
  absl::StatusOr<S3Response> Send(const S3Request& request);

  absl::Status HeadBucket();
  // The object's size, or nullopt if it does not exist.
  absl::StatusOr<std::optional<int64_t>> HeadObject(const std::string& key);
  struct ObjectInfo {
    int64_t size = 0;
    std::chrono::system_clock::time_point modified;  // Last-Modified (whole seconds)
  };
  // The object's size and modification time, or nullopt if it does not exist.
  absl::StatusOr<std::optional<ObjectInfo>> StatObject(const std::string& key);
  absl::Status PutObject(const std::string& key, absl::string_view bytes);
  // Bytes [offset, offset + limit) (limit 0 = to the end).
  absl::StatusOr<std::string> GetObject(const std::string& key, int64_t offset = 0,
                                        int64_t limit = 0);
  absl::Status DeleteObject(const std::string& key);
  absl::Status CopyObject(const std::string& from_key, const std::string& to_key);
  // Copies an object (up to 5 GiB) onto itself with its metadata replaced, which S3 allows and
  // which sets its modification time to now (the store's "touch").
  absl::Status TouchObject(const std::string& key);

  struct Part {
    int number = 0;
    std::string etag;
    int64_t size = 0;
  };
  struct Upload {
    std::string key, upload_id, initiated;
  };
  absl::StatusOr<std::string> CreateMultipartUpload(const std::string& key);
  absl::StatusOr<std::string> UploadPart(const std::string& key, const std::string& upload_id,
                                         int number, absl::string_view bytes);  // -> ETag
  // Copies bytes [first, last] of `from_key` as part `number` (multipart copy of large objects).
  absl::StatusOr<std::string> UploadPartCopy(const std::string& key, const std::string& upload_id,
                                             int number, const std::string& from_key, int64_t first,
                                             int64_t last);
  absl::StatusOr<std::vector<Part>> ListParts(const std::string& key, const std::string& upload_id);
  absl::Status CompleteMultipartUpload(const std::string& key, const std::string& upload_id,
                                       const std::vector<Part>& parts);
  absl::Status AbortMultipartUpload(const std::string& key, const std::string& upload_id);
  absl::StatusOr<std::vector<Upload>> ListMultipartUploads(const std::string& prefix);

  struct Object {
    std::string key;
    int64_t size = 0;
    std::chrono::system_clock::time_point modified;  // LastModified
  };
  // Every object under `prefix` (all pages).
  absl::StatusOr<std::vector<Object>> ListObjects(const std::string& prefix);

 private:
  void* AcquireHandle();
  void ReleaseHandle(void* handle);
  absl::StatusOr<S3Response> SendOnce(const S3Request& request);
  // The error status of a failed response ("" key = the bucket).
  absl::Status ToStatus(const S3Request& request, const S3Response& response) const;
  absl::StatusOr<S3Response> Call(const S3Request& request);  // Send + non-2xx -> error

  const S3Location location_;
  const S3Credentials credentials_;
  const S3ClientOptions options_;
  std::mutex pool_mutex_;
  std::vector<void*> pool_;  // idle CURL easy handles
};

}  // namespace instascene::store
