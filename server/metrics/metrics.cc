#include "server/metrics/metrics.h"

#include <prometheus/collectable.h>
#include <prometheus/counter.h>
#include <prometheus/family.h>
#include <prometheus/gauge.h>
#include <prometheus/histogram.h>
#include <prometheus/registry.h>
#include <prometheus/text_serializer.h>

#include <algorithm>
#include <exception>
#include <filesystem>
#include <utility>

#include <httplib.h>

#include "recog_build_info.h"
#include "server/config/server_config.h"
#include "server/http/guarded_http_server.h"
#include "server/http/host_header.h"

namespace recog::server {
namespace {

// RPC durations from 1 ms (a cached query) to 10 s (a deadline).
const prometheus::Histogram::BucketBoundaries& RpcBuckets() {
  static const prometheus::Histogram::BucketBoundaries buckets = {
      0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0};
  return buckets;
}

std::string RpcTypeName(RpcType type) {
  switch (type) {
    case RpcType::kUnary:
      return "unary";
    case RpcType::kClientStream:
      return "client_stream";
    case RpcType::kServerStream:
      return "server_stream";
    case RpcType::kBidiStream:
      return "bidi_stream";
  }
  return "unknown";
}

template <typename T>
prometheus::Family<T>& Register(prometheus::detail::Builder<T> builder, prometheus::Registry& r,
                                const std::string& name, const std::string& help) {
  return builder.Name(name).Help(help).Register(r);
}

}  // namespace

class ServerMetrics::DiskSpace : public prometheus::Collectable {
 public:
  void Watch(const std::string& path) {
    std::lock_guard lock(mutex_);
    path_ = path;
  }

  std::vector<prometheus::MetricFamily> Collect() const override {
    std::string path;
    {
      std::lock_guard lock(mutex_);
      path = path_;
    }
    if (path.empty()) return {};
    std::error_code error;
    const std::filesystem::space_info space = std::filesystem::space(path, error);
    if (error) return {};
    const auto gauge = [](const char* name, const char* help, std::uintmax_t bytes) {
      prometheus::MetricFamily family{name, help, prometheus::MetricType::Gauge, {}};
      family.metric.emplace_back().gauge.value = static_cast<double>(bytes);
      return family;
    };
    return {gauge("recog_store_disk_available_bytes",
                  "Free bytes of the file system holding the data directory", space.available),
            gauge("recog_store_disk_capacity_bytes",
                  "Size of the file system holding the data directory", space.capacity)};
  }

 private:
  mutable std::mutex mutex_;
  std::string path_;
};

ServerMetrics::ServerMetrics()
    : registry_(std::make_shared<prometheus::Registry>()), disk_(std::make_shared<DiskSpace>()) {
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
  map_index_from_snapshot_ =
      &Register(prometheus::BuildGauge(), r, "recog_map_index_from_snapshot",
                "1 when start-up loaded the place map's index from its snapshot, 0 when rebuilt");
  map_frames_read_at_start_ =
      &Register(prometheus::BuildGauge(), r, "recog_map_frames_read_at_start",
                "Frames start-up read from the store to index the place map");
  objects_ =
      &Register(prometheus::BuildGauge(), r, "recog_objects", "Object models in the database")
           .Add({});
  recovery_lost_ = &Register(prometheus::BuildGauge(), r, "recog_store_recovery_lost",
                             "What a point-in-time recovery of the damaged store lost at start-up");
  SetStoreRecoveryLoss(0, 0, 0);
  store_damaged_ = &Register(prometheus::BuildGauge(), r, "recog_store_damaged",
                             "1 when the last check of the store's files found damage")
                        .Add({});
  verified_bytes_ = &Register(prometheus::BuildCounter(), r, "recog_store_verified_bytes_total",
                              "Bytes read by the checks of the store's files")
                         .Add({});
  verify_seconds_ = &Register(prometheus::BuildGauge(), r, "recog_store_verify_seconds",
                              "Duration of the last check of the store's files")
                         .Add({});
  stream_active_ =
      &Register(prometheus::BuildGauge(), r, "recog_stream_active", "Open streaming calls per RPC");
  replica_synced_ = &Register(prometheus::BuildGauge(), r, "recog_replica_synced",
                              "1 while this repository replica follows its primary live")
                         .Add({});
  replica_changes_ = &Register(prometheus::BuildCounter(), r, "recog_replica_changes_total",
                               "Model changes this repository replica copied from its primary")
                          .Add({});
  grpc_started_ = &Register(prometheus::BuildCounter(), r, "grpc_server_started_total",
                            "RPCs started, by type, service and method");
  grpc_handled_ = &Register(prometheus::BuildCounter(), r, "grpc_server_handled_total",
                            "RPCs finished, by type, service, method and status code");
  grpc_handling_ = &Register(prometheus::BuildHistogram(), r, "grpc_server_handling_seconds",
                             "Duration of finished RPCs by type, service and method");
  grpc_received_ = &Register(prometheus::BuildCounter(), r, "grpc_server_msg_received_total",
                             "Request messages received, by type, service and method");
  grpc_sent_ = &Register(prometheus::BuildCounter(), r, "grpc_server_msg_sent_total",
                         "Response messages sent, by type, service and method");
  Register(prometheus::BuildGauge(), r, "recog_build_info",
           "Always 1: the version and commit of this recogd")
      .Add({{"version", build_info::kVersion}, {"commit", build_info::kCommit}})
      .Set(1.0);
}

// The endpoint stops serving before the registry goes away.
ServerMetrics::~ServerMetrics() = default;

ServerMetrics::FinishedSeries ServerMetrics::FindFinished(std::string_view method,
                                                          std::string_view code) {
  FinishedSeries found;
  const auto by_method = rpc_histograms_.find(method);
  if (by_method != rpc_histograms_.end()) {
    const auto by_code = by_method->second.find(code);
    if (by_code != by_method->second.end()) found.duration = by_code->second;
  }
  found.grpc = FindGrpc(method);
  if (found.grpc != nullptr) {
    const auto handled = found.grpc->handled.find(code);
    if (handled != found.grpc->handled.end()) found.handled = handled->second;
  }
  return found;
}

ServerMetrics::GrpcSeries* ServerMetrics::FindGrpc(std::string_view method) {
  const auto it = grpc_series_.find(method);
  return it == grpc_series_.end() ? nullptr : &it->second;
}

void ServerMetrics::ObserveRpc(std::string_view method, std::string_view code, double seconds) {
  FinishedSeries series;
  {
    std::shared_lock lock(rpc_mutex_);
    series = FindFinished(method, code);
  }
  if (series.duration == nullptr || (series.grpc != nullptr && series.handled == nullptr)) {
    std::unique_lock lock(rpc_mutex_);
    series = FindFinished(method, code);
    if (series.duration == nullptr) {
      series.duration = &rpc_duration_->Add(
          {{"method", std::string(method)}, {"code", std::string(code)}}, RpcBuckets());
      rpc_histograms_[std::string(method)].emplace(std::string(code), series.duration);
    }
    if (series.grpc != nullptr && series.handled == nullptr) {
      const GrpcSeries& g = *series.grpc;
      series.handled = &grpc_handled_->Add({{"grpc_type", g.type},
                                            {"grpc_service", g.service},
                                            {"grpc_method", g.method},
                                            {"grpc_code", std::string(code)}});
      series.grpc->handled.emplace(std::string(code), series.handled);
    }
  }
  series.duration->Observe(seconds);
  if (series.grpc != nullptr) {
    series.handled->Increment();
    series.grpc->handling->Observe(seconds);
  }
}

void ServerMetrics::RegisterRpc(std::string_view method, RpcType type) {
  std::unique_lock lock(rpc_mutex_);
  if (grpc_series_.find(method) != grpc_series_.end()) return;
  // "/recognition.v1.PlaceRecognition/QueryPlace": service and method.
  const size_t slash = method.rfind('/');
  const std::string_view service =
      slash == std::string_view::npos ? std::string_view() : method.substr(0, slash);
  GrpcSeries series;
  series.type = RpcTypeName(type);
  series.service = std::string(service.starts_with('/') ? service.substr(1) : service);
  series.method = std::string(method.substr(slash + 1));
  const prometheus::Labels labels = {
      {"grpc_type", series.type}, {"grpc_service", series.service}, {"grpc_method", series.method}};
  series.started = &grpc_started_->Add(labels);
  series.received = &grpc_received_->Add(labels);
  series.sent = &grpc_sent_->Add(labels);
  series.handling = &grpc_handling_->Add(labels, RpcBuckets());
  grpc_series_.emplace(std::string(method), std::move(series));
}

void ServerMetrics::RpcStarted(std::string_view method) {
  std::shared_lock lock(rpc_mutex_);
  if (GrpcSeries* series = FindGrpc(method)) series->started->Increment();
}

void ServerMetrics::MessageReceived(std::string_view method) {
  std::shared_lock lock(rpc_mutex_);
  if (GrpcSeries* series = FindGrpc(method)) series->received->Increment();
}

void ServerMetrics::MessageSent(std::string_view method) {
  std::shared_lock lock(rpc_mutex_);
  if (GrpcSeries* series = FindGrpc(method)) series->sent->Increment();
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

void ServerMetrics::SetMapIndexOpening(std::string_view map, bool from_snapshot,
                                       uint64_t frames_read) {
  const prometheus::Labels labels = {{"map", std::string(map)}};
  std::lock_guard lock(map_mutex_);
  map_index_from_snapshot_->Add(labels).Set(from_snapshot ? 1.0 : 0.0);
  map_frames_read_at_start_->Add(labels).Set(static_cast<double>(frames_read));
}

void ServerMetrics::RemoveMap(std::string_view map) {
  const prometheus::Labels labels = {{"map", std::string(map)}};
  std::lock_guard lock(map_mutex_);
  for (prometheus::Family<prometheus::Gauge>* family :
       {map_entries_, map_index_from_snapshot_, map_frames_read_at_start_}) {
    if (family->Has(labels)) family->Remove(&family->Add(labels));
  }
}

void ServerMetrics::SetObjects(uint64_t objects) { objects_->Set(static_cast<double>(objects)); }

void ServerMetrics::StoreVerified(bool damaged, uint64_t bytes, double seconds) {
  store_damaged_->Set(damaged ? 1.0 : 0.0);
  verified_bytes_->Increment(static_cast<double>(bytes));
  verify_seconds_->Set(seconds);
}

void ServerMetrics::SetStoreRecoveryLoss(uint64_t entries, uint64_t maps, uint64_t blobs) {
  recovery_lost_->Add({{"kind", "entries"}}).Set(static_cast<double>(entries));
  recovery_lost_->Add({{"kind", "maps"}}).Set(static_cast<double>(maps));
  recovery_lost_->Add({{"kind", "blobs"}}).Set(static_cast<double>(blobs));
}

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

void ServerMetrics::WatchDisk(const std::string& path) { disk_->Watch(path); }

Status ServerMetrics::StartHttp(const std::string& listen_address) {
  return StartHttp(listen_address, MetricsConfig());
}

Status ServerMetrics::StartHttp(const std::string& listen_address, const HttpPortConfig& port) {
  if (listen_address.empty()) {
    return Status::InvalidArgument("the metrics endpoint needs an address (host:port)");
  }
  std::lock_guard lock(http_mutex_);
  if (http_ != nullptr) {
    return Status::FailedPrecondition("the metrics endpoint is already serving");
  }
  const HeaderList headers = {{"X-Content-Type-Options", "nosniff"}};
  std::unique_ptr<httplib::Server> http = MakeGuardedHttpServer(LimitsOf(port), nullptr, headers);
  http->set_default_headers(httplib::Headers(headers.begin(), headers.end()));
  // Before routing, before any body: the wrong host, method or a body close the connection.
  http->set_pre_routing_handler([hosts = HostAllowList(port.hosts)](const httplib::Request& request,
                                                                    httplib::Response& response) {
    const auto refuse = [&](int status, const char* message) {
      response.status = status;
      response.set_header("Connection", "close");
      response.set_content(message, "text/plain; charset=utf-8");
      CloseConnectionAfterResponse();
      return httplib::Server::HandlerResponse::Handled;
    };
    if (request.get_header_value_count("Host") != 1 ||
        !hosts.AcceptsHeader(request.get_header_value("Host"))) {
      return refuse(403,
                    "the metrics answer to their addresses, localhost and the names of "
                    "metrics.hosts, not to the Host of this request\n");
    }
    if (request.method != "GET" && request.method != "HEAD") {
      return refuse(405, "the metrics answer GET and HEAD only\n");
    }
    if (request.has_header("Transfer-Encoding") ||
        request.get_header_value<uint64_t>("Content-Length") > 0) {
      return refuse(400, "a request for the metrics has no body\n");
    }
    return httplib::Server::HandlerResponse::Unhandled;
  });
  http->Get("/metrics", [this](const httplib::Request&, httplib::Response& response) {
    response.set_header("Cache-Control", "no-store");
    response.set_content(Serialize(), "text/plain; version=0.0.4; charset=utf-8");
  });
  http->set_error_handler([](const httplib::Request&, httplib::Response& response) {
    if (response.body.empty()) {
      response.set_content(
          response.status == 404 ? "the metrics are at /metrics\n" : "the request is malformed\n",
          "text/plain; charset=utf-8");
    }
  });
  StatusOr<std::unique_ptr<::recog::server::HttpPort>> listening =
      ::recog::server::HttpPort::Listen(std::move(http), listen_address, "the metrics endpoint");
  if (!listening.ok()) return listening.status();
  http_ = std::move(listening).value();
  return Status::Ok();
}

int ServerMetrics::HttpPort() const {
  std::lock_guard lock(http_mutex_);
  return http_ == nullptr ? 0 : http_->port();
}

std::string ServerMetrics::Serialize() const {
  std::vector<prometheus::MetricFamily> families = registry_->Collect();
  for (prometheus::MetricFamily& family : disk_->Collect()) families.push_back(std::move(family));
  return prometheus::TextSerializer().Serialize(families);
}

ServerMetrics::Totals ServerMetrics::ReadTotals() const {
  Totals totals;
  totals.bucket_bounds = RpcBuckets();
  totals.bucket_counts.assign(totals.bucket_bounds.size(), 0);
  for (const prometheus::MetricFamily& family : registry_->Collect()) {
    if (family.name == "recog_rpc_duration_seconds") {
      for (const prometheus::ClientMetric& metric : family.metric) {
        const uint64_t count = metric.histogram.sample_count;
        totals.calls += count;
        const bool ok = std::any_of(metric.label.begin(), metric.label.end(), [](const auto& l) {
          return l.name == "code" && l.value == "OK";
        });
        if (!ok) totals.errors += count;
        const auto& buckets = metric.histogram.bucket;
        for (size_t b = 0; b < buckets.size() && b < totals.bucket_counts.size(); ++b) {
          totals.bucket_counts[b] += buckets[b].cumulative_count;
        }
      }
    } else if (family.name == "recog_frames_total") {
      for (const prometheus::ClientMetric& metric : family.metric) {
        totals.frames += uint64_t(metric.counter.value);
      }
    } else if (family.name == "recog_worker_queue_depth" && !family.metric.empty()) {
      totals.queue_depth = family.metric.front().gauge.value;
    }
  }
  return totals;
}

}  // namespace recog::server
