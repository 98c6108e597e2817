// instascene/client/services.h: protocol-level access through a Client's connection, for tools
// that need more than client.h offers (the `instascene` CLI's jobs, watch and cancel): the
// generated gRPC stubs of instascene/v1 and the same deadline-and-retry policy.
#pragma once

#include <functional>
#include <string>

#include <grpcpp/grpcpp.h>

#include "instascene/client/client.h"
#include "instascene/v1/objects.grpc.pb.h"
#include "instascene/v1/scheduler.grpc.pb.h"

namespace instascene::client {

v1::Scheduler::Stub& SchedulerStub(Client& client);
v1::Objects::Stub& ObjectsStub(Client& client);

// Runs a unary call with a fresh context carrying the client's deadline, retried with backoff
// while the service is UNAVAILABLE; `service` names it in errors ("scheduler", "store", ...).
absl::Status Call(Client& client, const std::string& service,
                  const std::function<grpc::Status(grpc::ClientContext*)>& call);
// The client's error for a finished call (streams: after Finish), without retrying: UNAVAILABLE and
// DEADLINE_EXCEEDED become "SERVICE ADDRESS unreachable: ...", other statuses pass through.
absl::Status StatusOf(Client& client, const std::string& service, const grpc::Status& status);

}  // namespace instascene::client
