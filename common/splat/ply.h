// common/splat/ply.h: a bounded, fuzz-safe reader and writer for the PLY container format.
//
// Reads ASCII, binary little-endian and binary big-endian files; every scalar type of the PLY spec;
// list properties (skipped when reading columns). Properties are looked up by name, never by
// position. Allocation is bounded by the input size: element counts are checked against the bytes
// that follow the header before anything is allocated. Errors name the source, element index and
// property. Stateless functions, thread-safe.
#pragma once

#include <cstdint>
#include <string>
#include <vector>
#include "absl/strings/string_view.h"

#include "absl/status/statusor.h"
#include "common/core/file_io.h"  // ReadFileBounded, WriteFileAtomically (used with PLY data)

namespace instascene {

enum class PlyFormat { kAscii, kBinaryLittleEndian, kBinaryBigEndian };
enum class ScalarType { kInt8, kUint8, kInt16, kUint16, kInt32, kUint32, kFloat32, kFloat64 };

int ScalarTypeSize(ScalarType type);
bool IsIntegerType(ScalarType type);                // every type but float and double
absl::string_view ScalarTypeName(ScalarType type);  // PLY spelling: "float", "uchar", ...

struct PlyProperty {
  std::string name;
  ScalarType type = ScalarType::kFloat32;  // value type (list element type for lists)
  bool is_list = false;
  ScalarType count_type = ScalarType::kUint8;  // list length type
};

struct PlyElement {
  std::string name;
  int64_t count = 0;
  std::vector<PlyProperty> properties;
};

struct PlyHeader {
  PlyFormat format = PlyFormat::kBinaryLittleEndian;
  std::vector<PlyElement> elements;
  std::vector<std::string> comments;
  size_t data_offset = 0;  // byte offset of the first data byte after "end_header\n"
};

// Limits that keep the parser allocation-bounded on hostile input.
struct PlyLimits {
  size_t max_header_bytes = 1 << 20;  // header text
  int max_properties = 4096;          // per element
  int64_t max_list_length = 1 << 20;  // entries of one list
};

// Parses the header of `data` (the whole file). `source` names the file in error messages.
absl::StatusOr<PlyHeader> ParsePlyHeader(absl::string_view data, absl::string_view source,
                                         const PlyLimits& limits = {});

// The scalar properties of one element as float columns, in header order.
struct PlyColumns {
  int64_t count = 0;
  std::vector<std::string> names;
  std::vector<ScalarType> types;
  std::vector<std::vector<float>> columns;  // columns[p][i] = value of property p of instance i

  // Index of the column named `name`, or -1.
  int Find(absl::string_view name) const;
};

// Reads every scalar property of element `element_name` (elements before it are skipped, list
// properties are skipped). Integer values are converted exactly when |v| <= 2^24, else rejected;
// doubles are rounded to float (out-of-range values become an error, not Inf).
absl::StatusOr<PlyColumns> ReadPlyElement(absl::string_view data, const PlyHeader& header,
                                          absl::string_view element_name, absl::string_view source,
                                          const PlyLimits& limits = {});

// Serialises one element of float columns (each written with its ScalarType) as binary
// little-endian PLY.
std::string EncodePlyBinary(const std::string& element_name, const PlyColumns& columns,
                            const std::vector<std::string>& comments = {});

}  // namespace instascene
