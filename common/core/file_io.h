// common/core/file_io.h: the one durable file write of the project. Every writer that must never
// leave a torn file behind (PLY, images, store blobs, manifests, ready files) goes through it.
#pragma once

#include <string>

#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"

namespace instascene {

// Writes `bytes` to `path` atomically and durably: a temporary file in the same folder, fsync,
// rename over `path`, fsync of the folder. On error nothing is left at `path` that was not there
// before and the temporary file is removed. Errors: Unavailable naming the path and the reason.
absl::Status WriteFileAtomically(const std::string& path, absl::string_view bytes);

// Reads a whole file into memory, refusing files larger than max_bytes (ResourceExhausted).
absl::StatusOr<std::string> ReadFileBounded(const std::string& path, size_t max_bytes);

// Writes `bytes` to `path` (create or truncate) and fsyncs the file; no rename.
absl::Status WriteAndSync(const std::string& path, absl::string_view bytes);

// fsyncs a file or a directory (after a rename into it).
absl::Status SyncPath(const std::string& path, bool directory);

// Renames `from` over `to` and fsyncs the folder of `to`: the last step of an atomic publish.
absl::Status RenameDurably(const std::string& from, const std::string& to);

}  // namespace instascene
