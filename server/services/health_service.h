// HealthService: the standard gRPC health protocol (proto/grpc/health/v1/health.proto), every
// status NOT_SERVING until Set() says otherwise.
//
// gRPC's built-in health service starts SERVING and can only be told otherwise once the server is
// already accepting calls, so a client checking in that instant was told SERVING before the store
// was open. This one is registered like any other service, before the server starts.
//
// The known names are "" (the server as a whole) and those given to the constructor. Check answers
// a known name's status and NOT_FOUND for any other; Watch sends the status at once and again at
// each change (SERVICE_UNKNOWN for an unknown name, as the protocol says; a watcher behind by
// several changes gets the latest only). Shutdown() sets every status NOT_SERVING for good (Set()
// is ignored after it) and ends each watch with UNAVAILABLE once that answer is written, so that
// watchers do not hold the server's drain until its deadline. At most kMaxWatches watches are
// open at once; one more ends at once with RESOURCE_EXHAUSTED.
#pragma once

#include <map>
#include <mutex>
#include <set>
#include <string>
#include <vector>

#include "grpc/health/v1/health.grpc.pb.h"

namespace recog::server {

class HealthWatch;

class HealthService final : public ::grpc::health::v1::Health::CallbackService {
 public:
  explicit HealthService(const std::vector<std::string>& services);

  static constexpr size_t kMaxWatches = 1000;

  // The status of `service` (one of the known names; others are ignored) from now on.
  void Set(const std::string& service, bool serving);
  void Shutdown();

  grpc::ServerUnaryReactor* Check(grpc::CallbackServerContext* context,
                                  const ::grpc::health::v1::HealthCheckRequest* request,
                                  ::grpc::health::v1::HealthCheckResponse* response) override;
  grpc::ServerWriteReactor<::grpc::health::v1::HealthCheckResponse>* Watch(
      grpc::CallbackServerContext* context,
      const ::grpc::health::v1::HealthCheckRequest* request) override;

 private:
  friend class HealthWatch;
  using ServingStatus = ::grpc::health::v1::HealthCheckResponse::ServingStatus;
  ServingStatus StatusOfLocked(const std::string& service) const;

  std::mutex mutex_;  // guards everything below; taken before a watch's own
  std::map<std::string, bool> serving_;
  std::set<HealthWatch*> watches_;
  bool shut_down_ = false;
};

}  // namespace recog::server
