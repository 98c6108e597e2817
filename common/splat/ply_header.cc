// common/splat/ply_header.cc: the PLY header parser declared in ply.h.
#include <charconv>
#include <string>
#include <vector>

#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "absl/strings/strip.h"
#include "common/core/status.h"
#include "common/splat/ply.h"

namespace instascene {
namespace {

bool ParseScalarType(absl::string_view s, ScalarType* type) {
  struct Entry {
    absl::string_view name;
    ScalarType type;
  };
  static constexpr Entry kTypes[] = {
      {"char", ScalarType::kInt8},      {"int8", ScalarType::kInt8},
      {"uchar", ScalarType::kUint8},    {"uint8", ScalarType::kUint8},
      {"short", ScalarType::kInt16},    {"int16", ScalarType::kInt16},
      {"ushort", ScalarType::kUint16},  {"uint16", ScalarType::kUint16},
      {"int", ScalarType::kInt32},      {"int32", ScalarType::kInt32},
      {"uint", ScalarType::kUint32},    {"uint32", ScalarType::kUint32},
      {"float", ScalarType::kFloat32},  {"float32", ScalarType::kFloat32},
      {"double", ScalarType::kFloat64}, {"float64", ScalarType::kFloat64},
  };
  for (const Entry& e : kTypes) {
    if (e.name == s) {
      *type = e.type;
      return true;
    }
  }
  return false;
}

// One header line, split into tokens, and how to report an error on it.
struct HeaderLine {
  absl::string_view source, text;
  int number = 0;
  std::vector<absl::string_view> tok;

  absl::Status Error(absl::string_view what) const {
    return absl::InvalidArgumentError(
        absl::StrCat(source, ": PLY header line ", number, ": ", what));
  }
};

absl::Status ParseFormat(const HeaderLine& line, PlyHeader* header) {
  const auto& tok = line.tok;
  if (tok.size() != 3) return line.Error("malformed 'format' line");
  if (tok[1] == "ascii")
    header->format = PlyFormat::kAscii;
  else if (tok[1] == "binary_little_endian")
    header->format = PlyFormat::kBinaryLittleEndian;
  else if (tok[1] == "binary_big_endian")
    header->format = PlyFormat::kBinaryBigEndian;
  else
    return line.Error(absl::StrCat("unknown format '", tok[1], "'"));
  return absl::OkStatus();
}

absl::Status ParseElement(const HeaderLine& line, PlyHeader* header) {
  const auto& tok = line.tok;
  int64_t count = -1;
  const char* count_end = tok.size() == 3 ? tok[2].data() + tok[2].size() : nullptr;
  std::from_chars_result parsed{};
  if (tok.size() == 3) parsed = std::from_chars(tok[2].data(), count_end, count);
  // The whole token must be the count: "8e3" is not 8.
  if (tok.size() != 3 || parsed.ec != std::errc() || parsed.ptr != count_end || count < 0) {
    return line.Error("malformed 'element' line (expected: element NAME COUNT)");
  }
  header->elements.push_back({std::string(tok[1]), count, {}});
  return absl::OkStatus();
}

absl::Status ParseProperty(const HeaderLine& line, const PlyLimits& limits, PlyHeader* header) {
  const auto& tok = line.tok;
  if (header->elements.empty()) return line.Error("property before any element");
  PlyElement& element = header->elements.back();
  if (static_cast<int>(element.properties.size()) >= limits.max_properties) {
    return line.Error(absl::StrCat("more than ", limits.max_properties, " properties"));
  }
  PlyProperty prop;
  if (tok.size() == 5 && tok[1] == "list") {
    prop.is_list = true;
    if (!ParseScalarType(tok[2], &prop.count_type) || !ParseScalarType(tok[3], &prop.type) ||
        !IsIntegerType(prop.count_type)) {
      return line.Error(absl::StrCat("unknown list property type in '", line.text, "'"));
    }
    prop.name = std::string(tok[4]);
  } else if (tok.size() == 3) {
    if (!ParseScalarType(tok[1], &prop.type)) {
      return line.Error(
          absl::StrCat("unknown property type '", tok[1], "' of property '", tok[2], "'"));
    }
    prop.name = std::string(tok[2]);
  } else {
    return line.Error(absl::StrCat("malformed property line '", line.text, "'"));
  }
  for (const PlyProperty& other : element.properties) {
    if (other.name == prop.name) {
      return line.Error(absl::StrCat("duplicate property '", prop.name, "'"));
    }
  }
  element.properties.push_back(std::move(prop));
  return absl::OkStatus();
}

// The header's end: the offset of 'end_header', checked against the limit and its newline.
absl::StatusOr<size_t> HeaderEnd(absl::string_view data, absl::string_view source,
                                 const PlyLimits& limits, size_t* data_offset) {
  if (!absl::StartsWith(data, "ply\n") && !absl::StartsWith(data, "ply\r\n")) {
    return absl::InvalidArgumentError(
        absl::StrCat(source, ": not a PLY file (missing 'ply' magic)"));
  }
  const size_t end = data.find("end_header");
  if (end == absl::string_view::npos || end > limits.max_header_bytes) {
    return absl::InvalidArgumentError(
        absl::StrCat(source, ": PLY header has no 'end_header' within ", limits.max_header_bytes,
                     " bytes (truncated file?)"));
  }
  const size_t newline = data.find('\n', end);
  if (newline == absl::string_view::npos) {
    return absl::InvalidArgumentError(
        absl::StrCat(source, ": PLY header not terminated by newline"));
  }
  *data_offset = newline + 1;
  return end;
}

}  // namespace

absl::StatusOr<PlyHeader> ParsePlyHeader(absl::string_view data, absl::string_view source,
                                         const PlyLimits& limits) {
  PlyHeader header;
  ASSIGN_OR_RETURN(const size_t end, HeaderEnd(data, source, limits, &header.data_offset));
  bool have_format = false;
  HeaderLine line{source, {}, 0, {}};
  for (absl::string_view text : absl::StrSplit(data.substr(0, end), '\n')) {
    ++line.number;
    line.text = absl::StripTrailingAsciiWhitespace(text);
    line.tok = absl::StrSplit(line.text, ' ', absl::SkipEmpty());
    const auto& tok = line.tok;
    if (tok.empty() || tok[0] == "ply") continue;
    if (tok[0] == "comment" || tok[0] == "obj_info") {
      header.comments.emplace_back(absl::StripPrefix(line.text, tok[0]));
    } else if (tok[0] == "format") {
      RETURN_IF_ERROR(ParseFormat(line, &header));
      have_format = true;
    } else if (tok[0] == "element") {
      RETURN_IF_ERROR(ParseElement(line, &header));
    } else if (tok[0] == "property") {
      RETURN_IF_ERROR(ParseProperty(line, limits, &header));
    } else {
      return line.Error(absl::StrCat("unknown keyword '", tok[0], "'"));
    }
  }
  if (!have_format)
    return absl::InvalidArgumentError(absl::StrCat(source, ": PLY header has no format line"));
  return header;
}

}  // namespace instascene
