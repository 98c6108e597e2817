// EncodePlyBinary (common/splat/ply.h): one element as binary little-endian PLY.
#include "common/splat/ply.h"

#include <bit>
#include <cstring>

#include "absl/strings/str_cat.h"

namespace instascene {
namespace {

// `v` converted to T (integers truncated toward zero) and stored at dst, little-endian.
template <typename T>
void Store(float v, char* dst) {
  const T x = static_cast<T>(v);
  std::memcpy(dst, &x, sizeof(T));
}

void EncodeScalar(float v, ScalarType type, char* dst) {
  switch (type) {
    case ScalarType::kInt8:
      return Store<int8_t>(v, dst);
    case ScalarType::kUint8:
      return Store<uint8_t>(v, dst);
    case ScalarType::kInt16:
      return Store<int16_t>(v, dst);
    case ScalarType::kUint16:
      return Store<uint16_t>(v, dst);
    case ScalarType::kInt32:
      return Store<int32_t>(v, dst);
    case ScalarType::kUint32:
      return Store<uint32_t>(v, dst);
    case ScalarType::kFloat32:
      return Store<float>(v, dst);
    case ScalarType::kFloat64:
      return Store<double>(v, dst);
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
