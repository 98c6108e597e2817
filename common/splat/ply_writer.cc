// EncodePlyBinary (common/splat/ply.h): one element as binary little-endian PLY.
#include "common/splat/ply.h"

#include <bit>
#include <cstring>

#include "absl/strings/str_cat.h"

namespace instascene {
namespace {

// `v` converted to `type` (integers truncated toward zero) and stored at dst, little-endian.
void EncodeScalar(float v, ScalarType type, char* dst) {
  switch (type) {
    case ScalarType::kInt8: {
      int8_t x = static_cast<int8_t>(v);
      std::memcpy(dst, &x, 1);
      break;
    }
    case ScalarType::kUint8: {
      uint8_t x = static_cast<uint8_t>(v);
      std::memcpy(dst, &x, 1);
      break;
    }
    case ScalarType::kInt16: {
      int16_t x = static_cast<int16_t>(v);
      std::memcpy(dst, &x, 2);
      break;
    }
    case ScalarType::kUint16: {
      uint16_t x = static_cast<uint16_t>(v);
      std::memcpy(dst, &x, 2);
      break;
    }
    case ScalarType::kInt32: {
      int32_t x = static_cast<int32_t>(v);
      std::memcpy(dst, &x, 4);
      break;
    }
    case ScalarType::kUint32: {
      uint32_t x = static_cast<uint32_t>(v);
      std::memcpy(dst, &x, 4);
      break;
    }
    case ScalarType::kFloat32:
      std::memcpy(dst, &v, 4);
      break;
    case ScalarType::kFloat64: {
      double x = v;
      std::memcpy(dst, &x, 8);
      break;
    }
  }
}

}  // namespace

std::string EncodePlyBinary(const std::string& element_name, const PlyColumns& columns,
                            const std::vector<std::string>& comments) {
  std::string out = "ply\nformat binary_little_endian 1.0\n";
  for (const std::string& c : comments) absl::StrAppend(&out, "comment ", c, "\n");
  absl::StrAppend(&out, "element ", element_name, " ", columns.count, "\n");
  size_t stride = 0;
  for (size_t p = 0; p < columns.names.size(); ++p) {
    absl::StrAppend(&out, "property ", ScalarTypeName(columns.types[p]), " ", columns.names[p],
                    "\n");
    stride += ScalarTypeSize(columns.types[p]);
  }
  out += "end_header\n";
  const size_t header_size = out.size();
  out.resize(header_size + stride * columns.count);
  char* dst = out.data() + header_size;
  static_assert(std::endian::native == std::endian::little, "writer assumes a little-endian host");
  for (int64_t i = 0; i < columns.count; ++i) {
    for (size_t p = 0; p < columns.names.size(); ++p) {
      EncodeScalar(columns.columns[p][i], columns.types[p], dst);
      dst += ScalarTypeSize(columns.types[p]);
    }
  }
  return out;
}

}  // namespace instascene
