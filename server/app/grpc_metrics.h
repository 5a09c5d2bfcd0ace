// The standard gRPC server metrics of ServerMetrics (server/metrics/metrics.h), fed from gRPC:
// RegisterServiceMethods gives every method of the named services its series (at zero, so that
// dashboards see them before the first call), and the interceptors made by
// GrpcMetricsInterceptorFactory count each call's start and its messages. A call's end is
// counted by the services' ObserveRpc, with the project's own duration histogram.
#pragma once

#include <memory>
#include <string_view>
#include <vector>

#include <grpcpp/support/server_interceptor.h>

#include "server/metrics/metrics.h"

namespace recog::server {

// Registers each method of the services named `services` ("recognition.v1.PlaceRecognition"),
// found in the generated descriptor pool, with its streaming type. A name not in the pool is
// skipped.
void RegisterServiceMethods(ServerMetrics& metrics, const std::vector<std::string_view>& services);

// For grpc::ServerBuilder::experimental().SetInterceptorCreators. `metrics` must outlive the
// server.
std::unique_ptr<grpc::experimental::ServerInterceptorFactoryInterface>
MakeGrpcMetricsInterceptorFactory(ServerMetrics* metrics);

}  // namespace recog::server
