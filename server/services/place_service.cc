#include "server/services/place_service.h"

#include <algorithm>
#include <chrono>
#include <optional>

#include <spdlog/spdlog.h>

#include "core/common/elapsed.h"
#include "core/place/map_search.h"
#include "server/api/frame_decoding.h"
#include "server/api/place_converters.h"
#include "server/api/prepared_frame.h"
#include "server/services/call.h"
#include "server/services/frame_stream.h"

namespace recog::server {
namespace {

constexpr char kPlaceService[] = "/recognition.v1.PlaceRecognition/";
constexpr size_t kDefaultPageSize = 100, kMaxPageSize = 1000;
constexpr size_t kMaxSearchMaps = 100;    // maps a query may search besides its own
constexpr int kMaxRelocalizeFrames = 10;  // frames of one Relocalize

using SearchSet = std::vector<std::shared_ptr<PlaceMap>>;

std::string PlaceMethod(const char* name) { return std::string(kPlaceService) + name; }

// What a frame does to its map.
enum class FrameMode {
  kAdd,     // PlaceMap::Add (AddFrame)
  kDetect,  // PlaceMap::Detect (StreamFrames, QueryPlace add_frame)
  kQuery,   // PlaceMap::Query (QueryPlace, query-only streams)
};

void FillMapInfo(const ServerState& state, const PlaceMap& map, pb::MapInfo* out) {
  const MapInfo& info = map.info();
  out->set_name(map.name());
  out->set_id(info.id);
  ToProto(map.params(), out->mutable_settings());
  if (!map.group().empty()) out->mutable_settings()->set_group(map.group());
  ToProto(map.rig(), out->mutable_settings());
  out->mutable_settings()->set_keep_thumbnails(state.thumbnails->Enabled(info.id));
  out->set_frames(map.frames());
  out->set_next_frame_id(map.next_frame_id());
  out->set_created_unix_ms(info.created_unix_ms);
  char checksum[19];
  std::snprintf(checksum, sizeof(checksum), "0x%016llx",
                static_cast<unsigned long long>(info.config.vocabulary_checksum));
  out->set_vocabulary_checksum(checksum);
}

// Where every map-scoped call starts: names the map in the call's log line and checks that this
// server owns it (FAILED_PRECONDITION otherwise, see CheckMapOwner).
Status ScopeCall(const ServerState& state, CallInfo& call, const std::string& name) {
  call.map = name;
  return CheckMapOwner(state, name);
}

// A new map's keep_thumbnails setting (a failure to store it is logged: the map is created, and
// its MapInfo says that it keeps none).
void ApplyThumbnailSetting(ServerState& state, const PlaceMap& map,
                           const pb::MapSettings& settings) {
  if (!settings.keep_thumbnails()) return;
  const Status enabled = state.thumbnails->Enable(map.info().id);
  if (!enabled.ok())
    spdlog::warn("map '{}' keeps no thumbnails: {}", map.name(), enabled.ToString());
}

// What creating map `name` in `group` ("" for none) needs: ScopeCall, the group placed on this
// shard too, and the caller's write right on the map.
Status CheckCreation(const ServerState& state, CallInfo& call, const std::string& name,
                     const std::string& group) {
  RECOG_RETURN_IF_ERROR(ScopeCall(state, call, name));
  if (!group.empty()) RECOG_RETURN_IF_ERROR(CheckGroupOwner(state, group));
  return TokenAuthenticator::CheckMap(call.caller, Right::kWrite, name, group);
}

// ScopeCall, then the map (NOT_FOUND when there is none), if the caller holds `right` on it
// (PERMISSION_DENIED naming it otherwise: TokenAuthenticator::CheckMap).
StatusOr<std::shared_ptr<PlaceMap>> CallMap(const ServerState& state, CallInfo& call,
                                            const std::string& name, Right right) {
  RECOG_RETURN_IF_ERROR(ScopeCall(state, call, name));
  RECOG_ASSIGN_OR_RETURN(std::shared_ptr<PlaceMap> map, state.maps->Get(name));
  RECOG_RETURN_IF_ERROR(TokenAuthenticator::CheckMap(call.caller, right, name, map->group()));
  return map;
}

// The Replay of a mutating call on map `name`: its rights (CallMap) are checked before the request
// log answers a repeat or refuses a reused request_id.
Replay MapReplay(ServerState& state, std::string request_id,
                 const google::protobuf::Message& request, std::string name, Right right) {
  return {std::move(request_id), &request, [&state, name = std::move(name), right](CallInfo& call) {
            return CallMap(state, call, name, right).status();
          }};
}

// The maps a query searches besides `own` (its search_maps and search_group; PlaceMap::Query on
// each, SearchMaps): NOT_FOUND naming an unknown map or group, PERMISSION_DENIED naming a map the
// caller may not read, FAILED_PRECONDITION on a shard for a map or group placed elsewhere (a
// search never leaves out a map silently), INVALID_ARGUMENT beyond kMaxSearchMaps. The own map is
// left out (its loops are the frame's result), and so are repeats.
template <typename Names>
StatusOr<SearchSet> ResolveSearchSet(const ServerState& state, const Caller& caller,
                                     const std::string& own, const Names& names,
                                     const std::string& group) {
  SearchSet maps;
  const auto add = [&](std::shared_ptr<PlaceMap> map) -> Status {
    RECOG_RETURN_IF_ERROR(
        TokenAuthenticator::CheckMap(caller, Right::kRead, map->name(), map->group()));
    if (map->has_rig() && map->name() != own) {
      return Status::InvalidArgument("map '" + map->name() +
                                     "' is a rig map: rig maps are not searched across maps");
    }
    const bool listed = std::any_of(maps.begin(), maps.end(),
                                    [&](const auto& m) { return m->name() == map->name(); });
    if (map->name() != own && !listed) maps.push_back(std::move(map));
    return Status::Ok();
  };
  for (const std::string& name : names) {
    RECOG_RETURN_IF_ERROR(CheckMapOwner(state, name));
    RECOG_ASSIGN_OR_RETURN(std::shared_ptr<PlaceMap> map, state.maps->Get(name));
    RECOG_RETURN_IF_ERROR(add(std::move(map)));
  }
  if (!group.empty()) {
    RECOG_RETURN_IF_ERROR(CheckGroupOwner(state, group));
    RECOG_ASSIGN_OR_RETURN(SearchSet members, state.maps->Group(group));
    for (std::shared_ptr<PlaceMap>& map : members) RECOG_RETURN_IF_ERROR(add(std::move(map)));
  }
  if (maps.size() > kMaxSearchMaps) {
    return Status::InvalidArgument("a query may search at most " + std::to_string(kMaxSearchMaps) +
                                   " maps" + (own.empty() ? "" : " besides its own") + ", not " +
                                   std::to_string(maps.size()));
  }
  return maps;
}

// The group a map is created in (settings.group, when set).
std::string GroupOf(const pb::MapSettings& settings) {
  return settings.has_group() ? settings.group() : std::string();
}

// Creates place map `name` for `call`, the one way both CreateMap and a stream's
// create_if_missing do: CheckCreation, `settings` over the server's defaults (ApplyMapSettings),
// the rig, MapRegistry::Create, the keep_thumbnails setting and the map's entries gauge (at 0).
// ALREADY_EXISTS when the map is there, also when another call created it since this one looked:
// CreateMap answers that, a stream takes the map that is there (PlaceFrameStream::Configure).
StatusOr<std::shared_ptr<PlaceMap>> CreatePlaceMap(ServerState& state, CallInfo& call,
                                                   const std::string& name,
                                                   const pb::MapSettings& settings) {
  const std::string group = GroupOf(settings);
  RECOG_RETURN_IF_ERROR(CheckCreation(state, call, name, group));
  LoopDetectorParams params = state.config.place;
  RECOG_RETURN_IF_ERROR(ApplyMapSettings(settings, &params));
  RECOG_ASSIGN_OR_RETURN(std::vector<RigCamera> rig, RigFromProto(settings));
  RECOG_ASSIGN_OR_RETURN(std::shared_ptr<PlaceMap> map,
                         state.maps->Create(name, params, group, rig));
  ApplyThumbnailSetting(state, *map, settings);
  state.metrics.SetMapEntries(name, 0);
  return map;
}

// The worker's place feature extractor, for PreparedFrame.
ExtractPlaceFeatures PlaceExtractor(WorkerContext& worker) {
  return [&worker](const cv::Mat& image, FeatureSet* out) {
    return worker.ExtractPlaceFeatures(image, out);
  };
}

StatusOr<PlaceFrameResult> RunMode(PlaceMap& map, FrameMode mode, const FeatureSet& features,
                                   const DecodedFrame& frame, const PlaceResultOptions& extras,
                                   const FrameGeometry* geometry) {
  const std::optional<double> timestamp = frame.timestamp;
  switch (mode) {
    case FrameMode::kAdd:
      return map.Add(features, timestamp, frame.client_frame_id, geometry);
    case FrameMode::kDetect:
      return map.Detect(features, timestamp, extras, frame.client_frame_id, geometry,
                        frame.excluded_frames);
    case FrameMode::kQuery:
      break;
  }
  return map.Query(features, extras, geometry, frame.excluded_frames);
}

// What a rig map refuses of a request (INVALID_ARGUMENT): the options of single-camera loops,
// and other maps to search. OK for a map without a rig.
Status CheckRigRequest(const PlaceMap& map, const pb::ResultOptions& options,
                       const SearchSet& search) {
  if (!map.has_rig()) return Status::Ok();
  if (options.top_k() > 0 || options.include_fundamental() || options.include_relative_pose()) {
    return Status::InvalidArgument(
        "map '" + map.name() + "' is a rig map: options.top_k, include_fundamental and " +
        "include_relative_pose are for single-camera maps (a rig loop's body pose is in " +
        "LoopResult.rig)");
  }
  if (!search.empty()) {
    return Status::InvalidArgument("map '" + map.name() + "' is a rig map: its frames are " +
                                   "not looked up in other maps (search_maps, search_group)");
  }
  return Status::Ok();
}

// A rig frame against a rig map (RunPlaceFrame's rig half): `num_features` over every camera.
Status RunRigFrame(ServerState& state, WorkerContext& worker, PlaceMap& map, FrameMode mode,
                   const pb::Frame& request, const pb::ResultOptions& options, pb::LoopResult* out,
                   pb::Timing* timing, uint32_t* num_features) {
  PixelBudget budget = CallPixelBudget(state);
  RECOG_ASSIGN_OR_RETURN(
      PreparedRigFrame prepared,
      PreparedRigFrame::Prepare(request, map, PlaceExtractor(worker), budget, timing));
  if (num_features != nullptr) *num_features = uint32_t(prepared.features());
  const auto start = std::chrono::steady_clock::now();
  const std::vector<uint64_t> excluded = prepared.excluded();
  const bool correspondences = options.include_correspondences();
  StatusOr<RigPlaceResult> result = mode == FrameMode::kAdd ? map.AddRig(prepared.frame())
                                    : mode == FrameMode::kDetect
                                        ? map.DetectRig(prepared.frame(), correspondences, excluded)
                                        : map.QueryRig(prepared.frame(), correspondences, excluded);
  if (!result.ok()) return result.status();
  state.metrics.AddFrames(FrameKind::kPlace);
  if (mode != FrameMode::kAdd && result->loop.status == RigLoopStatus::kLoopDetected) {
    state.metrics.AddLoopDetections();
  }
  if (mode != FrameMode::kQuery) state.metrics.SetMapEntries(map.name(), map.frames());
  ToProto(result.value(), map.rig(), out);
  timing->set_recognition_ms(timing->recognition_ms() + MillisecondsSince(start));
  return Status::Ok();
}

// What the web console keeps of a frame its map stored (Add or Detect): the frame's thumbnail when
// the map keeps them (written in the background), and the loop it closed, with its inliers, when
// the console is on. A failure here does not fail the frame, which the map holds already: it is
// logged.
void KeepForConsole(ServerState& state, const PlaceMap& map, const PreparedFrame& prepared,
                    const PlaceFrameResult& result) {
  const uint32_t map_id = map.info().id;
  const LoopResult& loop = result.loop;
  if (loop.entry == kInvalidEntryId) return;  // the map did not keep the frame
  const Status queued = state.thumbnails->Keep(map_id, loop.entry, prepared.frame().image);
  if (!queued.ok()) spdlog::warn("map '{}': {}", map.name(), queued.ToString());
  if (state.recent_loops == nullptr || loop.status != LoopStatus::kLoopDetected) return;
  RecordedLoop recorded;
  recorded.frame_id = loop.entry;
  recorded.match_frame_id = loop.match;
  recorded.unix_ms = std::chrono::duration_cast<std::chrono::milliseconds>(
                         std::chrono::system_clock::now().time_since_epoch())
                         .count();
  recorded.score = loop.score;
  recorded.normalized_score = loop.normalized_score;
  recorded.inliers = uint32_t(loop.inliers.size());
  recorded.frame_size = prepared.frame().image.size();
  recorded.pairs.reserve(result.correspondences.size());
  for (const PlaceCorrespondence& c : result.correspondences) {
    recorded.pairs.emplace_back(c.query_pixel.x, c.query_pixel.y, c.match_pixel.x, c.match_pixel.y);
  }
  state.recent_loops->Record(map.name(), std::move(recorded));
}

// A removed frame's thumbnail (a failure is logged: the frame is gone already).
void ForgetThumbnail(ServerState& state, const PlaceMap& map, uint64_t frame_id) {
  const Status removed = state.thumbnails->RemoveFrame(map.info().id, frame_id);
  if (!removed.ok())
    spdlog::warn("map '{}': thumbnail of frame {} not removed: {}", map.name(), frame_id,
                 removed.ToString());
}

// A deleted map's thumbnails and recent loops (a failure is logged: the map is gone already).
void ForgetConsoleRecords(ServerState& state, const std::string& map, uint32_t map_id) {
  const Status removed = state.thumbnails->RemoveMap(map_id);
  if (!removed.ok()) spdlog::warn("map '{}': thumbnails not removed: {}", map, removed.ToString());
  if (state.recent_loops != nullptr) state.recent_loops->Forget(map);
}

// Decodes one frame, runs it against the map, looks it up in the `search` maps, and encodes what
// it did (`inter_map` may be null when `search` is empty). `num_features` reports an added
// frame's features.
Status RunPlaceFrame(ServerState& state, WorkerContext& worker, PlaceMap& map, FrameMode mode,
                     const pb::Frame& request, const pb::ResultOptions& options,
                     pb::LoopResult* out, pb::Timing* timing, uint32_t* num_features = nullptr,
                     const SearchSet& search = {},
                     google::protobuf::RepeatedPtrField<pb::InterMapMatch>* inter_map = nullptr) {
  if (map.has_rig()) {
    RECOG_RETURN_IF_ERROR(CheckRigRequest(map, options, search));
    return RunRigFrame(state, worker, map, mode, request, options, out, timing, num_features);
  }
  PixelBudget budget = CallPixelBudget(state);
  RECOG_ASSIGN_OR_RETURN(PreparedFrame prepared,
                         PreparedFrame::Prepare(request, map.vocabulary().info().descriptor,
                                                PlaceExtractor(worker), budget, timing));
  const FeatureSet& features = prepared.features();
  if (num_features != nullptr) *num_features = uint32_t(features.size());
  const auto start = std::chrono::steady_clock::now();
  PlaceResultOptions extras = prepared.Extras(options);
  // The console shows a detected loop's inliers: asked for whenever it records loops.
  const bool recording = state.recent_loops != nullptr && mode == FrameMode::kDetect;
  extras.include_correspondences = extras.include_correspondences || recording;
  StatusOr<PlaceFrameResult> result =
      RunMode(map, mode, features, prepared.frame(), extras, prepared.geometry());
  if (!result.ok()) return result.status();
  if (mode != FrameMode::kQuery) KeepForConsole(state, map, prepared, result.value());
  if (!options.include_correspondences()) result->correspondences.clear();
  state.metrics.AddFrames(FrameKind::kPlace);
  if (mode != FrameMode::kAdd && result->loop.status == LoopStatus::kLoopDetected) {
    state.metrics.AddLoopDetections();
  }
  if (mode != FrameMode::kQuery) state.metrics.SetMapEntries(map.name(), map.frames());
  ToProto(result.value(), out);
  if (!search.empty()) {
    StatusOr<std::vector<MapMatch>> matches =
        SearchMaps(search, features, extras, prepared.geometry());
    if (!matches.ok()) return matches.status();
    for (const MapMatch& match : matches.value()) {
      pb::InterMapMatch* found = inter_map->Add();
      found->set_map(match.map);
      ToProto(match.result, found->mutable_result());
    }
  }
  timing->set_recognition_ms(timing->recognition_ms() + MillisecondsSince(start));
  return Status::Ok();
}

// StreamFrames: config (map, creation, query-only), then the loop detector on every frame.
class PlaceFrameStream final
    : public FrameStream<pb::StreamFramesRequest, pb::StreamFramesResponse> {
 public:
  PlaceFrameStream(ServerState& state, grpc::CallbackServerContext* context)
      : FrameStream(state, context, PlaceMethod("StreamFrames"), "StreamFrames") {}

 private:
  Status Configure(const pb::StreamFramesRequest& first) override {
    if (!first.has_config()) {
      return Status::FailedPrecondition("the first message of StreamFrames must be a StreamConfig");
    }
    const pb::StreamConfig& config = first.config();
    const Right right = config.query_only() ? Right::kRead : Right::kWrite;
    StatusOr<std::shared_ptr<PlaceMap>> map = CallMap(state_, call_, config.map(), right);
    // A missing map may be created below; any other refusal (not this shard's map) ends here.
    if (!map.ok() && map.status().code() != StatusCode::kNotFound) return map.status();
    mode_ = config.query_only() ? FrameMode::kQuery : FrameMode::kDetect;
    options_ = config.options();
    RECOG_RETURN_IF_ERROR(FromProto(options_, std::nullopt).Validate());
    RECOG_ASSIGN_OR_RETURN(search_, ResolveSearchSet(state_, call_.caller, config.map(),
                                                     config.search_maps(), config.search_group()));
    if (!map.ok() && config.create_if_missing() && !config.query_only()) {
      map = CreatePlaceMap(state_, call_, config.map(), config.settings());
      if (map.status().code() == StatusCode::kAlreadyExists) {
        // Created by another call since CallMap looked: the stream writes to it like to any map
        // that was there (its settings are that map's, not the config's).
        map = CallMap(state_, call_, config.map(), right);
      }
    }
    if (!map.ok()) return map.status();
    map_ = std::move(map).value();
    return CheckRigRequest(*map_, options_, search_);
  }

  Status Answer(const pb::Frame& frame, WorkerContext& worker,
                pb::StreamFramesResponse* response) override {
    return RunPlaceFrame(state_, worker, *map_, mode_, frame, options_, response->mutable_result(),
                         response->mutable_timing(), nullptr, search_,
                         response->mutable_inter_map());
  }

  std::shared_ptr<PlaceMap> map_;
  SearchSet search_;  // the maps every frame is also looked up in
  FrameMode mode_ = FrameMode::kDetect;
  pb::ResultOptions options_;
};

// Relocalize: every frame prepared, then looked up in every map of the set (core Relocalize).
Status RunRelocalize(ServerState& state, WorkerContext& worker, const Caller& caller,
                     const pb::RelocalizeRequest& request, pb::RelocalizeResponse* response) {
  if (request.frames_size() < 1 || request.frames_size() > kMaxRelocalizeFrames) {
    return Status::InvalidArgument("frames: Relocalize takes 1 to " +
                                   std::to_string(kMaxRelocalizeFrames) + " frames, not " +
                                   std::to_string(request.frames_size()));
  }
  RECOG_ASSIGN_OR_RETURN(SearchSet maps,
                         ResolveSearchSet(state, caller, "", request.maps(), request.group()));
  if (maps.empty()) return Status::InvalidArgument("Relocalize needs maps or a group to search");
  pb::Timing* timing = response->mutable_timing();
  std::vector<PreparedFrame> prepared;
  prepared.reserve(size_t(request.frames_size()));
  PixelBudget budget = CallPixelBudget(state);  // every frame's images together
  const ExtractPlaceFeatures extract = PlaceExtractor(worker);
  for (int i = 0; i < request.frames_size(); ++i) {
    StatusOr<PreparedFrame> frame = PreparedFrame::Prepare(
        request.frames(i), maps.front()->vocabulary().info().descriptor, extract, budget, timing);
    if (!frame.ok()) return frame.status().WithContext("frames[" + std::to_string(i) + "]");
    prepared.push_back(std::move(frame).value());
  }
  std::vector<RelocalizationFrame> frames;
  frames.reserve(prepared.size());
  for (const PreparedFrame& p : prepared) {
    frames.push_back({&p.features(), p.geometry()});
  }
  const auto start = std::chrono::steady_clock::now();
  // Frames of one request share their options; the intrinsics for relative poses are the first's.
  RECOG_ASSIGN_OR_RETURN(std::vector<Relocalization> found,
                         Relocalize(maps, frames, prepared.front().Extras(request.options())));
  timing->set_recognition_ms(timing->recognition_ms() + MillisecondsSince(start));
  state.metrics.AddFrames(FrameKind::kPlace, prepared.size());
  const size_t limit = request.max_results() == 0 ? found.size() : request.max_results();
  for (size_t i = 0; i < found.size() && i < limit; ++i) {
    pb::Relocalization* place = response->add_places();
    place->set_map(found[i].map);
    place->set_frame_index(uint32_t(found[i].frame_index));
    place->set_client_frame_id(request.frames(int(found[i].frame_index)).client_frame_id());
    place->set_frames_recognised(uint32_t(found[i].frames_recognised));
    ToProto(found[i].result, place->mutable_result());
  }
  return Status::Ok();
}

}  // namespace

grpc::ServerUnaryReactor* PlaceService::CreateMap(grpc::CallbackServerContext* context,
                                                  const pb::CreateMapRequest* request,
                                                  pb::CreateMapResponse* response) {
  const Replay replay{request->request_id(), request, [this, request](CallInfo& call) {
                        return CheckCreation(state_, call, request->name(),
                                             GroupOf(request->settings()));
                      }};
  return RunUnary(state_, context, PlaceMethod("CreateMap"), Right::kWrite, replay, response,
                  [=, this](CallInfo& call, WorkerContext&) {
                    RECOG_ASSIGN_OR_RETURN(
                        std::shared_ptr<PlaceMap> map,
                        CreatePlaceMap(state_, call, request->name(), request->settings()));
                    FillMapInfo(state_, *map, response->mutable_map());
                    return Status::Ok();
                  });
}

grpc::ServerUnaryReactor* PlaceService::GetMap(grpc::CallbackServerContext* context,
                                               const pb::GetMapRequest* request,
                                               pb::GetMapResponse* response) {
  return RunUnary(state_, context, PlaceMethod("GetMap"), Right::kRead, *request,
                  [=, this](CallInfo& call, WorkerContext&) {
                    RECOG_ASSIGN_OR_RETURN(std::shared_ptr<PlaceMap> map,
                                           CallMap(state_, call, request->name(), Right::kRead));
                    FillMapInfo(state_, *map, response->mutable_map());
                    return Status::Ok();
                  });
}

grpc::ServerUnaryReactor* PlaceService::ListMaps(grpc::CallbackServerContext* context,
                                                 const pb::ListMapsRequest* request,
                                                 pb::ListMapsResponse* response) {
  return RunUnary(state_, context, PlaceMethod("ListMaps"), Right::kRead, *request,
                  [=, this](CallInfo& call, WorkerContext&) {
                    size_t page_size =
                        request->page_size() == 0 ? kDefaultPageSize : request->page_size();
                    page_size = std::min(page_size, kMaxPageSize);
                    const std::string& after = request->page_token();  // last name of the page
                    size_t added = 0;
                    for (const std::shared_ptr<PlaceMap>& map : state_.maps->List()) {
                      if (!after.empty() && map->name() <= after) continue;
                      if (!call.caller.readable_maps.Covers(map->name(), map->group())) continue;
                      if (added == page_size) {
                        response->set_next_page_token(response->maps(int(added) - 1).name());
                        break;
                      }
                      FillMapInfo(state_, *map, response->add_maps());
                      ++added;
                    }
                    return Status::Ok();
                  });
}

grpc::ServerUnaryReactor* PlaceService::DeleteMap(grpc::CallbackServerContext* context,
                                                  const pb::DeleteMapRequest* request,
                                                  pb::DeleteMapResponse* response) {
  return RunUnary(
      state_, context, PlaceMethod("DeleteMap"), Right::kWrite,
      MapReplay(state_, request->request_id(), *request, request->name(), Right::kWrite), response,
      [=, this](CallInfo& call, WorkerContext&) {
        RECOG_ASSIGN_OR_RETURN(std::shared_ptr<PlaceMap> map,
                               CallMap(state_, call, request->name(), Right::kWrite));
        const uint32_t map_id = map->info().id;
        RECOG_ASSIGN_OR_RETURN(const size_t frames, state_.maps->Delete(request->name()));
        ForgetConsoleRecords(state_, request->name(), map_id);
        response->set_frames_deleted(frames);
        state_.metrics.RemoveMap(request->name());
        return Status::Ok();
      });
}

grpc::ServerUnaryReactor* PlaceService::AddFrame(grpc::CallbackServerContext* context,
                                                 const pb::AddFrameRequest* request,
                                                 pb::AddFrameResponse* response) {
  return RunUnary(
      state_, context, PlaceMethod("AddFrame"), Right::kWrite,
      MapReplay(state_, request->request_id(), *request, request->map(), Right::kWrite), response,
      [=, this](CallInfo& call, WorkerContext& worker) {
        RECOG_ASSIGN_OR_RETURN(std::shared_ptr<PlaceMap> map,
                               CallMap(state_, call, request->map(), Right::kWrite));
        pb::LoopResult added;
        uint32_t num_features = 0;
        RECOG_RETURN_IF_ERROR(RunPlaceFrame(state_, worker, *map, FrameMode::kAdd, request->frame(),
                                            {}, &added, response->mutable_timing(), &num_features));
        response->mutable_timing()->set_queue_ms(call.queue_ms);
        response->set_frame_id(added.frame_id());
        response->set_num_features(num_features);
        response->set_client_frame_id(request->frame().client_frame_id());
        return Status::Ok();
      });
}

grpc::ServerUnaryReactor* PlaceService::QueryPlace(grpc::CallbackServerContext* context,
                                                   const pb::QueryPlaceRequest* request,
                                                   pb::QueryPlaceResponse* response) {
  const Right right = request->add_frame() ? Right::kWrite : Right::kRead;
  return RunUnary(
      state_, context, PlaceMethod("QueryPlace"), right,
      // Only a query that adds its frame changes the map: a relocalisation query just runs again.
      MapReplay(state_, request->add_frame() ? request->request_id() : std::string(), *request,
                request->map(), right),
      response, [=, this](CallInfo& call, WorkerContext& worker) {
        RECOG_ASSIGN_OR_RETURN(std::shared_ptr<PlaceMap> map,
                               CallMap(state_, call, request->map(), right));
        const FrameMode mode = request->add_frame() ? FrameMode::kDetect : FrameMode::kQuery;
        RECOG_ASSIGN_OR_RETURN(SearchSet search,
                               ResolveSearchSet(state_, call.caller, request->map(),
                                                request->search_maps(), request->search_group()));
        RECOG_RETURN_IF_ERROR(RunPlaceFrame(state_, worker, *map, mode, request->frame(),
                                            request->options(), response->mutable_result(),
                                            response->mutable_timing(), nullptr, search,
                                            response->mutable_inter_map()));
        response->set_client_frame_id(request->frame().client_frame_id());
        response->mutable_timing()->set_queue_ms(call.queue_ms);
        return Status::Ok();
      });
}

grpc::ServerUnaryReactor* PlaceService::RemoveFrame(grpc::CallbackServerContext* context,
                                                    const pb::RemoveFrameRequest* request,
                                                    pb::RemoveFrameResponse* response) {
  return RunUnary(
      state_, context, PlaceMethod("RemoveFrame"), Right::kWrite,
      MapReplay(state_, request->request_id(), *request, request->map(), Right::kWrite), response,
      [=, this](CallInfo& call, WorkerContext&) {
        RECOG_ASSIGN_OR_RETURN(std::shared_ptr<PlaceMap> map,
                               CallMap(state_, call, request->map(), Right::kWrite));
        switch (request->frame_case()) {
          case pb::RemoveFrameRequest::kFrameId: {
            if (request->frame_id() >= kInvalidEntryId) {
              return Status::NotFound("map '" + request->map() + "' has no frame " +
                                      std::to_string(request->frame_id()));
            }
            RECOG_RETURN_IF_ERROR(map->RemoveFrame(EntryId(request->frame_id())));
            response->add_removed_frame_ids(request->frame_id());
            ForgetThumbnail(state_, *map, request->frame_id());
            break;
          }
          case pb::RemoveFrameRequest::kClientFrameId: {
            RECOG_ASSIGN_OR_RETURN(std::vector<EntryId> removed,
                                   map->RemoveFramesByClientId(request->client_frame_id()));
            for (EntryId id : removed) {
              response->add_removed_frame_ids(id);
              ForgetThumbnail(state_, *map, id);
            }
            break;
          }
          case pb::RemoveFrameRequest::FRAME_NOT_SET:
            return Status::InvalidArgument("RemoveFrame needs a frame_id or a client_frame_id");
        }
        state_.metrics.SetMapEntries(map->name(), map->frames());
        return Status::Ok();
      });
}

grpc::ServerUnaryReactor* PlaceService::Relocalize(grpc::CallbackServerContext* context,
                                                   const pb::RelocalizeRequest* request,
                                                   pb::RelocalizeResponse* response) {
  return RunUnary(
      state_, context, PlaceMethod("Relocalize"), Right::kRead, *request,
      [=, this](CallInfo& call, WorkerContext& worker) {
        RECOG_RETURN_IF_ERROR(RunRelocalize(state_, worker, call.caller, *request, response));
        response->mutable_timing()->set_queue_ms(call.queue_ms);
        return Status::Ok();
      });
}

grpc::ServerBidiReactor<pb::StreamFramesRequest, pb::StreamFramesResponse>*
PlaceService::StreamFrames(grpc::CallbackServerContext* context) {
  auto* stream = new PlaceFrameStream(state_, context);
  stream->Start(Right::kRead);  // writing streams are checked for kWrite by their config
  return stream;
}

}  // namespace recog::server
