#include "server/metrics/metrics.h"

#include <prometheus/counter.h>
#include <prometheus/exposer.h>
#include <prometheus/family.h>
#include <prometheus/gauge.h>
#include <prometheus/histogram.h>
#include <prometheus/registry.h>
#include <prometheus/text_serializer.h>

#include <exception>
#include <utility>

#include "recog_build_info.h"

namespace recog::server {
namespace {

// RPC durations from 1 ms (a cached query) to 10 s (a deadline).
const prometheus::Histogram::BucketBoundaries& RpcBuckets() {
  static const prometheus::Histogram::BucketBoundaries buckets = {
      0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0};
  return buckets;
}

template <typename T>
prometheus::Family<T>& Register(prometheus::detail::Builder<T> builder, prometheus::Registry& r,
                                const std::string& name, const std::string& help) {
  return builder.Name(name).Help(help).Register(r);
}

}  // namespace

ServerMetrics::ServerMetrics() : registry_(std::make_shared<prometheus::Registry>()) {
  prometheus::Registry& r = *registry_;
  rpc_duration_ = &Register(prometheus::BuildHistogram(), r, "recog_rpc_duration_seconds",
                            "Duration of finished RPCs by method and gRPC status code");
  auto& frames = Register(prometheus::BuildCounter(), r, "recog_frames_total",
                          "Frames processed, by kind (place or object)");
  place_frames_ = &frames.Add({{"kind", "place"}});
  object_frames_ = &frames.Add({{"kind", "object"}});
  loop_detections_ = &Register(prometheus::BuildCounter(), r, "recog_loop_detections_total",
                               "Verified loop closures")
                          .Add({});
  object_detections_ = &Register(prometheus::BuildCounter(), r, "recog_object_detections_total",
                                 "Recognised object instances")
                            .Add({});
  queue_depth_ = &Register(prometheus::BuildGauge(), r, "recog_worker_queue_depth",
                           "Tasks waiting for a worker")
                      .Add({});
  busy_workers_ =
      &Register(prometheus::BuildGauge(), r, "recog_worker_busy", "Workers running a task").Add({});
  map_entries_ =
      &Register(prometheus::BuildGauge(), r, "recog_map_entries", "Entries of each place map");
  objects_ =
      &Register(prometheus::BuildGauge(), r, "recog_objects", "Object models in the database")
           .Add({});
  stream_active_ =
      &Register(prometheus::BuildGauge(), r, "recog_stream_active", "Open streaming calls per RPC");
  replica_synced_ = &Register(prometheus::BuildGauge(), r, "recog_replica_synced",
                              "1 while this repository replica follows its primary live")
                         .Add({});
  replica_changes_ = &Register(prometheus::BuildCounter(), r, "recog_replica_changes_total",
                               "Model changes this repository replica copied from its primary")
                          .Add({});
  Register(prometheus::BuildGauge(), r, "recog_build_info",
           "Always 1: the version and commit of this recogd")
      .Add({{"version", build_info::kVersion}, {"commit", build_info::kCommit}})
      .Set(1.0);
}

// The exposer stops serving before the registry goes away.
ServerMetrics::~ServerMetrics() = default;

void ServerMetrics::ObserveRpc(std::string_view method, std::string_view code, double seconds) {
  {
    std::shared_lock lock(rpc_mutex_);
    const auto by_method = rpc_histograms_.find(method);
    if (by_method != rpc_histograms_.end()) {
      const auto by_code = by_method->second.find(code);
      if (by_code != by_method->second.end()) {
        by_code->second->Observe(seconds);
        return;
      }
    }
  }
  std::unique_lock lock(rpc_mutex_);
  auto by_method = rpc_histograms_.find(method);
  if (by_method == rpc_histograms_.end()) {
    by_method =
        rpc_histograms_.emplace(std::string(method), StringMap<prometheus::Histogram*>()).first;
  }
  auto by_code = by_method->second.find(code);
  if (by_code == by_method->second.end()) {
    prometheus::Histogram& histogram = rpc_duration_->Add(
        {{"method", std::string(method)}, {"code", std::string(code)}}, RpcBuckets());
    by_code = by_method->second.emplace(std::string(code), &histogram).first;
  }
  by_code->second->Observe(seconds);
}

void ServerMetrics::AddFrames(FrameKind kind, uint64_t count) {
  (kind == FrameKind::kPlace ? place_frames_ : object_frames_)
      ->Increment(static_cast<double>(count));
}

void ServerMetrics::AddLoopDetections(uint64_t count) {
  loop_detections_->Increment(static_cast<double>(count));
}

void ServerMetrics::AddObjectDetections(uint64_t count) {
  object_detections_->Increment(static_cast<double>(count));
}

void ServerMetrics::SetWorkerQueueDepth(uint64_t tasks) {
  queue_depth_->Set(static_cast<double>(tasks));
}

void ServerMetrics::SetBusyWorkers(uint64_t workers) {
  busy_workers_->Set(static_cast<double>(workers));
}

void ServerMetrics::SetMapEntries(std::string_view map, uint64_t entries) {
  std::lock_guard lock(map_mutex_);
  map_entries_->Add({{"map", std::string(map)}}).Set(static_cast<double>(entries));
}

void ServerMetrics::RemoveMap(std::string_view map) {
  const prometheus::Labels labels = {{"map", std::string(map)}};
  std::lock_guard lock(map_mutex_);
  if (map_entries_->Has(labels)) map_entries_->Remove(&map_entries_->Add(labels));
}

void ServerMetrics::SetObjects(uint64_t objects) { objects_->Set(static_cast<double>(objects)); }

void ServerMetrics::SetReplicaSynced(bool synced) { replica_synced_->Set(synced ? 1.0 : 0.0); }

void ServerMetrics::AddReplicaChanges(uint64_t count) {
  replica_changes_->Increment(static_cast<double>(count));
}

void ServerMetrics::StreamOpened(std::string_view rpc) {
  stream_active_->Add({{"rpc", std::string(rpc)}}).Increment();
}

void ServerMetrics::StreamClosed(std::string_view rpc) {
  stream_active_->Add({{"rpc", std::string(rpc)}}).Decrement();
}

Status ServerMetrics::StartHttp(const std::string& listen_address) {
  if (listen_address.empty()) {
    return Status::InvalidArgument("the metrics endpoint needs an address (host:port)");
  }
  std::lock_guard lock(exposer_mutex_);
  if (exposer_ != nullptr) {
    return Status::FailedPrecondition("the metrics endpoint is already serving");
  }
  try {
    auto exposer = std::make_unique<prometheus::Exposer>(listen_address, /*num_threads=*/2);
    exposer->RegisterCollectable(registry_);
    exposer_ = std::move(exposer);
  } catch (const std::exception& e) {
    return Status::Unavailable("cannot serve metrics on '" + listen_address +
                               "' (port in use or address not local?): " + e.what());
  }
  return Status::Ok();
}

int ServerMetrics::HttpPort() const {
  std::lock_guard lock(exposer_mutex_);
  if (exposer_ == nullptr) return 0;
  const std::vector<int> ports = exposer_->GetListeningPorts();
  return ports.empty() ? 0 : ports.front();
}

std::string ServerMetrics::Serialize() const {
  return prometheus::TextSerializer().Serialize(registry_->Collect());
}

}  // namespace recog::server
