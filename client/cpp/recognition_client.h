// RecognitionClient: one connection to recogd and every call of its API
// (proto/recognition/v1/): place maps, frames and place queries, object recognition, and the
// model repository (uploads, resumable downloads, listings, change notifications).
//
// One client holds one gRPC channel; it is thread-safe, and meant to be shared by every thread of
// a process. Connect() checks the options and reads the TLS and token files, then returns at
// once: the channel connects in the background, and a server that is not listening yet is met by
// gRPC's retries of the first calls. Each call adds the bearer token and the deadline
// (ClientOptions::deadline for unary calls, transfer_deadline for model files); gRPC retries it
// by the policy of proto/service_config.json (ClientOptions). Every call that changes the server
// (CreateMap, DeleteMap, AddFrame, QueryPlace with add_frame, RemoveFrame, UploadModel,
// DeleteModel) takes an optional `request_id`; without one it sends a fresh UUID v4, so that the
// server answers a retry whose first answer was lost with that answer instead of applying the
// call twice. Give your own id to make a repeat of the whole call (say, after the process
// restarted) idempotent too, within the server's 10-minute window. Errors are grpc::Status values
// with canonical codes (see result.h); nothing throws.
//
// CheckHealth and DownloadCheckpoint serve operators (recog admin).
//
// Frame streams are separate objects (FrameStream, ObjectStream in frame_stream.h), opened on a
// client; they and ModelWatch handles may outlive it.
//
// What gRPC's retry cannot do stays here: gRPC retries a stream only until its first answer (or
// until it sent more than the retry buffer), so the transfers resume themselves. Model files
// travel in 256 KiB chunks. UploadModel computes the SHA-256 the server checks; when
// the connection breaks mid-file, it resumes the upload from the bytes the server kept
// (GetUploadStatus, PutModelHeader.offset) and, when the upload had completed but its answer was
// lost, return the version it created instead of storing the file twice.
// DownloadModel writes to `<path>.part`, verifies the size and SHA-256 the server announced, and
// renames the file into place; when the connection breaks mid-file it asks for the rest from the
// byte it has, and a `<path>.part` left by an earlier broken download is continued the same way
// (if the result does not verify, the file is fetched once more from the start). One download per
// path at a time.
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <grpcpp/grpcpp.h>

#include "client/cpp/client_options.h"
#include "client/cpp/result.h"
#include "grpc/health/v1/health.grpc.pb.h"
#include "recognition/v1/admin.grpc.pb.h"
#include "recognition/v1/object.grpc.pb.h"
#include "recognition/v1/place.grpc.pb.h"
#include "recognition/v1/repository.grpc.pb.h"

namespace recog::client {

namespace pb = ::recognition::v1;

namespace internal {
class WatchReactor;
}  // namespace internal

// What QueryPlace does with the frame.
enum class QueryMode {
  kRelocalise,  // look the frame up and change nothing (needs the read right)
  kAddFrame,    // run the map's loop detector and keep the frame, as a stream frame does
};

// Other maps QueryPlace also looks the frame up in: by name, and every map of a group (created
// with MapSettings.group). Their recognised places come back in the response's inter_map, best
// first; an unknown map or group is NOT_FOUND naming it. A stream names them in its StreamConfig
// (search_maps, search_group).
struct SearchSet {
  std::vector<std::string> maps = {};  // default: none
  std::string group = {};              // default "": none
};

// Which models ListModels returns; empty fields match everything. The initializers let callers
// name only the fields they set: ListModels({.tag = "kitchen"}).
struct ModelFilter {
  std::string name_prefix = {};   // default "": any name
  std::string object_class = {};  // default "": any class
  std::string tag = {};           // default "": any tag
};

// A running WatchModels stream. Events arrive on a gRPC thread, one at a time and in order; the
// callbacks must not block for long and must not destroy the handle. Destroying the handle
// cancels the stream and waits for it to end.
class ModelWatch {
 public:
  ~ModelWatch();
  ModelWatch(const ModelWatch&) = delete;
  ModelWatch& operator=(const ModelWatch&) = delete;

  // Ends the stream (Wait() then returns CANCELLED unless it had already ended).
  void Cancel();
  // Blocks until the stream ends; returns why: CANCELLED after Cancel(), RESOURCE_EXHAUSTED when
  // this watcher fell too far behind (list the models again, then watch anew), UNAVAILABLE when
  // the server shut down or the connection broke, UNAUTHENTICATED / PERMISSION_DENIED.
  grpc::Status Wait();

 private:
  friend class RecognitionClient;
  explicit ModelWatch(std::unique_ptr<internal::WatchReactor> reactor);
  std::unique_ptr<internal::WatchReactor> reactor_;
};

class RecognitionClient {
 public:
  // INVALID_ARGUMENT for bad options (ClientOptions::Validate) or a token file without a usable
  // token; NOT_FOUND when a TLS or token file cannot be read.
  static Result<std::unique_ptr<RecognitionClient>> Connect(const ClientOptions& options);
  ~RecognitionClient();
  RecognitionClient(const RecognitionClient&) = delete;
  RecognitionClient& operator=(const RecognitionClient&) = delete;

  const ClientOptions& options() const { return options_; }

  // --- Place maps ---

  // Creates an empty map; unset settings take the server's defaults. ALREADY_EXISTS.
  Result<pb::MapInfo> CreateMap(const std::string& name, const pb::MapSettings& settings = {},
                                const std::string& request_id = {});
  // NOT_FOUND for an unknown map.
  Result<pb::MapInfo> GetMap(const std::string& name);
  // Every map, by name (all pages).
  Result<std::vector<pb::MapInfo>> ListMaps();
  // Deletes a map and its frames; returns the number of frames deleted. NOT_FOUND.
  Result<uint64_t> DeleteMap(const std::string& name, const std::string& request_id = {});
  // Adds a frame to a map without querying it (keyframe upload).
  Result<pb::AddFrameResponse> AddFrame(const std::string& map, const pb::Frame& frame,
                                        const std::string& request_id = {});
  // Looks a frame up in a map (see QueryMode). `result_options` asks for the top-k candidates,
  // and for the fundamental matrix, the relative pose or the inlier correspondences of a verified
  // loop. The matched frame's client_frame_id comes in result().match_client_frame_id().
  // `request_id` counts with kAddFrame only. `search` names other maps to look the frame up in
  // (SearchSet).
  Result<pb::QueryPlaceResponse> QueryPlace(const std::string& map, const pb::Frame& frame,
                                            QueryMode mode = QueryMode::kRelocalise,
                                            const pb::ResultOptions& result_options = {},
                                            const std::string& request_id = {},
                                            const SearchSet& search = {});
  // Relocalisation (a kidnapped robot, the start of a session): looks 1..10 frames (say, the
  // last few of one camera) up in the maps of `search` and returns the places recognised, one at
  // most per map, best first (RelocalizeResponse.places; a map recognising more of the frames
  // first). `max_results` 0 keeps them all. Nothing is added; needs the read right. Through a
  // router the call goes to the shard of search.maps' first map, or else of search.group.
  Result<pb::RelocalizeResponse> Relocalize(const std::vector<pb::Frame>& frames,
                                            const SearchSet& search,
                                            const pb::ResultOptions& result_options = {},
                                            uint32_t max_results = 0);
  // Removes frame `frame_id` from a map (keyframe culling); returns {frame_id}. NOT_FOUND for an
  // unknown map or frame.
  Result<std::vector<uint64_t>> RemoveFrame(const std::string& map, uint64_t frame_id,
                                            const std::string& request_id = {});
  // Removes every frame added with `client_frame_id` and returns their ids. NOT_FOUND for an
  // unknown map or when no frame has that client id.
  Result<std::vector<uint64_t>> RemoveFramesByClientId(const std::string& map,
                                                       const std::string& client_frame_id,
                                                       const std::string& request_id = {});

  // --- Objects ---

  // The known objects a frame shows (the frame needs intrinsics), best first. `detection_options`
  // asks each detection for its inlier 2D-3D correspondences and its pose covariance (for a SLAM
  // that inserts objects as landmarks); by default neither. With `explain`, the response's
  // `explanations` say where every object of the filter dropped out.
  Result<pb::RecognizeObjectsResponse> RecognizeObjects(
      const pb::Frame& frame, const pb::ObjectFilter& filter = {},
      const pb::DetectionOptions& detection_options = {}, bool explain = false);

  // --- Model repository ---

  // Uploads a model file (.robj) as a new version of `name` ("" = the name inside the file),
  // with `tags`; returns the version created. INVALID_ARGUMENT for an empty file.
  Result<pb::ModelInfo> UploadModel(std::string_view file_bytes, const std::string& name = {},
                                    const std::vector<std::string>& tags = {},
                                    const std::string& request_id = {});
  // The same for a file on disk (read whole: models are at most 256 MiB). NOT_FOUND.
  Result<pb::ModelInfo> UploadModelFile(const std::string& path, const std::string& name = {},
                                        const std::vector<std::string>& tags = {},
                                        const std::string& request_id = {});
  // Downloads `version` of a model (0 = the latest) to `path` (replaced if it exists), verified
  // and resumable as the header comment describes; returns the version's info. NOT_FOUND,
  // DATA_LOSS when the file does not verify even when fetched from the start,
  // FAILED_PRECONDITION when the file cannot be written.
  Result<pb::ModelInfo> DownloadModel(const std::string& name, uint32_t version,
                                      const std::string& path);
  // The latest version of every model that passes the filter, by name (all pages).
  Result<std::vector<pb::ModelInfo>> ListModels(const ModelFilter& filter = {});
  // Deletes every version of a model; returns how many there were. NOT_FOUND.
  Result<uint32_t> DeleteModel(const std::string& name, const std::string& request_id = {});
  // Streams every change to the models whose names start with `name_prefix` ("" = all) from now
  // on: `on_change` gets each upload and deletion, in order. The server registers the watcher
  // shortly after the call starts; changes before that are not reported, unless
  // `include_existing`: then every version stored at that moment comes first (as
  // MODEL_CHANGE_PUT), then MODEL_CHANGE_SYNCED, then the changes since, none missed or repeated.
  // `on_end`, when given, is called once with the stream's final status (as Wait() returns it)
  // on a gRPC thread, after the last `on_change`.
  std::unique_ptr<ModelWatch> WatchModels(
      const std::string& name_prefix, std::function<void(const pb::WatchModelsResponse&)> on_change,
      bool include_existing = false, std::function<void(const grpc::Status&)> on_end = {});

  // --- Operation ---

  // The server's health (grpc.health.v1 Check of the whole server): SERVING once its store is
  // open, NOT_SERVING while it opens or drains. One attempt, the unary deadline, no retries
  // (a probe); UNAVAILABLE when nothing answers.
  Result<grpc::health::v1::HealthCheckResponse::ServingStatus> CheckHealth();
  // An online checkpoint of the server's whole store (Admin.Checkpoint), written to the new
  // directory `directory` (ALREADY_EXISTS when it exists): the files arrive in `<directory>.part`,
  // are checked against the manifest's sizes, synced, and the folder is renamed into place, so
  // `directory` is either a whole checkpoint or absent. `progress(bytes, total)` (optional) is
  // called as bytes arrive. Returns the manifest. Retried from the start on UNAVAILABLE; the
  // transfer deadline applies.
  Result<pb::CheckpointManifest> DownloadCheckpoint(
      const std::string& directory, const std::function<void(uint64_t, uint64_t)>& progress = {});
  // Has the server check every file of its store now (Admin.Verify) at `mib_per_second` (0: the
  // server's default); DATA_LOSS when it found damage. The transfer deadline applies; no retries.
  Result<pb::VerifyResponse> VerifyStore(uint32_t mib_per_second = 0);
  // What a point-in-time recovery at the server's start-up lost and how the last check of its
  // store's files went (Admin.StoreStatus).
  Result<pb::StoreStatusResponse> GetStoreStatus();

 private:
  template <class Rpc>
  friend class BasicFrameStream;
  using Deadline = std::chrono::system_clock::time_point;

  RecognitionClient(const ClientOptions& options, std::string token,
                    std::shared_ptr<grpc::Channel> channel);

  // RemoveFrame and RemoveFramesByClientId.
  Result<std::vector<uint64_t>> RemoveFrames(pb::RemoveFrameRequest request,
                                             const std::string& request_id);
  // Sets the bearer token and, when given, the deadline.
  void PrepareContext(grpc::ClientContext& context, const Deadline* deadline) const;
  // A prepared context for one unary call, with the unary deadline and, when `map` is given, the
  // routing header of that place map (wire/routing.h).
  std::unique_ptr<grpc::ClientContext> UnaryContext(const std::string* map = nullptr) const;
  // Whether a transfer stream that failed with `status` after data flowed may be resumed or
  // restarted: UNAVAILABLE (the connection broke, the server went away).
  static bool Resumable(const grpc::Status& status);

  const ClientOptions options_;
  const std::string token_;  // the bearer token from options_.token or token_file; "" = none
  const std::shared_ptr<grpc::Channel> channel_;
  const std::unique_ptr<pb::PlaceRecognition::Stub> places_;
  const std::unique_ptr<pb::ObjectRecognition::Stub> objects_;
  const std::unique_ptr<pb::ObjectRepository::Stub> models_;
  const std::unique_ptr<pb::Admin::Stub> admin_;
  const std::unique_ptr<grpc::health::v1::Health::Stub> health_;
};

}  // namespace recog::client
