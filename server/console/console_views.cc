#include "server/console/console_views.h"

#include <algorithm>
#include <charconv>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <limits>

#include <nlohmann/json.hpp>

#include "core/object/formats/model_file.h"
#include "server/api/object_converters.h"
#include "server/api/pose_converter.h"
#include "server/api/status_mapping.h"

namespace recog::server {
namespace {

using nlohmann::json;
namespace pb = ::recognition::v1;

constexpr size_t kDefaultMaxPoints = 20000, kMaxMaxPoints = 1000000;

HttpReply Error(const Status& status) { return ErrorReply(ToGrpcStatus(status)); }

HttpReply Json(const json& body) { return {200, "application/json", JsonText(body)}; }

// The caller of `authorization` when it holds the read right and the server is ready.
StatusOr<Caller> Reader(const ServerState& state, const std::string& authorization) {
  RECOG_ASSIGN_OR_RETURN(Caller caller, state.auth.Authenticate(authorization));
  RECOG_RETURN_IF_ERROR(TokenAuthenticator::Check(caller, Right::kRead));
  if (!state.ready.load()) return Status::Unavailable("the server is starting (opening its store)");
  return caller;
}

// `found`, or when it was not found (or its name is malformed) "no such `what`": errors never echo
// what a request asked for.
template <typename T>
StatusOr<T> Unechoed(StatusOr<T> found, const char* what) {
  if (found.ok() || (found.status().code() != StatusCode::kNotFound &&
                     found.status().code() != StatusCode::kInvalidArgument)) {
    return found;
  }
  return Status::NotFound(std::string("no such ") + what);
}

// The place map `name`, when the caller may read it.
StatusOr<std::shared_ptr<PlaceMap>> ReadableMap(const ServerState& state,
                                                const std::string& authorization,
                                                const std::string& name) {
  RECOG_ASSIGN_OR_RETURN(Caller caller, Reader(state, authorization));
  RECOG_ASSIGN_OR_RETURN(std::shared_ptr<PlaceMap> map, Unechoed(state.maps->Get(name), "map"));
  RECOG_RETURN_IF_ERROR(TokenAuthenticator::CheckMap(caller, Right::kRead, name, map->group()));
  return map;
}

// A decimal number of a path or query ("what" names it in the error, which does not echo it).
StatusOr<uint64_t> ParseNumber(const std::string& text, const char* what, uint64_t max) {
  uint64_t value = 0;
  const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), value);
  if (text.empty() || error != std::errc() || end != text.data() + text.size() || value > max) {
    return Status::InvalidArgument(std::string(what) + " must be a number from 0 to " +
                                   std::to_string(max));
  }
  return value;
}

// The latest version of model `name` as stored, decoded.
StatusOr<std::pair<ModelVersionInfo, ObjectModel>> ReadableModel(const ServerState& state,
                                                                 const std::string& authorization,
                                                                 const std::string& name) {
  RECOG_RETURN_IF_ERROR(Reader(state, authorization).status());
  RECOG_ASSIGN_OR_RETURN(auto stored, Unechoed(state.repository->Get(name, 0), "model"));
  RECOG_ASSIGN_OR_RETURN(ObjectModel model,
                         DecodeObjectModel(stored.second, "model '" + name + "'"));
  return std::make_pair(std::move(stored.first), std::move(model));
}

json PoseJson(const RigidTransform& pose) {
  pb::Pose proto;
  ToProto(pose.R, pose.t, &proto);
  return json::parse(ToJson(proto));
}

}  // namespace

HttpReply WhoAmIView(const ServerState& state, const std::string& authorization) {
  const StatusOr<Caller> caller = state.auth.Authenticate(authorization);
  json body = {{"auth_required", !state.auth.allows_all()}, {"authenticated", caller.ok()}};
  if (caller.ok()) {
    body["name"] = caller->name;
    body["can_read"] = caller->can_read;
    body["can_write"] = caller->can_write;
  }
  return Json(body);
}

HttpReply MapsView(const ServerState& state, const RpcGateway& gateway,
                   const std::string& authorization) {
  const StatusOr<Caller> reader = Reader(state, authorization);
  if (!reader.ok()) return Error(reader.status());
  json maps = json::array();
  pb::ListMapsRequest request;
  request.set_page_size(1000);
  do {
    pb::ListMapsResponse page;
    const grpc::Status listed =
        gateway.Call("recognition.v1.PlaceRecognition/ListMaps", request, &page, authorization);
    if (!listed.ok()) return ErrorReply(listed);
    for (const pb::MapInfo& info : page.maps()) {
      json entry = {{"info", json::parse(ToJson(info))}};
      const StatusOr<uint64_t> bytes = state.store->MapDiskBytes(MapId(info.id()));
      const StatusOr<uint64_t> thumbnails = state.thumbnails->Count(info.id());
      // Proto's JSON writes 64-bit numbers as strings: so do these.
      entry["disk_bytes"] = bytes.ok() ? std::to_string(*bytes) : "0";
      entry["thumbnails"] = thumbnails.ok() ? std::to_string(*thumbnails) : "0";
      entry["loops_kept"] = state.recent_loops->Count(info.name());
      maps.push_back(std::move(entry));
    }
    request.set_page_token(page.next_page_token());
  } while (!request.page_token().empty());
  return Json({{"maps", maps}});
}

HttpReply LoopsView(const ServerState& state, const std::string& authorization,
                    const std::string& map_name) {
  const StatusOr<std::shared_ptr<PlaceMap>> map = ReadableMap(state, authorization, map_name);
  if (!map.ok()) return Error(map.status());
  const uint32_t map_id = (*map)->info().id;
  json loops = json::array();
  for (const RecordedLoop& loop : state.recent_loops->Of(map_name)) {
    // A frame's size is its thumbnail's record of it when the loop's frame had no image.
    const auto size_of = [&](uint64_t frame, cv::Size known) {
      if (known.area() == 0) {
        const StatusOr<Thumbnail> thumbnail = state.thumbnails->Get(map_id, frame);
        if (thumbnail.ok()) known = thumbnail->frame_size;
      }
      return json::array({known.width, known.height});
    };
    json pairs = json::array();
    for (const cv::Vec4f& p : loop.pairs) pairs.push_back({p[0], p[1], p[2], p[3]});
    loops.push_back({{"frame_id", std::to_string(loop.frame_id)},
                     {"match_frame_id", std::to_string(loop.match_frame_id)},
                     {"unix_ms", std::to_string(loop.unix_ms)},
                     {"score", loop.score},
                     {"normalized_score", loop.normalized_score},
                     {"inliers", loop.inliers},
                     {"frame_size", size_of(loop.frame_id, loop.frame_size)},
                     {"match_size", size_of(loop.match_frame_id, cv::Size())},
                     {"pairs", pairs}});
  }
  return Json({{"map", map_name}, {"loops", loops}});
}

HttpReply ThumbnailView(const ServerState& state, const std::string& authorization,
                        const std::string& map_name, const std::string& frame) {
  const StatusOr<std::shared_ptr<PlaceMap>> map = ReadableMap(state, authorization, map_name);
  if (!map.ok()) return Error(map.status());
  const StatusOr<uint64_t> id =
      ParseNumber(frame, "frame id", std::numeric_limits<uint64_t>::max());
  if (!id.ok()) return Error(id.status());
  StatusOr<Thumbnail> thumbnail = state.thumbnails->Get((*map)->info().id, *id);
  if (!thumbnail.ok()) return Error(thumbnail.status());
  // The size of the frame it shows, to scale pixels of the frame onto it.
  return {200,
          "image/jpeg",
          std::move(thumbnail->jpeg),
          {{"X-Frame-Width", std::to_string(thumbnail->frame_size.width)},
           {"X-Frame-Height", std::to_string(thumbnail->frame_size.height)}}};
}

HttpReply ModelView(const ServerState& state, const std::string& authorization,
                    const std::string& name) {
  const auto model = ReadableModel(state, authorization, name);
  if (!model.ok()) return Error(model.status());
  const auto& [info, object] = model.value();
  pb::ModelInfo proto;
  ToProto(info, &proto);
  json views = json::array();
  for (size_t i = 0; i < object.views.size(); ++i) {
    const TrainingView& view = object.views[i];
    views.push_back({{"index", i},
                     {"name", view.name},
                     {"has_image", !view.image_png.empty()},
                     {"camera",
                      {{"fx", view.camera.fx},
                       {"fy", view.camera.fy},
                       {"cx", view.camera.cx},
                       {"cy", view.camera.cy}}},
                     {"pose", PoseJson(view.camera_from_object)}});
  }
  cv::Point3f low(0, 0, 0), high(0, 0, 0);
  if (!object.points.empty()) low = high = object.points.front();
  for (const cv::Point3f& p : object.points) {
    low = {std::min(low.x, p.x), std::min(low.y, p.y), std::min(low.z, p.z)};
    high = {std::max(high.x, p.x), std::max(high.y, p.y), std::max(high.z, p.z)};
  }
  return Json({{"info", json::parse(ToJson(proto))},
               {"views", views},
               {"bounds", {{"min", {low.x, low.y, low.z}}, {"max", {high.x, high.y, high.z}}}}});
}

HttpReply ModelPointsView(const ServerState& state, const std::string& authorization,
                          const std::string& name, const std::string& max_text) {
  const StatusOr<uint64_t> max = max_text.empty() ? StatusOr<uint64_t>(kDefaultMaxPoints)
                                                  : ParseNumber(max_text, "max", kMaxMaxPoints);
  if (!max.ok()) return Error(max.status());
  if (*max == 0) return Error(Status::InvalidArgument("max must be at least 1"));
  const auto model = ReadableModel(state, authorization, name);
  if (!model.ok()) return Error(model.status());
  const ObjectModel& object = model->second;
  std::vector<uint32_t> observations(object.points.size(), 0);
  for (uint32_t point : object.point_of_feature) ++observations[point];
  const size_t n = object.points.size();
  const size_t shown = std::min<size_t>(n, *max);
  json points = json::array(), counts = json::array();
  for (size_t k = 0; k < shown; ++k) {
    const size_t i = k * n / shown;  // evenly over the model
    const cv::Point3f& p = object.points[i];
    points.push_back({p.x, p.y, p.z});
    counts.push_back(observations[i]);
  }
  return Json({{"name", name},
               {"units", object.metadata.units},
               {"total", n},
               {"points", points},
               {"observations", counts}});
}

HttpReply ModelImageView(const ServerState& state, const std::string& authorization,
                         const std::string& name, const std::string& index_text) {
  const auto model = ReadableModel(state, authorization, name);
  if (!model.ok()) return Error(model.status());
  const std::vector<TrainingView>& views = model->second.views;
  const StatusOr<uint64_t> index = ParseNumber(index_text, "view", 1u << 20);
  if (!index.ok()) return Error(index.status());
  if (*index >= views.size() || views[*index].image_png.empty()) {
    return Error(Status::NotFound("the model has no image of view " + std::to_string(*index)));
  }
  const std::vector<uint8_t>& png = views[*index].image_png;
  return {200, "image/png", std::string(png.begin(), png.end())};
}

HttpReply ChartsView(const ServerState& state, const std::string& authorization) {
  const StatusOr<Caller> reader = Reader(state, authorization);
  if (!reader.ok()) return Error(reader.status());
  namespace fs = std::filesystem;
  const std::string& dir = state.config.console.charts_dir;
  json charts = json::array(), errors = json::array();
  if (dir.empty()) return Json({{"configured", false}, {"charts", charts}, {"errors", errors}});
  std::error_code error;
  std::vector<fs::path> files;
  for (const fs::directory_entry& entry : fs::directory_iterator(dir, error)) {
    // A plot's chart has its PNG beside it; other JSON files (reports) are not charts.
    fs::path png = entry.path();
    png.replace_extension(".png");
    if (entry.path().extension() == ".json" && entry.is_regular_file() && fs::exists(png)) {
      files.push_back(entry);
    }
  }
  if (error) {
    return Error(Status::FailedPrecondition("console.charts_dir '" + dir +
                                            "' cannot be read: " + error.message()));
  }
  std::sort(files.begin(), files.end());
  if (files.size() > kMaxCharts) {
    errors.push_back({{"file", files[kMaxCharts].filename().string()},
                      {"message", "and the " + std::to_string(files.size() - kMaxCharts) +
                                      " charts after it are not shown (at most " +
                                      std::to_string(kMaxCharts) + ")"}});
    files.resize(kMaxCharts);
  }
  for (const fs::path& file : files) {
    const auto refuse = [&](const std::string& message) {
      errors.push_back({{"file", file.filename().string()}, {"message", message}});
    };
    const uintmax_t bytes = fs::file_size(file, error);
    if (error || bytes > kMaxChartBytes) {
      refuse(error ? error.message() : "larger than " + std::to_string(kMaxChartBytes) + " bytes");
      continue;
    }
    std::ifstream in(file);
    const json chart = json::parse(in, nullptr, /*allow_exceptions=*/false);
    if (!chart.is_object() || !chart.contains("series") || !chart["series"].is_array()) {
      refuse("not a chart (a JSON object with a series list, as recog eval --plot writes)");
      continue;
    }
    // The file clock's time as the system clock's (no clock_cast in GCC 12's library).
    const auto modified = std::chrono::system_clock::now() +
                          std::chrono::duration_cast<std::chrono::system_clock::duration>(
                              fs::last_write_time(file, error) - fs::file_time_type::clock::now());
    charts.push_back(
        {{"name", file.stem().string()},
         {"file", file.filename().string()},
         {"modified_unix_ms", std::to_string(std::chrono::duration_cast<std::chrono::milliseconds>(
                                                 modified.time_since_epoch())
                                                 .count())},
         {"chart", chart}});
  }
  return Json({{"configured", true}, {"charts", charts}, {"errors", errors}});
}

HttpReply LiveView(const ServerState& state, const LiveSampler& live,
                   const std::string& authorization) {
  const StatusOr<Caller> reader = Reader(state, authorization);
  if (!reader.ok()) return Error(reader.status());
  const auto optional = [](const std::optional<double>& value) {
    return value.has_value() ? json(*value) : json(nullptr);
  };
  json samples = json::array();
  for (const LiveSample& s : live.Samples()) {
    samples.push_back({{"unix_ms", std::to_string(s.unix_ms)},
                       {"calls_per_s", s.calls_per_s},
                       {"frames_per_s", s.frames_per_s},
                       {"errors_per_s", s.errors_per_s},
                       {"latency_p50_ms", optional(s.latency_p50_ms)},
                       {"latency_p90_ms", optional(s.latency_p90_ms)},
                       {"latency_p99_ms", optional(s.latency_p99_ms)},
                       {"queue_depth", s.queue_depth}});
  }
  return Json({{"interval_s", 1}, {"samples", samples}});
}

}  // namespace recog::server
