// services/scheduler/job_proto.h: conversions between the job model and scheduler.proto.
#pragma once

#include "instascene/v1/scheduler.pb.h"
#include "services/scheduler/job.h"

namespace instascene::scheduler {

void ToProto(const Job& job, v1::Job* out);
v1::JobState ToProto(JobState state);
void ToProto(const JobProgress& progress, v1::Progress* out);
JobProgress FromProto(const v1::Progress& progress);
absl::StatusOr<FailureKind> FromProto(v1::FailureKind kind);  // InvalidArgument if unspecified
v1::FailureKind ToProto(FailureKind kind);
// "queued", "running", ... for a proto state (lower case, as the CLI prints them).
std::string StateName(v1::JobState state);

}  // namespace instascene::scheduler
