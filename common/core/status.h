// common/core/status.h: error handling for every InstaScene library.
//
// Errors are values (absl::Status / absl::StatusOr); these macros propagate them. CHECK-style
// aborts are reserved for programmer errors no request can trigger. Thread-safe: stateless.
#pragma once

#include <utility>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/str_cat.h"

#define INSTASCENE_CONCAT_INNER(a, b) a##b
#define INSTASCENE_CONCAT(a, b) INSTASCENE_CONCAT_INNER(a, b)

// Returns from the current function if `expr` (an absl::Status) is not OK. The temporary's name is
// unique per use, so the macro nests (e.g. inside a lambda passed to another RETURN_IF_ERROR).
#define RETURN_IF_ERROR(expr) \
  RETURN_IF_ERROR_IMPL(INSTASCENE_CONCAT(_instascene_status_, __COUNTER__), expr)
#define RETURN_IF_ERROR_IMPL(tmp, expr) \
  do {                                  \
    ::absl::Status tmp = (expr);        \
    if (!tmp.ok()) return tmp;          \
  } while (0)

// `lhs = value of expr` where expr is an absl::StatusOr<T>; returns its status on error.
#define ASSIGN_OR_RETURN(lhs, expr) \
  ASSIGN_OR_RETURN_IMPL(INSTASCENE_CONCAT(_instascene_statusor_, __COUNTER__), lhs, expr)
#define ASSIGN_OR_RETURN_IMPL(tmp, lhs, expr)    \
  auto tmp = (expr);                             \
  if (!tmp.ok()) return std::move(tmp).status(); \
  lhs = std::move(tmp).value()

namespace instascene {

// Prefixes a status message with context ("file.ply: " + message), keeping the code.
inline absl::Status Annotate(const absl::Status& status, absl::string_view context) {
  if (status.ok()) return status;
  return absl::Status(status.code(), absl::StrCat(context, ": ", status.message()));
}

}  // namespace instascene
