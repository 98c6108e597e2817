// services/gateway/routes.h: the gateway's /api/v1 routes, each forwarding to a gRPC service
// (Scheduler: jobs, scenes, pipelines, the queue, live events; Store: blobs; Objects: a scene's
// objects found by id, point, click or ray), and /api/v1/health.
#pragma once

#include <memory>

#include <httplib.h>

#include "services/gateway/http_util.h"

namespace instascene::gateway {

void AddRoutes(httplib::Server& http, const std::shared_ptr<Stubs>& stubs);

}  // namespace instascene::gateway
