// The web console's HTTP API against a recogd in this process (server/console/): the gateway's
// unary calls, the views of maps, loops, thumbnails, models and live samples, the tokens' rules,
// and bad input. The pages themselves are tested in a real browser (tests/console/).
#include <httplib.h>
#include <nlohmann/json.hpp>

#include <filesystem>
#include <fstream>
#include <opencv2/imgcodecs.hpp>

#include "server/console/live_sampler.h"
#include "server/console/rpc_gateway.h"
#include "tests/server/server_fixture.h"
#include "tests/testing/model_files.h"
#include "tests/testing/wait.h"

namespace recog::server::testing {
namespace {

using nlohmann::json;
using recog::testing::WaitUntil;

constexpr char kReader[] = "reader-token-0123456789", kWriter[] = "writer-token-0123456789";

class ConsoleTest : public ServerFixture {
 protected:
  ConsoleTest() { config().console.listen = "127.0.0.1:0"; }

  void SetUp() override {
    ServerFixture::SetUp();
    ASSERT_GT(server_->console_port(), 0);
    http_ = std::make_unique<httplib::Client>("127.0.0.1", server_->console_port());
    http_->set_read_timeout(30);
  }

  httplib::Headers Auth(const std::string& token) const {
    if (token.empty()) return {};
    return {{"Authorization", "Bearer " + token}};
  }
  // GET `path`: the status and the body.
  std::pair<int, std::string> Get(const std::string& path, const std::string& token = {}) {
    httplib::Result result = http_->Get(path, Auth(token));
    if (!result) return {0, "no answer: " + httplib::to_string(result.error())};
    return {result->status, result->body};
  }
  std::pair<int, json> GetJson(const std::string& path, const std::string& token = {}) {
    auto [status, body] = Get(path, token);
    return {status, json::parse(body, nullptr, false)};
  }
  // GET /api/maps once the map's thumbnails are written (in the background), or when they never
  // were, as it was at the deadline.
  json MapsOnceWritten(const std::string& thumbnails) {
    json maps;
    EXPECT_TRUE(WaitUntil([&] {
      maps = GetJson("/api/maps").second;
      return maps["maps"][0]["thumbnails"] == thumbnails;
    })) << "the map's thumbnails were never "
        << thumbnails;
    return maps;
  }
  std::pair<int, json> Rpc(const std::string& method, const std::string& body,
                           const std::string& token = {}) {
    httplib::Result result =
        http_->Post("/api/rpc/" + method, Auth(token), body, "application/json");
    if (!result) return {0, json()};
    return {result->status, json::parse(result->body, nullptr, false)};
  }

  // Streams corridor images 1, 20, 41, 60 and 1 again into a new map that keeps thumbnails: the
  // last frame closes a loop with the first.
  void StreamRevisit(const std::string& map) {
    pb::MapSettings settings;
    settings.set_temporal_matches(0);
    settings.set_recent_frames(1);
    settings.set_keep_thumbnails(true);
    ASSERT_TRUE(CreateMap(map, settings).ok());
    for (int n : {1, 20, 41, 60, 1}) {
      pb::QueryPlaceRequest request;
      request.set_map(map);
      request.set_add_frame(true);
      *request.mutable_frame() = JpegFrame(CorridorJpeg(n));
      pb::QueryPlaceResponse response;
      ASSERT_TRUE(places_->QueryPlace(Context().get(), request, &response).ok());
      // The console records the inliers; the client, which did not ask, does not get them.
      EXPECT_EQ(response.result().inlier_correspondences_size(), 0);
    }
  }

  std::unique_ptr<httplib::Client> http_;
};

TEST_F(ConsoleTest, AMapShowsItsFramesThumbnailsAndTheLoopItAnsweredWithItsInliers) {
  StreamRevisit("tour");
  const json maps = MapsOnceWritten("5");
  ASSERT_EQ(maps["maps"].size(), 1u);
  const json& tour = maps["maps"][0];
  EXPECT_EQ(tour["info"]["name"], "tour");
  EXPECT_EQ(tour["info"]["frames"], "5");
  EXPECT_EQ(tour["info"]["settings"]["keep_thumbnails"], true);
  EXPECT_EQ(tour["thumbnails"], "5");
  const size_t loops_kept = tour["loops_kept"];
  EXPECT_GE(loops_kept, 1u);  // the revisit, and neighbours along the corridor
  EXPECT_GT(std::stoull(tour["disk_bytes"].get<std::string>()), 10000u);

  auto [loops_status, loops] = GetJson("/api/maps/tour/loops");
  ASSERT_EQ(loops_status, 200) << loops;
  ASSERT_EQ(loops["loops"].size(), loops_kept);
  const json& loop = loops["loops"][0];  // the newest: the revisit
  EXPECT_EQ(loop["frame_id"], "4");
  EXPECT_EQ(loop["match_frame_id"], "0");
  EXPECT_GE(loop["inliers"].get<int>(), 12);
  EXPECT_EQ(loop["pairs"].size(), loop["inliers"].get<size_t>());
  EXPECT_EQ(loop["frame_size"], json::array({512, 384}));
  EXPECT_EQ(loop["match_size"], json::array({512, 384}));
  // The same image twice: every inlier pairs a pixel with itself.
  for (const json& pair : loop["pairs"]) {
    EXPECT_NEAR(pair[0].get<double>(), pair[2].get<double>(), 2.0);
    EXPECT_NEAR(pair[1].get<double>(), pair[3].get<double>(), 2.0);
  }

  httplib::Result jpeg_answer = http_->Get("/api/maps/tour/frames/4/thumbnail");
  ASSERT_TRUE(jpeg_answer);
  ASSERT_EQ(jpeg_answer->status, 200);
  EXPECT_EQ(jpeg_answer->get_header_value("X-Frame-Width"), "512");
  EXPECT_EQ(jpeg_answer->get_header_value("X-Frame-Height"), "384");
  const std::string& jpeg = jpeg_answer->body;
  const cv::Mat thumbnail =
      cv::imdecode(std::vector<uint8_t>(jpeg.begin(), jpeg.end()), cv::IMREAD_UNCHANGED);
  EXPECT_EQ(thumbnail.size(), cv::Size(320, 240));
  EXPECT_EQ(Get("/api/maps/tour/frames/99/thumbnail").first, 404);
  EXPECT_EQ(Get("/api/maps/tour/frames/x1/thumbnail").first, 400);
  EXPECT_EQ(Get("/api/maps/nowhere/loops").first, 404);
}

TEST_F(ConsoleTest, DeletingAMapForgetsItsLoopsAndThumbnails) {
  StreamRevisit("tour");
  pb::DeleteMapRequest request;
  request.set_name("tour");
  pb::DeleteMapResponse response;
  ASSERT_TRUE(places_->DeleteMap(Context().get(), request, &response).ok());
  EXPECT_EQ(Get("/api/maps/tour/loops").first, 404);
  pb::MapSettings settings;
  settings.set_keep_thumbnails(true);
  ASSERT_TRUE(CreateMap("tour", settings).ok());  // a new map of the same name starts empty
  auto [status, maps] = GetJson("/api/maps");
  ASSERT_EQ(status, 200);
  EXPECT_EQ(maps["maps"][0]["thumbnails"], "0");
  EXPECT_EQ(maps["maps"][0]["loops_kept"], 0);
  EXPECT_EQ(Get("/api/maps/tour/frames/0/thumbnail").first, 404);
}

TEST_F(ConsoleTest, AMapWithoutThumbnailsKeepsNoneAndItsLoopsStillHaveTheirInliers) {
  pb::MapSettings settings;
  settings.set_temporal_matches(0);
  settings.set_recent_frames(1);
  ASSERT_TRUE(CreateMap("plain", settings).ok());
  for (int n : {1, 20, 41, 60, 1}) {
    pb::AddFrameResponse added;
    ASSERT_TRUE(AddFrame("plain", JpegFrame(CorridorJpeg(n)), &added).ok());
  }
  auto [status, maps] = GetJson("/api/maps");
  ASSERT_EQ(status, 200);
  EXPECT_EQ(maps["maps"][0]["thumbnails"], "0");
  EXPECT_EQ(maps["maps"][0]["info"]["settings"]["keep_thumbnails"], false);
  EXPECT_EQ(Get("/api/maps/plain/frames/0/thumbnail").first, 404);
}

TEST_F(ConsoleTest, ARigMapRefusesThumbnails) {
  pb::MapSettings settings;
  settings.set_keep_thumbnails(true);
  pb::RigCameraSettings* camera = settings.add_rig();
  camera->set_name("front");
  camera->mutable_intrinsics()->set_fx(500);
  camera->mutable_intrinsics()->set_fy(500);
  camera->set_width(640);
  camera->set_height(480);
  for (double r : {1, 0, 0, 0, 1, 0, 0, 0, 1}) camera->mutable_body_pose()->add_rotation(r);
  for (int i = 0; i < 3; ++i) camera->mutable_body_pose()->add_translation(0);
  const grpc::Status status = CreateMap("rig", settings);
  EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(status.error_message().find("keep_thumbnails"), std::string::npos);
}

TEST_F(ConsoleTest, TheGatewayCallsTheServicesAndRefusesWhatIsNotARequest) {
  StreamRevisit("tour");
  auto [status, map] = Rpc("recognition.v1.PlaceRecognition/GetMap", R"({"name": "tour"})");
  ASSERT_EQ(status, 200) << map;
  EXPECT_EQ(map["map"]["frames"], "5");

  pb::QueryPlaceRequest query;
  query.set_map("tour");
  *query.mutable_frame() = JpegFrame(CorridorJpeg(1));
  query.mutable_options()->set_include_correspondences(true);
  auto [query_status, answer] = Rpc("recognition.v1.PlaceRecognition/QueryPlace", ToJson(query));
  ASSERT_EQ(query_status, 200) << answer;
  EXPECT_EQ(answer["result"]["status"], "LOOP_STATUS_LOOP_DETECTED");
  EXPECT_GE(answer["result"]["inlier_correspondences"].size(), 12u);

  const auto refused = [&](const std::string& method, const std::string& body, int http,
                           const std::string& code) {
    auto [got, error] = Rpc(method, body);
    EXPECT_EQ(got, http) << method << " " << body << ": " << error;
    EXPECT_EQ(error["code"], code) << error;
    EXPECT_FALSE(error["message"].get<std::string>().empty());
  };
  refused("recognition.v1.PlaceRecognition/GetMap", R"({"name": "nowhere"})", 404, "NOT_FOUND");
  refused("recognition.v1.PlaceRecognition/GetMap", "{not json", 400, "INVALID_ARGUMENT");
  refused("recognition.v1.PlaceRecognition/GetMap", R"({"nme": "tour"})", 400, "INVALID_ARGUMENT");
  refused("recognition.v1.PlaceRecognition/StreamFrames", "{}", 404, "NOT_FOUND");
  refused("recognition.v1.Nothing/Here", "{}", 404, "NOT_FOUND");
  refused(
      "recognition.v1.ObjectRecognition/RecognizeObjects",
      R"({"frame": {"encoded_image": "bm90IGFuIGltYWdl", "intrinsics": {"fx": 500, "fy": 500}}})",
      400, "INVALID_ARGUMENT");
  // The HTTP layer's own refusals are JSON too.
  auto [unknown, body] = Get("/api/nothing");
  EXPECT_EQ(unknown, 404);
  EXPECT_EQ(json::parse(body)["code"], "NOT_FOUND");
  // Only JSON: a page of another site cannot send it without the browser asking first.
  httplib::Result text = http_->Post("/api/rpc/recognition.v1.PlaceRecognition/CreateMap",
                                     R"({"name": "forged"})", "text/plain");
  ASSERT_TRUE(text);
  EXPECT_EQ(text->status, 415);
  EXPECT_EQ(GetMap("forged").error_code(), grpc::StatusCode::NOT_FOUND);
  httplib::Result form = http_->Post("/api/rpc/recognition.v1.PlaceRecognition/GetMap",
                                     std::string(20000, 'a'), "application/x-www-form-urlencoded");
  ASSERT_TRUE(form);
  EXPECT_EQ(form->status, 415);
  EXPECT_NE(form->body.find("application/json"), std::string::npos) << form->body;
}

TEST_F(ConsoleTest, AModelShowsItsViewsAndItsPoints) {
  ASSERT_TRUE(PutModel(recog::testing::ModelFile("crate", {1, 20}, "box"), "crate").ok());
  auto [status, model] = GetJson("/api/models/crate");
  ASSERT_EQ(status, 200) << model;
  EXPECT_EQ(model["info"]["name"], "crate");
  EXPECT_EQ(model["info"]["object_class"], "box");
  const uint32_t points = model["info"]["num_points"];
  EXPECT_GT(points, 100u);
  const json& low = model["bounds"]["min"];
  const json& high = model["bounds"]["max"];
  const double width = high[0].get<double>() - low[0].get<double>();
  EXPECT_GT(width, 0.3);  // the features of a 0.64 m wide face
  EXPECT_LE(width, 0.641);

  auto [points_status, all] = GetJson("/api/models/crate/points");
  ASSERT_EQ(points_status, 200);
  EXPECT_EQ(all["points"].size(), points);
  EXPECT_EQ(all["observations"].size(), points);
  EXPECT_EQ(all["total"], points);
  auto [few_status, few] = GetJson("/api/models/crate/points?max=10");
  ASSERT_EQ(few_status, 200);
  EXPECT_EQ(few["points"].size(), 10u);
  EXPECT_EQ(Get("/api/models/crate/points?max=0").first, 400);
  EXPECT_EQ(Get("/api/models/crate/points?max=ten").first, 400);
  EXPECT_EQ(Get("/api/models/nothing").first, 404);
  EXPECT_EQ(Get("/api/models/crate/views/1000/image").first, 404);

  auto [list_status, list] = Rpc("recognition.v1.ObjectRepository/ListModels", "{}");
  ASSERT_EQ(list_status, 200);
  EXPECT_EQ(list["models"][0]["name"], "crate");
}

TEST_F(ConsoleTest, TheLiveViewCountsTheCallsOfTheLastSeconds) {
  for (int i = 0; i < 5; ++i)
    ASSERT_EQ(GetMap("nowhere").error_code(), grpc::StatusCode::NOT_FOUND);
  json samples;
  EXPECT_TRUE(WaitUntil(  // one sample a second
      [&] {
        auto [status, live] = GetJson("/api/live");
        EXPECT_EQ(status, 200);
        samples = live["samples"];
        double calls = 0;
        for (const json& s : samples) calls += s["calls_per_s"].get<double>();
        return calls > 0;
      },
      recog::testing::kEventTimeout, std::chrono::milliseconds(100)))
      << "the live view never counted a call";
  double calls = 0, errors = 0;
  for (const json& s : samples) {
    calls += s["calls_per_s"].get<double>();
    errors += s["errors_per_s"].get<double>();
  }
  EXPECT_GT(calls, 0) << samples;
  EXPECT_GT(errors, 0) << samples;  // NOT_FOUND is not OK
}

TEST_F(ConsoleTest, TokensRuleTheConsoleAsTheyRuleTheApi) {
  const std::string tokens = data_dir_.Sub("tokens.yaml");
  std::ofstream(tokens) << "tokens:\n"
                        << "  - name: reader\n    token: " << kReader << "\n    rights: [read]\n"
                        << "  - name: writer\n    token: " << kWriter << "\n    rights: [write]\n";
  StopServer();
  config().token_file = tokens;
  StartServer();
  http_ = std::make_unique<httplib::Client>("127.0.0.1", server_->console_port());

  auto [who_status, who] = GetJson("/api/whoami");
  ASSERT_EQ(who_status, 200);
  EXPECT_EQ(who["auth_required"], true);
  EXPECT_EQ(who["authenticated"], false);
  EXPECT_EQ(GetJson("/api/whoami", kReader).second["can_write"], false);

  EXPECT_EQ(Get("/api/maps").first, 401);
  EXPECT_EQ(Get("/api/maps", "not-a-token-at-all-0000").first, 401);
  EXPECT_EQ(Get("/api/live").first, 401);
  EXPECT_EQ(Rpc("recognition.v1.PlaceRecognition/ListMaps", "{}").first, 401);
  EXPECT_EQ(Get("/api/maps", kReader).first, 200);
  auto [denied, error] =
      Rpc("recognition.v1.PlaceRecognition/CreateMap", R"({"name": "mine"})", kReader);
  EXPECT_EQ(denied, 403) << error;
  EXPECT_EQ(error["code"], "PERMISSION_DENIED");
  EXPECT_EQ(Rpc("recognition.v1.PlaceRecognition/CreateMap", R"({"name": "mine"})", kWriter).first,
            200);
  EXPECT_EQ(Get("/api/maps/mine/loops", kReader).first, 200);
}

TEST_F(ConsoleTest, TheChartsOfItsFolderAreListedAndWhatIsNotAChartSaysSo) {
  auto [none_status, none] = GetJson("/api/charts");
  ASSERT_EQ(none_status, 200);
  EXPECT_EQ(none["configured"], false);
  EXPECT_TRUE(none["charts"].empty());

  const std::string charts = data_dir_.Sub("charts");
  std::filesystem::create_directories(charts);
  const auto write = [&](const std::string& name, const std::string& text) {
    std::ofstream(charts + "/" + name) << text;
  };
  write("pr.json", R"({"title": "PR", "x_min": 0, "x_max": 1, "y_min": 0, "y_max": 1,
                      "series": [{"label": "a", "points": [[0.5, 1.0]]}]})");
  write("pr.png", "png");
  write("broken.json", "{not json");
  write("broken.png", "png");
  write("report.json", R"({"frames": 84})");  // no PNG beside it: a report, not a chart
  StopServer();
  config().console.charts_dir = charts;
  StartServer();
  http_ = std::make_unique<httplib::Client>("127.0.0.1", server_->console_port());

  auto [status, listed] = GetJson("/api/charts");
  ASSERT_EQ(status, 200) << listed;
  EXPECT_EQ(listed["configured"], true);
  ASSERT_EQ(listed["charts"].size(), 1u) << listed;
  EXPECT_EQ(listed["charts"][0]["name"], "pr");
  EXPECT_EQ(listed["charts"][0]["chart"]["series"][0]["label"], "a");
  ASSERT_EQ(listed["errors"].size(), 1u) << listed;
  EXPECT_EQ(listed["errors"][0]["file"], "broken.json");
  EXPECT_NE(listed["errors"][0]["message"].get<std::string>().find("not a chart"),
            std::string::npos);
}

TEST_F(ConsoleTest, ThePagesAndDebiansLibrariesAreServed) {
  auto [index_status, index] = Get("/static/index.html");
  EXPECT_EQ(index_status, 200);
  EXPECT_NE(index.find("<html"), std::string::npos);
  httplib::Result root = http_->Get("/");
  ASSERT_TRUE(root);
  EXPECT_EQ(root->status, 302);
  EXPECT_EQ(root->get_header_value("Location"), "/static/index.html");
  if (std::filesystem::exists("/usr/share/javascript/three/build/three.module.js")) {
    httplib::Result three = http_->Get("/vendor/three/build/three.module.js");
    ASSERT_TRUE(three);
    EXPECT_EQ(three->status, 200);
    EXPECT_EQ(three->get_header_value("Content-Type"), "text/javascript; charset=utf-8");
  }
}

// A server on a free loopback port over `dir`, without metrics.
ServerConfig LoopbackConfig(const recog::testing::TempDir& dir) {
  ServerConfig config;
  config.listen = "127.0.0.1:0";
  config.data_dir = dir.path().string();
  config.metrics_listen = "";
  return config;
}

TEST(ConsoleOffTest, WithoutAnAddressThereIsNoConsole) {
  recog::testing::TempDir dir("console-off");
  const ServerConfig config = LoopbackConfig(dir);
  auto server = RecognitionServer::Start(config);
  ASSERT_TRUE(server.ok()) << server.status().ToString();
  EXPECT_EQ((*server)->console_port(), 0);
}

// The console's thread may not listen yet when the server stops: stopping must still end it (a
// stop that came too early used to leave it in accept() and the shutdown waiting forever).
TEST(ConsoleStartTest, AServerStoppedAsSoonAsItStartedStops) {
  recog::testing::TempDir dir("console-quick");
  ServerConfig config = LoopbackConfig(dir);
  config.console.listen = "127.0.0.1:0";
  for (int i = 0; i < 10; ++i) {
    auto server = RecognitionServer::Start(config);
    ASSERT_TRUE(server.ok()) << server.status().ToString();
    EXPECT_GT((*server)->console_port(), 0);
    (*server)->Shutdown(std::chrono::milliseconds(0));
  }
}

TEST(ConsoleStartTest, AMissingPageFolderOrABadAddressStopsTheStart) {
  recog::testing::TempDir dir("console-bad");
  ServerConfig config = LoopbackConfig(dir);
  config.console.listen = "127.0.0.1:0";
  config.console.web_root = dir.Sub("no-pages");
  auto missing = RecognitionServer::Start(config);
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.status().code(), StatusCode::kNotFound);
  EXPECT_NE(missing.status().message().find("index.html"), std::string::npos);
  config.console.web_root = "";
  config.console.listen = "127.0.0.1:http";
  auto malformed = RecognitionServer::Start(config);
  ASSERT_FALSE(malformed.ok());
  EXPECT_EQ(malformed.status().code(), StatusCode::kInvalidArgument);
}

// The live charts' arithmetic: rates between two readings and percentiles in the buckets.
TEST(LiveSamplerTest, RatesAndPercentilesComeFromTheDifferenceOfTwoReadings) {
  ServerMetrics::Totals before, after;
  before.bucket_bounds = after.bucket_bounds = {0.001, 0.01, 0.1};
  before.bucket_counts = {5, 5, 5};
  before.calls = 5;
  // 100 new calls: 50 under 1 ms, 40 in 1..10 ms, 10 in 10..100 ms; 4 failed; 30 frames.
  after.bucket_counts = {55, 95, 105};
  after.calls = 105;
  after.errors = 4;
  after.frames = 30;
  after.queue_depth = 3;
  const LiveSample sample = LiveSampler::Between(before, after, 2.0, 1234);
  EXPECT_EQ(sample.unix_ms, 1234);
  EXPECT_DOUBLE_EQ(sample.calls_per_s, 50);
  EXPECT_DOUBLE_EQ(sample.errors_per_s, 2);
  EXPECT_DOUBLE_EQ(sample.frames_per_s, 15);
  EXPECT_DOUBLE_EQ(sample.queue_depth, 3);
  EXPECT_NEAR(*sample.latency_p50_ms, 1.0, 1e-9);  // the 50th call ends the first bucket
  EXPECT_NEAR(*sample.latency_p90_ms, 1 + 9 * 40. / 40, 1e-9);  // the last of the second
  EXPECT_NEAR(*sample.latency_p99_ms, 10 + 90 * 9. / 10, 1e-9);
  const LiveSample idle = LiveSampler::Between(after, after, 1.0, 0);
  EXPECT_FALSE(idle.latency_p50_ms.has_value());
  EXPECT_DOUBLE_EQ(idle.calls_per_s, 0);
}

}  // namespace
}  // namespace recog::server::testing
