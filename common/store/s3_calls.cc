// S3Client's calls (s3_client.h): buckets and objects, multipart uploads, listings, each one
// request through the client's transport (S3Client::Call / Send) and its XML answer parsed.
#include <openssl/evp.h>

#include <algorithm>

#include <pugixml.hpp>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/time/time.h"
#include "common/core/status.h"
#include "common/store/s3_client.h"

namespace instascene::store {
namespace {

std::string XmlEscape(absl::string_view s) {
  std::string out;
  for (char c : s) {
    switch (c) {
      case '&':
        out += "&amp;";
        break;
      case '<':
        out += "&lt;";
        break;
      case '>':
        out += "&gt;";
        break;
      case '"':
        out += "&quot;";
        break;
      default:
        out += c;
    }
  }
  return out;
}

// The root element of an XML response, or an error naming the call.
absl::StatusOr<pugi::xml_node> ParseXml(pugi::xml_document& doc, const std::string& body,
                                        absl::string_view call) {
  if (!doc.load_buffer(body.data(), body.size()) || !doc.document_element())
    return absl::DataLossError(absl::StrCat("S3 ", call, ": malformed XML response"));
  return doc.document_element();
}

// Content-MD5 of a body (base64): every S3 implementation checks it before storing, also those
// that do not check x-amz-content-sha256 against the body.
std::string ContentMd5(absl::string_view body) {
  unsigned char md5[EVP_MAX_MD_SIZE];
  unsigned int len = 0;
  EVP_Digest(body.data(), body.size(), md5, &len, EVP_md5(), nullptr);
  unsigned char b64[64];
  const int n = EVP_EncodeBlock(b64, md5, static_cast<int>(len));
  return std::string(reinterpret_cast<char*>(b64), static_cast<size_t>(n));
}

// S3's two time formats: ListObjectsV2's ISO 8601 (2026-12-07T13:00:00.000Z) and HTTP's
// Last-Modified (Mon, 07 Dec 2026 13:00:00 GMT).
absl::StatusOr<std::chrono::system_clock::time_point> ParseS3Time(const std::string& text,
                                                                  bool http) {
  absl::Time t;
  std::string error;
  if (!absl::ParseTime(http ? "%a, %d %b %Y %H:%M:%S GMT" : "%Y-%m-%d%ET%H:%M:%E*SZ", text,
                       absl::UTCTimeZone(), &t, &error))
    return absl::DataLossError(
        absl::StrCat("S3: unreadable time '", text.substr(0, 40), "': ", error));
  return std::chrono::time_point_cast<std::chrono::system_clock::duration>(absl::ToChronoTime(t));
}

}  // namespace

absl::Status S3Client::HeadBucket() {
  S3Request r;  // a one-key listing rather than HEAD: its errors come with S3's explanation
  r.query = {{"list-type", "2"}, {"max-keys", "1"}};
  ASSIGN_OR_RETURN(S3Response response, Send(r));
  if (response.status == 200) return absl::OkStatus();
  if (response.status == 404)
    return absl::NotFoundError(
        absl::StrCat("S3 bucket '", location_.bucket, "' does not exist at ", location_.endpoint));
  return ToStatus(r, response);
}

absl::StatusOr<std::optional<int64_t>> S3Client::HeadObject(const std::string& key) {
  S3Request r;
  r.method = "HEAD";
  r.key = key;
  ASSIGN_OR_RETURN(S3Response response, Send(r));
  if (response.status == 404) return std::optional<int64_t>();
  if (response.status != 200) return ToStatus(r, response);
  int64_t size = 0;
  if (!absl::SimpleAtoi(response.headers["content-length"], &size))
    return absl::DataLossError(absl::StrCat("S3 HEAD ", key, ": no Content-Length"));
  return std::optional<int64_t>(size);
}

absl::StatusOr<std::optional<S3Client::ObjectInfo>> S3Client::StatObject(const std::string& key) {
  S3Request r;
  r.method = "HEAD";
  r.key = key;
  ASSIGN_OR_RETURN(S3Response response, Send(r));
  if (response.status == 404) return std::optional<ObjectInfo>();
  if (response.status != 200) return ToStatus(r, response);
  ObjectInfo info;
  if (!absl::SimpleAtoi(response.headers["content-length"], &info.size))
    return absl::DataLossError(absl::StrCat("S3 HEAD ", key, ": no Content-Length"));
  ASSIGN_OR_RETURN(info.modified, ParseS3Time(response.headers["last-modified"], /*http=*/true));
  return std::optional<ObjectInfo>(info);
}

absl::Status S3Client::PutObject(const std::string& key, absl::string_view bytes) {
  S3Request r;
  r.method = "PUT";
  r.key = key;
  r.body = bytes;
  r.headers = {absl::StrCat("Content-MD5: ", ContentMd5(bytes))};
  return Call(r).status();
}

absl::StatusOr<std::string> S3Client::GetObject(const std::string& key, int64_t offset,
                                                int64_t limit) {
  S3Request r;
  r.key = key;
  if (offset > 0 || limit > 0)
    r.headers.push_back(absl::StrCat("Range: bytes=", offset, "-",
                                     limit > 0 ? absl::StrCat(offset + limit - 1) : ""));
  ASSIGN_OR_RETURN(S3Response response, Call(r));
  return std::move(response.body);
}

absl::Status S3Client::DeleteObject(const std::string& key) {
  S3Request r;
  r.method = "DELETE";
  r.key = key;
  return Call(r).status();
}

absl::Status S3Client::CopyObject(const std::string& from_key, const std::string& to_key) {
  S3Request r;
  r.method = "PUT";
  r.key = to_key;
  r.headers = {
      absl::StrCat("x-amz-copy-source: /", location_.bucket, "/", AwsUriEncode(from_key, true))};
  return Call(r).status();
}

absl::Status S3Client::TouchObject(const std::string& key) {
  S3Request r;
  r.method = "PUT";
  r.key = key;
  r.headers = {absl::StrCat("x-amz-copy-source: /", location_.bucket, "/", AwsUriEncode(key, true)),
               "x-amz-metadata-directive: REPLACE"};
  return Call(r).status();
}

absl::StatusOr<std::string> S3Client::CreateMultipartUpload(const std::string& key) {
  S3Request r;
  r.method = "POST";
  r.key = key;
  r.query = {{"uploads", ""}};
  ASSIGN_OR_RETURN(S3Response response, Call(r));
  pugi::xml_document doc;
  ASSIGN_OR_RETURN(pugi::xml_node root, ParseXml(doc, response.body, "CreateMultipartUpload"));
  const std::string id = root.child_value("UploadId");
  if (id.empty()) return absl::DataLossError("S3 CreateMultipartUpload: no UploadId");
  return id;
}

absl::StatusOr<std::string> S3Client::UploadPart(const std::string& key,
                                                 const std::string& upload_id, int number,
                                                 absl::string_view bytes) {
  S3Request r;
  r.method = "PUT";
  r.key = key;
  r.query = {{"partNumber", absl::StrCat(number)}, {"uploadId", upload_id}};
  r.body = bytes;
  r.headers = {absl::StrCat("Content-MD5: ", ContentMd5(bytes))};
  ASSIGN_OR_RETURN(S3Response response, Call(r));
  const std::string etag = response.headers["etag"];
  if (etag.empty()) return absl::DataLossError("S3 UploadPart: no ETag");
  return etag;
}

absl::StatusOr<std::string> S3Client::UploadPartCopy(const std::string& key,
                                                     const std::string& upload_id, int number,
                                                     const std::string& from_key, int64_t first,
                                                     int64_t last) {
  S3Request r;
  r.method = "PUT";
  r.key = key;
  r.query = {{"partNumber", absl::StrCat(number)}, {"uploadId", upload_id}};
  r.headers = {
      absl::StrCat("x-amz-copy-source: /", location_.bucket, "/", AwsUriEncode(from_key, true)),
      absl::StrCat("x-amz-copy-source-range: bytes=", first, "-", last)};
  ASSIGN_OR_RETURN(S3Response response, Call(r));
  pugi::xml_document doc;
  ASSIGN_OR_RETURN(pugi::xml_node root, ParseXml(doc, response.body, "UploadPartCopy"));
  const std::string etag = root.child_value("ETag");
  if (etag.empty()) return absl::DataLossError("S3 UploadPartCopy: no ETag");
  return etag;
}

absl::StatusOr<std::vector<S3Client::Part>> S3Client::ListParts(const std::string& key,
                                                                const std::string& upload_id) {
  std::vector<Part> parts;
  std::string marker;
  for (;;) {
    S3Request r;
    r.key = key;
    r.query = {{"uploadId", upload_id}};
    if (!marker.empty()) r.query.push_back({"part-number-marker", marker});
    ASSIGN_OR_RETURN(S3Response response, Call(r));
    pugi::xml_document doc;
    ASSIGN_OR_RETURN(pugi::xml_node root, ParseXml(doc, response.body, "ListParts"));
    for (pugi::xml_node p : root.children("Part")) {
      Part part;
      part.number = p.child("PartNumber").text().as_int();
      part.etag = p.child_value("ETag");
      part.size = p.child("Size").text().as_llong();
      parts.push_back(part);
    }
    if (std::string(root.child_value("IsTruncated")) != "true") break;
    marker = root.child_value("NextPartNumberMarker");
    if (marker.empty()) break;
  }
  std::sort(parts.begin(), parts.end(),
            [](const Part& a, const Part& b) { return a.number < b.number; });
  return parts;
}

absl::Status S3Client::CompleteMultipartUpload(const std::string& key, const std::string& upload_id,
                                               const std::vector<Part>& parts) {
  std::string body = "<CompleteMultipartUpload>";
  for (const Part& p : parts)
    absl::StrAppend(&body, "<Part><PartNumber>", p.number, "</PartNumber><ETag>", XmlEscape(p.etag),
                    "</ETag></Part>");
  body += "</CompleteMultipartUpload>";
  S3Request r;
  r.method = "POST";
  r.key = key;
  r.query = {{"uploadId", upload_id}};
  r.body = body;
  r.headers = {"Content-Type: application/xml"};
  return Call(r).status();
}

absl::Status S3Client::AbortMultipartUpload(const std::string& key, const std::string& upload_id) {
  S3Request r;
  r.method = "DELETE";
  r.key = key;
  r.query = {{"uploadId", upload_id}};
  absl::Status s = Call(r).status();
  return absl::IsNotFound(s) ? absl::OkStatus() : s;
}

absl::StatusOr<std::vector<S3Client::Upload>> S3Client::ListMultipartUploads(
    const std::string& prefix) {
  std::vector<Upload> uploads;
  std::string key_marker, id_marker;
  for (;;) {
    S3Request r;
    r.query = {{"uploads", ""}, {"prefix", prefix}};
    if (!key_marker.empty()) r.query.push_back({"key-marker", key_marker});
    if (!id_marker.empty()) r.query.push_back({"upload-id-marker", id_marker});
    ASSIGN_OR_RETURN(S3Response response, Call(r));
    pugi::xml_document doc;
    ASSIGN_OR_RETURN(pugi::xml_node root, ParseXml(doc, response.body, "ListMultipartUploads"));
    for (pugi::xml_node u : root.children("Upload"))
      uploads.push_back(
          {u.child_value("Key"), u.child_value("UploadId"), u.child_value("Initiated")});
    if (std::string(root.child_value("IsTruncated")) != "true") break;
    key_marker = root.child_value("NextKeyMarker");
    id_marker = root.child_value("NextUploadIdMarker");
    if (key_marker.empty()) break;
  }
  return uploads;
}

absl::StatusOr<std::vector<S3Client::Object>> S3Client::ListObjects(const std::string& prefix) {
  std::vector<Object> objects;
  std::string after;
  for (;;) {
    S3Request r;
    // Paged by start-after (a key) rather than continuation tokens, whose base64 would need
    // encoding that curl's signer re-encodes.
    r.query = {{"list-type", "2"}, {"prefix", prefix}};
    if (!after.empty()) r.query.push_back({"start-after", after});
    ASSIGN_OR_RETURN(S3Response response, Call(r));
    pugi::xml_document doc;
    ASSIGN_OR_RETURN(pugi::xml_node root, ParseXml(doc, response.body, "ListObjectsV2"));
    for (pugi::xml_node c : root.children("Contents")) {
      ASSIGN_OR_RETURN(const auto modified,
                       ParseS3Time(c.child_value("LastModified"), /*http=*/false));
      objects.push_back({c.child_value("Key"), c.child("Size").text().as_llong(), modified});
    }
    if (std::string(root.child_value("IsTruncated")) != "true" || objects.empty()) break;
    if (objects.back().key == after) break;
    after = objects.back().key;
  }
  return objects;
}

}  // namespace instascene::store
