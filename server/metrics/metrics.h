// ServerMetrics: recogd's Prometheus metrics, and the HTTP endpoint that serves them.
//
// One instance per server owns a registry with these metrics:
//   recog_rpc_duration_seconds{method, code}  histogram, 1 ms to 10 s: every finished RPC
//   recog_frames_total{kind}                   counter: frames processed, kind "place" or "object"
//   recog_loop_detections_total                counter: verified loop closures
//   recog_object_detections_total              counter: recognised object instances
//   recog_worker_queue_depth                   gauge: tasks waiting for a worker
//   recog_worker_busy                          gauge: workers running a task
//   recog_map_entries{map}                     gauge: entries of each place map
//   recog_map_index_from_snapshot{map}         gauge: 1 when the map's index was loaded from its
//                                              snapshot at start-up, 0 when rebuilt from frames
//   recog_map_frames_read_at_start{map}        gauge: the frames start-up read from the store to
//                                              index the map (those after its snapshot, or all)
//   recog_objects                              gauge: object models in the database
//   recog_store_recovery_lost{kind}            gauge: what this start-up's point-in-time recovery
//                                              of a damaged store lost, kind "entries", "maps" or
//                                              "blobs" (0 when the store opened whole)
//   recog_store_damaged                        gauge: 1 when the last check of the store's files
//                                              (background or `recog admin verify`) found damage
//   recog_store_verified_bytes_total           counter: bytes those checks read
//   recog_store_verify_seconds                 gauge: how long the last check took
//   recog_stream_active{rpc}                   gauge: open streaming calls per RPC
//   recog_replica_synced                       gauge: 1 while a repository replica follows its
//                                              primary live, 0 otherwise (and on a primary)
//   recog_replica_changes_total                counter: model changes a replica copied
//   recog_build_info{version, commit}          gauge, always 1: the build serving (the version
//                                              and commit `recogd --version` prints)
//   recog_store_disk_available_bytes           gauge: free bytes of the file system holding the
//                                              data directory (WatchDisk), read at each scrape
//   recog_store_disk_capacity_bytes            gauge: that file system's size
// and, for the methods given to RegisterRpc, the standard gRPC server metrics of stock dashboards
// (the names and labels of go-grpc-prometheus), labelled grpc_type ("unary", "client_stream",
// "server_stream", "bidi_stream"), grpc_service ("recognition.v1.PlaceRecognition") and
// grpc_method ("QueryPlace"):
//   grpc_server_started_total                  counter: calls started (RpcStarted)
//   grpc_server_handled_total{..., grpc_code}  counter: calls finished, by status code ("OK")
//   grpc_server_handling_seconds               histogram: duration of finished calls
//   grpc_server_msg_received_total             counter: request messages received
//   grpc_server_msg_sent_total                 counter: response messages sent
// A finished call is recorded once, by ObserveRpc, in both recog_rpc_duration_seconds and the
// grpc_server_handled_total / grpc_server_handling_seconds pair.
// StartHttp serves them as text on http://<listen_address>/metrics (Serialize's text), through
// the guarded HTTP server of server/http/ (its deadlines, header limits and connection caps, as
// MetricsConfig sets them) and only to a Host that is an IP address, localhost or a name of
// `metrics.hosts` (403 otherwise: DNS rebinding). Every method is thread-safe; ObserveRpc,
// RpcStarted, MessageReceived and MessageSent, on every call's path, take a shared lock and
// allocate nothing once a (method, code) pair has been seen. No method throws.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <shared_mutex>
#include <string>
#include <string_view>
#include <unordered_map>
#include <vector>

#include "core/common/status.h"

namespace prometheus {
class Collectable;
class Counter;
class Gauge;
class Histogram;
class Registry;
template <typename T>
class Family;
}  // namespace prometheus

namespace recog::server {

class HttpPort;
struct HttpPortConfig;

enum class FrameKind {
  kPlace,   // a frame given to a place map (loop detection, query, keyframe)
  kObject,  // a frame searched for objects
};

// How a gRPC method streams (grpc_type).
enum class RpcType {
  kUnary,         // "unary"
  kClientStream,  // "client_stream"
  kServerStream,  // "server_stream"
  kBidiStream,    // "bidi_stream"
};

class ServerMetrics {
 public:
  ServerMetrics();
  ~ServerMetrics();
  ServerMetrics(const ServerMetrics&) = delete;
  ServerMetrics& operator=(const ServerMetrics&) = delete;

  // Records a finished RPC: `method` is the full name ("/recognition.v1.PlaceRecognition/
  // QueryPlace"), `code` the gRPC status code name ("OK", "NOT_FOUND"). Also counts it in the
  // standard gRPC metrics when `method` is registered.
  void ObserveRpc(std::string_view method, std::string_view code, double seconds);

  // Gives `method` (a full name, as above) the standard gRPC metrics, at zero; before serving.
  // Registering a method again does nothing.
  void RegisterRpc(std::string_view method, RpcType type);
  // A call of `method` started, received a request message, sent a response message. Nothing for
  // a method not registered (e.g. health checks, reflection).
  void RpcStarted(std::string_view method);
  void MessageReceived(std::string_view method);
  void MessageSent(std::string_view method);

  void AddFrames(FrameKind kind, uint64_t count = 1);
  void AddLoopDetections(uint64_t count = 1);
  void AddObjectDetections(uint64_t count);

  void SetWorkerQueueDepth(uint64_t tasks);
  void SetBusyWorkers(uint64_t workers);

  // The number of entries of place map `map`; RemoveMap drops its series (a deleted map).
  void SetMapEntries(std::string_view map, uint64_t entries);
  // How start-up built the index of place map `map` (see above); RemoveMap drops these too.
  void SetMapIndexOpening(std::string_view map, bool from_snapshot, uint64_t frames_read);
  void RemoveMap(std::string_view map);
  void SetObjects(uint64_t objects);
  void SetStoreRecoveryLoss(uint64_t entries, uint64_t maps, uint64_t blobs);
  // A check of the store's files ended: damage found or not, bytes read, its duration.
  void StoreVerified(bool damaged, uint64_t bytes, double seconds);

  // A repository replica (server/replication/) is or is no longer synced with its primary;
  // it applied `count` changes (copied versions, deletions).
  void SetReplicaSynced(bool synced);
  void AddReplicaChanges(uint64_t count = 1);

  // The disk metrics report the file system that holds `path` (the data directory) from now on;
  // until then, and while `path` cannot be read, they are absent.
  void WatchDisk(const std::string& path);

  // A streaming call of `rpc` (e.g. "StreamFrames") opened or closed.
  void StreamOpened(std::string_view rpc);
  void StreamClosed(std::string_view rpc);

  // Serves the metrics on http://<listen_address>/metrics ("127.0.0.1:9464"; port 0 picks a free
  // port, see HttpPort) with the limits of `port` (MetricsConfig's defaults when not given), from
  // background threads until the object is destroyed. GET and HEAD of /metrics only (other paths
  // 404, other methods 405, a body 400).
  // INVALID_ARGUMENT for an empty or malformed address, FAILED_PRECONDITION when already serving,
  // UNAVAILABLE when the address cannot be bound (port in use, no such interface).
  Status StartHttp(const std::string& listen_address);
  Status StartHttp(const std::string& listen_address, const HttpPortConfig& port);
  // The port StartHttp bound, 0 before.
  int HttpPort() const;

  // Every metric in Prometheus' text exposition format, as /metrics serves it.
  std::string Serialize() const;

  // Totals since start, read from the metrics above (for the console's live charts: RPCs of every
  // method, those whose code was not OK, frames of both kinds, the queue depth now, and the RPC
  // duration histogram summed over methods and codes).
  struct Totals {
    uint64_t calls = 0;
    uint64_t errors = 0;
    uint64_t frames = 0;
    double queue_depth = 0;
    std::vector<double> bucket_bounds;    // seconds: the histogram's upper bounds (no +Inf)
    std::vector<uint64_t> bucket_counts;  // calls at or below each bound (cumulative)
  };
  Totals ReadTotals() const;

 private:
  // Heterogeneous lookup by string_view, so that looking up a seen label value does not allocate.
  struct StringHash {
    using is_transparent = void;
    size_t operator()(std::string_view s) const { return std::hash<std::string_view>{}(s); }
  };
  template <typename V>
  using StringMap = std::unordered_map<std::string, V, StringHash, std::equal_to<>>;

  class DiskSpace;  // the disk metrics, computed when collected

  std::shared_ptr<prometheus::Registry> registry_;
  std::shared_ptr<DiskSpace> disk_;
  std::unique_ptr<::recog::server::HttpPort> http_;  // null until StartHttp succeeds

  prometheus::Family<prometheus::Histogram>* rpc_duration_;
  prometheus::Family<prometheus::Gauge>* map_entries_;
  prometheus::Family<prometheus::Gauge>* map_index_from_snapshot_;
  prometheus::Family<prometheus::Gauge>* map_frames_read_at_start_;
  prometheus::Family<prometheus::Gauge>* stream_active_;
  prometheus::Counter* place_frames_;
  prometheus::Counter* object_frames_;
  prometheus::Counter* loop_detections_;
  prometheus::Counter* object_detections_;
  prometheus::Gauge* queue_depth_;
  prometheus::Gauge* busy_workers_;
  prometheus::Gauge* objects_;
  prometheus::Family<prometheus::Gauge>* recovery_lost_;
  prometheus::Gauge* store_damaged_;
  prometheus::Counter* verified_bytes_;
  prometheus::Gauge* verify_seconds_;
  prometheus::Gauge* replica_synced_;
  prometheus::Counter* replica_changes_;

  // The standard gRPC series of one registered method; the registry owns them.
  struct GrpcSeries {
    std::string type, service, method;  // the labels
    prometheus::Counter* started;
    prometheus::Counter* received;
    prometheus::Counter* sent;
    prometheus::Histogram* handling;
    StringMap<prometheus::Counter*> handled;  // by code, under rpc_mutex_
  };
  // The series a finished call of (method, code) is counted in; null when not yet created, and
  // *grpc (and *handled) null for a method not registered.
  struct FinishedSeries {
    prometheus::Histogram* duration = nullptr;
    GrpcSeries* grpc = nullptr;
    prometheus::Counter* handled = nullptr;
  };
  FinishedSeries FindFinished(std::string_view method, std::string_view code);  // under rpc_mutex_
  GrpcSeries* FindGrpc(std::string_view method);                                // under rpc_mutex_

  prometheus::Family<prometheus::Counter>* grpc_started_;
  prometheus::Family<prometheus::Counter>* grpc_handled_;
  prometheus::Family<prometheus::Histogram>* grpc_handling_;
  prometheus::Family<prometheus::Counter>* grpc_received_;
  prometheus::Family<prometheus::Counter>* grpc_sent_;

  // rpc_duration_'s histograms by method, then code, and the registered methods' standard series
  // by method; the registry owns the metrics.
  mutable std::shared_mutex rpc_mutex_;
  StringMap<StringMap<prometheus::Histogram*>> rpc_histograms_;
  StringMap<GrpcSeries> grpc_series_;
  std::mutex map_mutex_;  // makes RemoveMap's find-and-remove atomic with SetMapEntries
  mutable std::mutex http_mutex_;
};

}  // namespace recog::server
