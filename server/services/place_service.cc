#include "server/services/place_service.h"

#include <algorithm>
#include <chrono>

#include "core/geometry/correspondences.h"
#include "server/api/converters.h"
#include "server/api/status_mapping.h"
#include "server/services/call.h"
#include "server/services/frame_stream.h"

namespace recog::server {
namespace {

constexpr char kService[] = "/recognition.v1.PlaceRecognition/";
constexpr size_t kDefaultPageSize = 100, kMaxPageSize = 1000;

using Clock = std::chrono::steady_clock;
double MsSince(Clock::time_point start) {
  return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

std::string Method(const char* name) { return std::string(kService) + name; }

// What a frame does to its map.
enum class FrameMode {
  kAdd,     // add without querying (AddFrame)
  kDetect,  // the loop detector's step: query, then add (StreamFrames, QueryPlace add_frame)
  kQuery,   // relocalisation query, nothing changes (QueryPlace, query-only streams)
};

// The image's features with the server's place settings, made by this worker thread's extractor.
Status ExtractPlaceFeatures(const ServerState& state, const cv::Mat& image, FeatureSet* out) {
  thread_local std::unique_ptr<FeatureExtractor> extractor;
  thread_local const ServerState* owner = nullptr;
  if (extractor == nullptr || owner != &state) {
    RECOG_ASSIGN_OR_RETURN(extractor, CreateFeatureExtractor(state.place_features));
    owner = &state;
  }
  return extractor->Extract(image, out);
}

void FillMapInfo(const PlaceMap& map, pb::MapInfo* out) {
  const MapInfo& info = map.database->info();
  out->set_name(map.name);
  out->set_id(info.id);
  ToProto(map.params, out->mutable_settings());
  out->set_frames(map.database->size());
  out->set_next_frame_id(map.database->next_entry_id());
  out->set_created_unix_ms(info.created_unix_ms);
  char checksum[19];
  std::snprintf(checksum, sizeof(checksum), "0x%016llx",
                static_cast<unsigned long long>(info.config.vocabulary_checksum));
  out->set_vocabulary_checksum(checksum);
}

// Adds what the result options ask for and the match's timestamp; needs the match's frame.
Status CompleteLoopResult(const PlaceMap& map, const DecodedFrame& frame,
                          const FeatureSet& features, const LoopResult& result,
                          const pb::ResultOptions& options, pb::LoopResult* out) {
  if (result.match == kInvalidEntryId) return Status::Ok();
  const bool verified = result.status == LoopStatus::kLoopDetected && !result.inliers.empty();
  const bool pose = options.include_relative_pose() && verified && frame.intrinsics.has_value();
  uint32_t parts = kEntryMetadata;
  if (pose) parts |= kEntryFeatures;
  StatusOr<EntryRecord> match = map.database->Get(result.match, parts);
  if (!match.ok()) {
    // The matched frame went away with its map (deleted meanwhile): answer without the extras.
    return match.status().code() == StatusCode::kNotFound ? Status::Ok() : match.status();
  }
  out->set_match_timestamp(match.value().metadata.timestamp);
  if (options.include_fundamental() && verified) {
    for (int i = 0; i < 9; ++i) out->add_fundamental(result.fundamental.val[i]);
  }
  if (pose) {
    cv::Matx33d R;
    cv::Vec3d t;
    if (RelativePoseFromFundamental(result.fundamental, frame.intrinsics->K(), features.keypoints,
                                    match.value().keypoints, result.inliers, &R, &t)) {
      ToProto(R, t, out->mutable_relative_pose());
    }
  }
  return Status::Ok();
}

// Runs one frame against a map. `frame_id`/`num_features` report an added frame.
Status RunPlaceFrame(ServerState& state, PlaceMap& map, FrameMode mode, const pb::Frame& request,
                     const pb::ResultOptions& options, pb::LoopResult* out, pb::Timing* timing,
                     uint32_t* num_features = nullptr) {
  RECOG_ASSIGN_OR_RETURN(DecodedFrame frame,
                         DecodeFrame(request, map.database->vocabulary().info().descriptor));
  timing->set_decode_ms(frame.decode_ms);
  FeatureSet extracted;
  const FeatureSet* features = &frame.features;
  if (frame.has_image()) {
    const auto start = Clock::now();
    RECOG_RETURN_IF_ERROR(ExtractPlaceFeatures(state, frame.image, &extracted));
    timing->set_features_ms(MsSince(start));
    features = &extracted;
  }
  if (num_features != nullptr) *num_features = uint32_t(features->size());
  const auto start = Clock::now();
  LoopResult result;
  if (mode == FrameMode::kQuery) {
    RECOG_ASSIGN_OR_RETURN(result, map.detector->Query(*features, frame.timestamp));
  } else {
    std::lock_guard lock(map.mutex);
    if (map.deleted) return Status::NotFound("map '" + map.name + "' was deleted");
    if (mode == FrameMode::kAdd) {
      RECOG_ASSIGN_OR_RETURN(result.entry, map.detector->Add(*features, frame.timestamp));
    } else {
      RECOG_ASSIGN_OR_RETURN(result, map.detector->Process(*features, frame.timestamp));
    }
  }
  state.metrics.AddFrames(FrameKind::kPlace);
  if (mode != FrameMode::kAdd) {
    if (result.status == LoopStatus::kLoopDetected) state.metrics.AddLoopDetections();
    ToProto(result, out);
    RECOG_RETURN_IF_ERROR(CompleteLoopResult(map, frame, *features, result, options, out));
  } else {
    out->set_frame_id(result.entry);
  }
  if (mode != FrameMode::kQuery) state.metrics.SetMapEntries(map.name, map.database->size());
  timing->set_recognition_ms(MsSince(start));
  return Status::Ok();
}

// StreamFrames: config (map, creation, query-only), then the loop detector on every frame.
class PlaceFrameStream final
    : public FrameStream<pb::StreamFramesRequest, pb::StreamFramesResponse> {
 public:
  PlaceFrameStream(ServerState& state, grpc::CallbackServerContext* context)
      : FrameStream(state, context, Method("StreamFrames"), "StreamFrames") {}

 private:
  grpc::Status Configure(const pb::StreamFramesRequest& first) override {
    if (!first.has_config()) {
      return {grpc::StatusCode::FAILED_PRECONDITION,
              "the first message of StreamFrames must be a StreamConfig"};
    }
    const pb::StreamConfig& config = first.config();
    call_.map = config.map();
    if (grpc::Status owned = CheckMapOwner(state_, call_.map); !owned.ok()) return owned;
    mode_ = config.query_only() ? FrameMode::kQuery : FrameMode::kDetect;
    if (!config.query_only()) {
      const Status allowed = TokenAuthenticator::Check(call_.caller, Right::kWrite);
      if (!allowed.ok()) return ToGrpcStatus(allowed, call_.request_id);
    }
    options_ = config.options();
    StatusOr<std::shared_ptr<PlaceMap>> map = state_.maps->Get(config.map());
    if (!map.ok() && map.status().code() == StatusCode::kNotFound && config.create_if_missing() &&
        !config.query_only()) {
      LoopDetectorParams params = state_.config.place;
      const Status settings = ApplyMapSettings(config.settings(), &params);
      if (!settings.ok()) return ToGrpcStatus(settings, call_.request_id);
      map = state_.maps->Create(config.map(), params);
      if (map.status().code() == StatusCode::kAlreadyExists) {
        map = state_.maps->Get(config.map());  // created by another stream meanwhile
      }
    }
    if (!map.ok()) return ToGrpcStatus(map.status(), call_.request_id);
    map_ = std::move(map).value();
    return grpc::Status::OK;
  }

  Status Answer(const pb::Frame& frame, pb::StreamFramesResponse* response) override {
    return RunPlaceFrame(state_, *map_, mode_, frame, options_, response->mutable_result(),
                         response->mutable_timing());
  }

  std::shared_ptr<PlaceMap> map_;
  FrameMode mode_ = FrameMode::kDetect;
  pb::ResultOptions options_;
};

}  // namespace

grpc::ServerUnaryReactor* PlaceService::CreateMap(grpc::CallbackServerContext* context,
                                                  const pb::CreateMapRequest* request,
                                                  pb::CreateMapResponse* response) {
  return RunUnary(state_, context, Method("CreateMap"), Right::kWrite, [=, this](CallInfo& call) {
    call.map = request->name();
    if (grpc::Status owned = CheckMapOwner(state_, call.map); !owned.ok()) return owned;
    LoopDetectorParams params = state_.config.place;
    RECOG_RETURN_IF_ERROR_AS_GRPC(ApplyMapSettings(request->settings(), &params), call.request_id);
    StatusOr<std::shared_ptr<PlaceMap>> map = state_.maps->Create(request->name(), params);
    if (!map.ok()) return ToGrpcStatus(map.status(), call.request_id);
    FillMapInfo(*map.value(), response->mutable_map());
    state_.metrics.SetMapEntries(request->name(), 0);
    return grpc::Status::OK;
  });
}

grpc::ServerUnaryReactor* PlaceService::GetMap(grpc::CallbackServerContext* context,
                                               const pb::GetMapRequest* request,
                                               pb::GetMapResponse* response) {
  return RunUnary(state_, context, Method("GetMap"), Right::kRead, [=, this](CallInfo& call) {
    call.map = request->name();
    if (grpc::Status owned = CheckMapOwner(state_, call.map); !owned.ok()) return owned;
    StatusOr<std::shared_ptr<PlaceMap>> map = state_.maps->Get(request->name());
    if (!map.ok()) return ToGrpcStatus(map.status(), call.request_id);
    FillMapInfo(*map.value(), response->mutable_map());
    return grpc::Status::OK;
  });
}

grpc::ServerUnaryReactor* PlaceService::ListMaps(grpc::CallbackServerContext* context,
                                                 const pb::ListMapsRequest* request,
                                                 pb::ListMapsResponse* response) {
  return RunUnary(state_, context, Method("ListMaps"), Right::kRead, [=, this](CallInfo&) {
    size_t page_size = request->page_size() == 0 ? kDefaultPageSize : request->page_size();
    page_size = std::min(page_size, kMaxPageSize);
    const std::string& after = request->page_token();  // the last name of the previous page
    size_t added = 0;
    for (const std::shared_ptr<PlaceMap>& map : state_.maps->List()) {
      if (!after.empty() && map->name <= after) continue;
      if (added == page_size) {
        response->set_next_page_token(response->maps(int(added) - 1).name());
        break;
      }
      FillMapInfo(*map, response->add_maps());
      ++added;
    }
    return grpc::Status::OK;
  });
}

grpc::ServerUnaryReactor* PlaceService::DeleteMap(grpc::CallbackServerContext* context,
                                                  const pb::DeleteMapRequest* request,
                                                  pb::DeleteMapResponse* response) {
  return RunUnary(state_, context, Method("DeleteMap"), Right::kWrite, [=, this](CallInfo& call) {
    call.map = request->name();
    if (grpc::Status owned = CheckMapOwner(state_, call.map); !owned.ok()) return owned;
    StatusOr<size_t> frames = state_.maps->Delete(request->name());
    if (!frames.ok()) return ToGrpcStatus(frames.status(), call.request_id);
    response->set_frames_deleted(frames.value());
    state_.metrics.RemoveMap(request->name());
    return grpc::Status::OK;
  });
}

grpc::ServerUnaryReactor* PlaceService::AddFrame(grpc::CallbackServerContext* context,
                                                 const pb::AddFrameRequest* request,
                                                 pb::AddFrameResponse* response) {
  return RunUnary(state_, context, Method("AddFrame"), Right::kWrite, [=, this](CallInfo& call) {
    call.map = request->map();
    if (grpc::Status owned = CheckMapOwner(state_, call.map); !owned.ok()) return owned;
    StatusOr<std::shared_ptr<PlaceMap>> map = state_.maps->Get(request->map());
    if (!map.ok()) return ToGrpcStatus(map.status(), call.request_id);
    pb::LoopResult added;
    uint32_t num_features = 0;
    RECOG_RETURN_IF_ERROR_AS_GRPC(
        RunPlaceFrame(state_, *map.value(), FrameMode::kAdd, request->frame(), {}, &added,
                      response->mutable_timing(), &num_features),
        call.request_id);
    response->mutable_timing()->set_queue_ms(call.queue_ms);
    response->set_frame_id(added.frame_id());
    response->set_num_features(num_features);
    response->set_client_frame_id(request->frame().client_frame_id());
    return grpc::Status::OK;
  });
}

grpc::ServerUnaryReactor* PlaceService::QueryPlace(grpc::CallbackServerContext* context,
                                                   const pb::QueryPlaceRequest* request,
                                                   pb::QueryPlaceResponse* response) {
  const Right right = request->add_frame() ? Right::kWrite : Right::kRead;
  return RunUnary(state_, context, Method("QueryPlace"), right, [=, this](CallInfo& call) {
    call.map = request->map();
    if (grpc::Status owned = CheckMapOwner(state_, call.map); !owned.ok()) return owned;
    StatusOr<std::shared_ptr<PlaceMap>> map = state_.maps->Get(request->map());
    if (!map.ok()) return ToGrpcStatus(map.status(), call.request_id);
    const FrameMode mode = request->add_frame() ? FrameMode::kDetect : FrameMode::kQuery;
    RECOG_RETURN_IF_ERROR_AS_GRPC(
        RunPlaceFrame(state_, *map.value(), mode, request->frame(), request->options(),
                      response->mutable_result(), response->mutable_timing()),
        call.request_id);
    response->set_client_frame_id(request->frame().client_frame_id());
    response->mutable_timing()->set_queue_ms(call.queue_ms);
    return grpc::Status::OK;
  });
}

grpc::ServerBidiReactor<pb::StreamFramesRequest, pb::StreamFramesResponse>*
PlaceService::StreamFrames(grpc::CallbackServerContext* context) {
  auto* stream = new PlaceFrameStream(state_, context);
  stream->Start(Right::kRead);  // writing streams are checked for kWrite by their config
  return stream;
}

}  // namespace recog::server
