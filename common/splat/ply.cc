#include "common/splat/ply.h"

#include <fcntl.h>
#include <unistd.h>

#include <bit>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <system_error>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "common/core/status.h"

namespace instascene {
namespace {

constexpr float kMaxExactInteger = 16777216.0f;  // 2^24: integers beyond it do not fit a float

// The scalar of type T in the first sizeof(T) bytes of `buf`, as double.
template <typename T>
double Read(const unsigned char* buf) {
  T v;
  std::memcpy(&v, buf, sizeof(T));
  return static_cast<double>(v);
}

// Decodes one binary scalar at p (which has at least ScalarTypeSize bytes) as double.
double DecodeBinary(const char* p, ScalarType type, bool big_endian) {
  unsigned char buf[8];
  const int n = ScalarTypeSize(type);
  std::memcpy(buf, p, n);
  if (big_endian != (std::endian::native == std::endian::big)) {
    for (int i = 0; i < n / 2; ++i) std::swap(buf[i], buf[n - 1 - i]);
  }
  switch (type) {
    case ScalarType::kInt8:
      return Read<int8_t>(buf);
    case ScalarType::kUint8:
      return Read<uint8_t>(buf);
    case ScalarType::kInt16:
      return Read<int16_t>(buf);
    case ScalarType::kUint16:
      return Read<uint16_t>(buf);
    case ScalarType::kInt32:
      return Read<int32_t>(buf);
    case ScalarType::kUint32:
      return Read<uint32_t>(buf);
    case ScalarType::kFloat32:
      return Read<float>(buf);
    case ScalarType::kFloat64:
      return Read<double>(buf);
  }
  return 0.0;
}

// Sequential reader over the data section, binary or ASCII, with bounds checks.
class DataCursor {
 public:
  DataCursor(absl::string_view data, size_t offset, PlyFormat format)
      : data_(data), pos_(offset), format_(format) {}

  size_t remaining() const { return data_.size() - pos_; }

  // Reads one scalar; false at end of data or on a malformed ASCII token.
  bool Read(ScalarType type, double* value) {
    if (format_ != PlyFormat::kAscii) {
      const size_t n = ScalarTypeSize(type);
      if (remaining() < n) return false;
      *value = DecodeBinary(data_.data() + pos_, type, format_ == PlyFormat::kBinaryBigEndian);
      pos_ += n;
      return true;
    }
    while (pos_ < data_.size() && IsSpace(data_[pos_])) ++pos_;
    size_t end = pos_;
    while (end < data_.size() && !IsSpace(data_[end])) ++end;
    if (end == pos_) return false;
    const char* first = data_.data() + pos_;
    const char* last = data_.data() + end;
    if (*first == '+') ++first;
    std::from_chars_result r;
    if (IsIntegerType(type)) {
      int64_t iv = 0;
      r = std::from_chars(first, last, iv);
      *value = static_cast<double>(iv);
    } else {
      r = std::from_chars(first, last, *value);
      if (r.ec == std::errc::result_out_of_range) return false;
    }
    if (r.ec != std::errc() || r.ptr != last) return false;
    pos_ = end;
    return true;
  }

  // Skips `count` scalars of a fixed type.
  bool Skip(ScalarType type, int64_t count) {
    if (format_ != PlyFormat::kAscii) {
      const uint64_t n = static_cast<uint64_t>(count) * ScalarTypeSize(type);
      if (remaining() < n) return false;
      pos_ += n;
      return true;
    }
    double dummy;
    for (int64_t i = 0; i < count; ++i) {
      if (!Read(type, &dummy)) return false;
    }
    return true;
  }

 private:
  static bool IsSpace(char c) { return c == ' ' || c == '\n' || c == '\r' || c == '\t'; }
  absl::string_view data_;
  size_t pos_;
  PlyFormat format_;
};

// Smallest number of bytes one instance of `element` can occupy (lists count as empty).
uint64_t MinInstanceBytes(const PlyElement& element, PlyFormat format) {
  uint64_t bytes = 0;
  for (const PlyProperty& p : element.properties) {
    if (format == PlyFormat::kAscii) {
      bytes += 2;  // at least one character and one separator per value (or list count)
    } else {
      bytes += ScalarTypeSize(p.is_list ? p.count_type : p.type);
    }
  }
  return bytes;
}

std::string DescribeFormat(PlyFormat f) {
  switch (f) {
    case PlyFormat::kAscii:
      return "ascii";
    case PlyFormat::kBinaryLittleEndian:
      return "binary_little_endian";
    case PlyFormat::kBinaryBigEndian:
      return "binary_big_endian";
  }
  return "?";
}

}  // namespace

bool IsIntegerType(ScalarType t) { return t != ScalarType::kFloat32 && t != ScalarType::kFloat64; }

int ScalarTypeSize(ScalarType type) {
  switch (type) {
    case ScalarType::kInt8:
    case ScalarType::kUint8:
      return 1;
    case ScalarType::kInt16:
    case ScalarType::kUint16:
      return 2;
    case ScalarType::kInt32:
    case ScalarType::kUint32:
    case ScalarType::kFloat32:
      return 4;
    case ScalarType::kFloat64:
      return 8;
  }
  return 0;
}

absl::string_view ScalarTypeName(ScalarType type) {
  switch (type) {
    case ScalarType::kInt8:
      return "char";
    case ScalarType::kUint8:
      return "uchar";
    case ScalarType::kInt16:
      return "short";
    case ScalarType::kUint16:
      return "ushort";
    case ScalarType::kInt32:
      return "int";
    case ScalarType::kUint32:
      return "uint";
    case ScalarType::kFloat32:
      return "float";
    case ScalarType::kFloat64:
      return "double";
  }
  return "?";
}

int PlyColumns::Find(absl::string_view name) const {
  for (size_t i = 0; i < names.size(); ++i) {
    if (names[i] == name) return static_cast<int>(i);
  }
  return -1;
}

namespace {

// Empty columns, one per scalar property of `element` (lists are skipped), room for its rows.
PlyColumns ColumnsFor(const PlyElement& element) {
  PlyColumns out;
  out.count = element.count;
  for (const PlyProperty& p : element.properties) {
    if (p.is_list) continue;
    out.names.push_back(p.name);
    out.types.push_back(p.type);
    out.columns.emplace_back();
    out.columns.back().reserve(element.count);
  }
  return out;
}

// Reads row `i` of `element` into `out`'s columns, or skips it when `out` is null. Lists are
// skipped (their length bounded); integers beyond 2^24 and values beyond float are refused.
absl::Status ReadRow(DataCursor& cursor, const PlyElement& element, int64_t i,
                     absl::string_view source, const PlyLimits& limits, PlyColumns* out) {
  int column = 0;
  for (const PlyProperty& p : element.properties) {
    auto fail = [&](absl::string_view what) {
      return absl::InvalidArgumentError(absl::StrCat(source, ": element '", element.name, "' #", i,
                                                     " property '", p.name, "': ", what));
    };
    double v = 0.0;
    if (p.is_list) {
      if (!cursor.Read(p.count_type, &v)) return fail("truncated or malformed list length");
      if (v < 0 || v > static_cast<double>(limits.max_list_length)) {
        return fail(absl::StrCat("list length ", v, " out of range"));
      }
      if (!cursor.Skip(p.type, static_cast<int64_t>(v))) return fail("truncated list");
      continue;
    }
    if (out == nullptr) {
      if (!cursor.Skip(p.type, 1)) return fail("truncated data");
      continue;
    }
    if (!cursor.Read(p.type, &v)) return fail("truncated data or malformed value");
    if (IsIntegerType(p.type) && std::abs(v) > kMaxExactInteger) {
      return fail(absl::StrCat("integer value ", v, " exceeds 2^24 and cannot be kept exactly"));
    }
    if (std::isfinite(v) && std::abs(v) > std::numeric_limits<float>::max()) {
      return fail(absl::StrCat("value ", v, " overflows float"));
    }
    out->columns[column++].push_back(static_cast<float>(v));
  }
  return absl::OkStatus();
}

}  // namespace

absl::StatusOr<PlyColumns> ReadPlyElement(absl::string_view data, const PlyHeader& header,
                                          absl::string_view element_name, absl::string_view source,
                                          const PlyLimits& limits) {
  DataCursor cursor(data, header.data_offset, header.format);
  for (const PlyElement& element : header.elements) {
    // Bound the element count by the bytes left before allocating anything.
    const uint64_t min_bytes = MinInstanceBytes(element, header.format);
    if (min_bytes > 0 && static_cast<uint64_t>(element.count) > cursor.remaining() / min_bytes) {
      return absl::InvalidArgumentError(absl::StrCat(
          source, ": truncated ", DescribeFormat(header.format), " PLY: header declares ",
          element.count, " '", element.name, "' elements (at least ", min_bytes,
          " bytes each) but only ", cursor.remaining(), " bytes follow"));
    }
    const bool wanted = element.name == element_name;
    // An element without properties holds no data, whatever its count: nothing to read or skip
    // (looping over a declared count of 2e13 would never end; found by ply_fuzz).
    if (element.properties.empty()) {
      if (!wanted) continue;
      PlyColumns empty;
      empty.count = element.count;
      return empty;
    }
    PlyColumns out = wanted ? ColumnsFor(element) : PlyColumns{};
    for (int64_t i = 0; i < element.count; ++i) {
      RETURN_IF_ERROR(ReadRow(cursor, element, i, source, limits, wanted ? &out : nullptr));
    }
    if (wanted) return out;
  }
  return absl::NotFoundError(
      absl::StrCat(source, ": PLY file has no element '", element_name, "'"));
}

}  // namespace instascene
