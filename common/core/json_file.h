// common/core/json_file.h: a JSON file read whole, bounded in size.
#pragma once

#include <cstddef>
#include <string>

#include <nlohmann/json.hpp>

#include "absl/status/statusor.h"

namespace instascene {

// The parsed document. NotFound / ResourceExhausted as ReadFileBounded (file_io.h); DataLoss
// "<path>: not JSON" when it does not parse.
absl::StatusOr<nlohmann::json> ReadJsonFile(const std::string& path, size_t max_bytes);

}  // namespace instascene
