#include "server/services/health_service.h"

namespace recog::server {

namespace health = ::grpc::health::v1;

// One Watch stream: while a write is out, `latest_` keeps the newest status, written after it.
class HealthWatch final : public grpc::ServerWriteReactor<health::HealthCheckResponse> {
 public:
  HealthWatch(HealthService& service, std::string name)
      : service_(service), name_(std::move(name)) {
    std::lock_guard service_lock(service_.mutex_);
    std::lock_guard lock(mutex_);
    if (service_.watches_.size() >= HealthService::kMaxWatches) {
      FinishLocked({grpc::StatusCode::RESOURCE_EXHAUSTED,
                    "too many health watches open (" + std::to_string(HealthService::kMaxWatches) +
                        "); use Check, or retry later"});
      return;
    }
    service_.watches_.insert(this);
    SendLocked(service_.StatusOfLocked(name_));
    if (service_.shut_down_) EndLocked();
  }

  const std::string& name() const { return name_; }

  // The status of the watched name changed. Called under the service's mutex.
  void Changed(HealthService::ServingStatus status) {
    std::lock_guard lock(mutex_);
    SendLocked(status);
  }

  // The server shuts down: ends the stream after the status being or waiting to be written.
  // Called under the service's mutex.
  void End() {
    std::lock_guard lock(mutex_);
    EndLocked();
  }

 private:
  void SendLocked(HealthService::ServingStatus status) {
    if (finished_ || status == latest_) return;
    latest_ = status;
    if (!writing_) WriteLatestLocked();
  }

  void WriteLatestLocked() {
    response_.set_status(latest_);
    writing_ = true;
    StartWrite(&response_);
  }

  void EndLocked() {
    end_ = true;
    if (!writing_) FinishLocked({grpc::StatusCode::UNAVAILABLE, "the server is shutting down"});
  }

  void FinishLocked(const grpc::Status& status) {
    if (finished_) return;
    finished_ = true;
    Finish(status);
  }

  void OnWriteDone(bool ok) override {
    std::lock_guard lock(mutex_);
    writing_ = false;
    if (!ok || cancelled_) {
      FinishLocked({grpc::StatusCode::CANCELLED, "the client went away"});
    } else if (latest_ != response_.status()) {
      WriteLatestLocked();
    } else if (end_) {
      FinishLocked({grpc::StatusCode::UNAVAILABLE, "the server is shutting down"});
    }
  }

  void OnCancel() override {
    std::lock_guard lock(mutex_);
    cancelled_ = true;  // the write out, if there is one, ends the stream when it returns
    if (!writing_) FinishLocked({grpc::StatusCode::CANCELLED, "the client cancelled"});
  }

  void OnDone() override {
    {
      std::lock_guard service_lock(service_.mutex_);
      service_.watches_.erase(this);
    }
    delete this;
  }

  HealthService& service_;
  const std::string name_;
  std::mutex mutex_;                      // guards everything below
  health::HealthCheckResponse response_;  // being written
  // The newest status, written or to be written (UNKNOWN, which is never sent, before the first).
  HealthService::ServingStatus latest_ = health::HealthCheckResponse::UNKNOWN;
  bool writing_ = false, end_ = false, cancelled_ = false, finished_ = false;
};

HealthService::HealthService(const std::vector<std::string>& services) {
  serving_[""] = false;
  for (const std::string& service : services) serving_[service] = false;
}

HealthService::ServingStatus HealthService::StatusOfLocked(const std::string& service) const {
  const auto known = serving_.find(service);
  if (known == serving_.end()) return health::HealthCheckResponse::SERVICE_UNKNOWN;
  return known->second ? health::HealthCheckResponse::SERVING
                       : health::HealthCheckResponse::NOT_SERVING;
}

void HealthService::Set(const std::string& service, bool serving) {
  std::lock_guard lock(mutex_);
  const auto known = serving_.find(service);
  if (shut_down_ || known == serving_.end() || known->second == serving) return;
  known->second = serving;
  for (HealthWatch* watch : watches_) {
    if (watch->name() == service) watch->Changed(StatusOfLocked(service));
  }
}

void HealthService::Shutdown() {
  std::lock_guard lock(mutex_);
  if (shut_down_) return;
  shut_down_ = true;
  for (auto& [service, serving] : serving_) serving = false;
  for (HealthWatch* watch : watches_) {
    watch->Changed(StatusOfLocked(watch->name()));
    watch->End();
  }
}

grpc::ServerUnaryReactor* HealthService::Check(grpc::CallbackServerContext* context,
                                               const health::HealthCheckRequest* request,
                                               health::HealthCheckResponse* response) {
  grpc::ServerUnaryReactor* reactor = context->DefaultReactor();
  std::lock_guard lock(mutex_);
  const ServingStatus status = StatusOfLocked(request->service());
  if (status == health::HealthCheckResponse::SERVICE_UNKNOWN) {
    reactor->Finish({grpc::StatusCode::NOT_FOUND, "no health status for the service '" +
                                                      request->service() +
                                                      "' (the server's own is the empty name)"});
    return reactor;
  }
  response->set_status(status);
  reactor->Finish(grpc::Status::OK);
  return reactor;
}

grpc::ServerWriteReactor<health::HealthCheckResponse>* HealthService::Watch(
    grpc::CallbackServerContext*, const health::HealthCheckRequest* request) {
  return new HealthWatch(*this, request->service());
}

}  // namespace recog::server
