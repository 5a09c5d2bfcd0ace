// Loopback tests of the PlaceRecognition service: maps, frames, streams and bad input.
#include <atomic>
#include <cmath>
#include <condition_variable>
#include <fstream>
#include <map>
#include <mutex>
#include <optional>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "client/cpp/frames.h"
#include "core/features/feature_extractor.h"
#include "tests/server/server_fixture.h"
#include "tests/testing/metrics_scrape.h"
#include "tools/evaluation/metric_sequence.h"

namespace recog::server::testing {
namespace {

class PlaceServiceTest : public ServerFixture {
 protected:
  // Robots A, B and the `others` in group "fleet", and a map "elsewhere" outside it: robot A
  // holds corridor frames 1 and 20 (client ids a-1, a-20), robot B frame 60, elsewhere frame 1.
  void CreateFleet(const std::vector<std::string>& others = {}) {
    pb::MapSettings fleet;
    fleet.set_group("fleet");
    for (const std::string& robot : {std::string("robot-a"), std::string("robot-b")}) {
      ASSERT_TRUE(CreateMap(robot, fleet).ok());
    }
    for (const std::string& robot : others) ASSERT_TRUE(CreateMap(robot, fleet).ok());
    ASSERT_TRUE(CreateMap("elsewhere").ok());
    pb::AddFrameResponse added;
    for (int n : {1, 20}) {
      pb::Frame frame = JpegFrame(CorridorJpeg(n));
      frame.set_client_frame_id("a-" + std::to_string(n));
      ASSERT_TRUE(AddFrame("robot-a", frame, &added).ok());
    }
    ASSERT_TRUE(AddFrame("robot-b", JpegFrame(CorridorJpeg(60)), &added).ok());
    ASSERT_TRUE(AddFrame("elsewhere", JpegFrame(CorridorJpeg(1)), &added).ok());
  }
};

pb::Frame FeaturesFrame(const std::string& jpeg) {
  const cv::Mat image =
      cv::imdecode(cv::Mat(1, int(jpeg.size()), CV_8U, (void*)jpeg.data()), cv::IMREAD_GRAYSCALE);
  auto extractor = CreateFeatureExtractor(FeatureOptions{});
  FeatureSet features;
  EXPECT_TRUE(extractor.value()->Extract(image, &features).ok());
  client::Result<pb::Frame> frame =
      client::FrameFromFeatures(features.keypoints, features.descriptors, image.size());
  EXPECT_TRUE(frame.ok());
  return std::move(frame).value();
}

TEST_F(PlaceServiceTest, MapsAreCreatedDescribedListedAndDeleted) {
  pb::MapSettings settings;
  settings.set_alpha(0.5);
  ASSERT_TRUE(CreateMap("robot-a", settings).ok());
  ASSERT_TRUE(CreateMap("robot-b").ok());
  EXPECT_EQ(CreateMap("robot-a").error_code(), grpc::StatusCode::ALREADY_EXISTS);
  EXPECT_EQ(CreateMap("bad name!").error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  pb::MapSettings negative;
  negative.set_alpha(-1);
  EXPECT_EQ(CreateMap("robot-c", negative).error_code(), grpc::StatusCode::INVALID_ARGUMENT);

  pb::MapInfo a, b;
  ASSERT_TRUE(GetMap("robot-a", &a).ok());
  ASSERT_TRUE(GetMap("robot-b", &b).ok());
  EXPECT_EQ(a.settings().alpha(), 0.5);
  EXPECT_EQ(b.settings().alpha(), 0.3);  // thesis Table 4.4 defaults
  EXPECT_EQ(b.settings().temporal_matches(), 3u);
  EXPECT_EQ(b.settings().min_inliers(), 12u);
  EXPECT_EQ(b.settings().geometry(), pb::GEOMETRY_CHECK_DIRECT_INDEX);
  EXPECT_EQ(a.frames(), 0u);
  EXPECT_NE(a.id(), b.id());
  EXPECT_EQ(a.vocabulary_checksum().size(), 18u);

  pb::ListMapsRequest list;
  list.set_page_size(1);
  pb::ListMapsResponse first, second;
  ASSERT_TRUE(places_->ListMaps(Context().get(), list, &first).ok());
  ASSERT_EQ(first.maps_size(), 1);
  EXPECT_EQ(first.maps(0).name(), "robot-a");
  ASSERT_FALSE(first.next_page_token().empty());
  list.set_page_token(first.next_page_token());
  ASSERT_TRUE(places_->ListMaps(Context().get(), list, &second).ok());
  ASSERT_EQ(second.maps_size(), 1);
  EXPECT_EQ(second.maps(0).name(), "robot-b");
  EXPECT_TRUE(second.next_page_token().empty());

  pb::AddFrameResponse added;
  ASSERT_TRUE(AddFrame("robot-a", JpegFrame(CorridorJpeg(1)), &added).ok());
  pb::DeleteMapRequest remove;
  remove.set_name("robot-a");
  pb::DeleteMapResponse removed;
  ASSERT_TRUE(places_->DeleteMap(Context().get(), remove, &removed).ok());
  EXPECT_EQ(removed.frames_deleted(), 1u);
  EXPECT_EQ(GetMap("robot-a").error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_EQ(places_->DeleteMap(Context().get(), remove, &removed).error_code(),
            grpc::StatusCode::NOT_FOUND);
  ASSERT_TRUE(CreateMap("robot-a").ok());  // the name is free again
}

TEST_F(PlaceServiceTest, AnAddedPlaceIsFoundByARelocalisationQueryThatChangesNothing) {
  ASSERT_TRUE(CreateMap("hall").ok());
  for (int n : {1, 20, 41, 60}) {
    pb::AddFrameResponse added;
    ASSERT_TRUE(AddFrame("hall", JpegFrame(CorridorJpeg(n), n), &added).ok());
    EXPECT_GT(added.num_features(), 300u);
  }
  pb::QueryPlaceRequest query;
  query.set_map("hall");
  *query.mutable_frame() = JpegFrame(CorridorJpeg(41));
  query.mutable_frame()->set_client_frame_id("probe-1");
  query.mutable_options()->set_include_fundamental(true);
  pb::QueryPlaceResponse response;
  ASSERT_TRUE(places_->QueryPlace(Context().get(), query, &response).ok());
  const pb::LoopResult& result = response.result();
  EXPECT_EQ(result.status(), pb::LOOP_STATUS_LOOP_DETECTED);
  EXPECT_EQ(result.match_frame_id(), 2u);
  EXPECT_EQ(result.match_timestamp(), 41.0);
  EXPECT_FALSE(result.has_frame_id());  // nothing was added
  EXPECT_GE(result.inliers(), 12u);
  EXPECT_EQ(result.fundamental_size(), 9);
  EXPECT_EQ(response.client_frame_id(), "probe-1");
  EXPECT_GT(response.timing().features_ms(), 0.0);
  pb::MapInfo info;
  ASSERT_TRUE(GetMap("hall", &info).ok());
  EXPECT_EQ(info.frames(), 4u);
}

TEST_F(PlaceServiceTest, ClientSideFeaturesWorkLikeImages) {
  ASSERT_TRUE(CreateMap("light").ok());
  pb::AddFrameResponse added;
  ASSERT_TRUE(AddFrame("light", FeaturesFrame(CorridorJpeg(20)), &added).ok());
  EXPECT_EQ(added.frame_id(), 0u);
  EXPECT_GT(added.num_features(), 300u);
  pb::QueryPlaceRequest query;
  query.set_map("light");
  *query.mutable_frame() = JpegFrame(CorridorJpeg(20));
  pb::QueryPlaceResponse response;
  ASSERT_TRUE(places_->QueryPlace(Context().get(), query, &response).ok());
  EXPECT_EQ(response.result().status(), pb::LOOP_STATUS_LOOP_DETECTED);
  EXPECT_EQ(response.result().match_frame_id(), 0u);
}

// Streams the frames after `config` (in `context`, e.g. one with a caller's token) and collects
// every answer.
std::vector<pb::StreamFramesResponse> Stream(
    pb::PlaceRecognition::Stub& stub, const pb::StreamConfig& config,
    const std::vector<pb::Frame>& frames, grpc::Status* status,
    std::unique_ptr<grpc::ClientContext> context = std::make_unique<grpc::ClientContext>()) {
  auto stream = stub.StreamFrames(context.get());
  pb::StreamFramesRequest request;
  *request.mutable_config() = config;
  std::vector<pb::StreamFramesResponse> answers;
  if (stream->Write(request)) {
    for (const pb::Frame& frame : frames) {
      *request.mutable_frame() = frame;
      if (!stream->Write(request)) break;
      pb::StreamFramesResponse answer;
      if (!stream->Read(&answer)) break;
      answers.push_back(answer);
    }
  }
  stream->WritesDone();
  *status = stream->Finish();
  return answers;
}

TEST_F(PlaceServiceTest, AStreamAnswersEveryFrameInOrderAndDetectsTheRevisit) {
  pb::StreamConfig config;
  config.set_map("tour");
  config.set_create_if_missing(true);
  config.mutable_settings()->set_temporal_matches(0);  // four frames cannot build consistency
  config.mutable_settings()->set_recent_frames(1);
  std::vector<pb::Frame> frames;
  for (int n : {1, 20, 41, 60, 1}) frames.push_back(JpegFrame(CorridorJpeg(n)));
  grpc::Status status;
  const auto answers = Stream(*places_, config, frames, &status);
  ASSERT_TRUE(status.ok()) << status.error_message();
  ASSERT_EQ(answers.size(), 5u);
  for (size_t i = 0; i < answers.size(); ++i) {
    EXPECT_EQ(answers[i].sequence(), i);
    ASSERT_TRUE(answers[i].has_result()) << answers[i].error().message();
    EXPECT_EQ(answers[i].result().frame_id(), i);
  }
  EXPECT_EQ(answers[0].result().status(), pb::LOOP_STATUS_LOW_SCORE_WITH_PREVIOUS);
  EXPECT_EQ(answers[4].result().status(), pb::LOOP_STATUS_LOOP_DETECTED);
  EXPECT_EQ(answers[4].result().match_frame_id(), 0u);
  pb::MapInfo info;
  ASSERT_TRUE(GetMap("tour", &info).ok());
  EXPECT_EQ(info.frames(), 5u);
  EXPECT_EQ(info.settings().temporal_matches(), 0u);
}

// A map created by a stream (create_if_missing) is created like one of CreateMap: its gauge of
// entries is there, at 0, before any frame reaches it.
TEST_F(PlaceServiceTest, AMapAStreamCreatesHasItsEntriesGaugeLikeOneOfCreateMap) {
  StopServer();
  config().metrics_listen = "127.0.0.1:0";
  StartServer();
  ASSERT_TRUE(CreateMap("made").ok());
  pb::StreamConfig config;
  config.set_map("streamed");
  config.set_create_if_missing(true);
  grpc::Status status;
  EXPECT_TRUE(Stream(*places_, config, {}, &status).empty());
  ASSERT_TRUE(status.ok()) << status.error_message();
  ASSERT_TRUE(GetMap("streamed").ok());
  const std::string metrics = recog::testing::FetchMetrics(server_->metrics_port());
  EXPECT_NE(metrics.find("recog_map_entries{map=\"made\"} 0"), std::string::npos) << metrics;
  EXPECT_NE(metrics.find("recog_map_entries{map=\"streamed\"} 0"), std::string::npos) << metrics;
}

TEST_F(PlaceServiceTest, BadFramesAreAnsweredWithTheirErrorAndTheStreamGoesOn) {
  ASSERT_TRUE(CreateMap("noisy").ok());
  std::vector<pb::Frame> frames;
  frames.push_back(JpegFrame("\xff\xd8 this is not a JPEG"));  // undecodable image
  pb::Frame zero;
  zero.mutable_raw_image()->set_format(pb::PIXEL_FORMAT_GRAY8);  // zero-size image
  frames.push_back(zero);
  pb::Frame short_pixels;
  short_pixels.mutable_raw_image()->set_width(64);
  short_pixels.mutable_raw_image()->set_height(48);
  short_pixels.mutable_raw_image()->set_format(pb::PIXEL_FORMAT_BGR8);
  short_pixels.mutable_raw_image()->set_pixels(std::string(100, '\x7f'));  // garbage length
  frames.push_back(short_pixels);
  pb::Frame wrong_length = FeaturesFrame(CorridorJpeg(1));
  wrong_length.mutable_features()->set_descriptor_bytes(16);  // wrong descriptor length
  frames.push_back(wrong_length);
  pb::Frame garbage_descriptors = FeaturesFrame(CorridorJpeg(1));
  garbage_descriptors.mutable_features()->set_descriptors("garbage");
  frames.push_back(garbage_descriptors);
  pb::Frame short_array = FeaturesFrame(CorridorJpeg(1));
  short_array.mutable_features()->mutable_keypoints()->mutable_octave()->RemoveLast();
  frames.push_back(short_array);  // one keypoint has no octave
  pb::Frame not_finite = FeaturesFrame(CorridorJpeg(1));
  not_finite.mutable_features()->mutable_keypoints()->set_x(3, std::nanf(""));
  frames.push_back(not_finite);
  frames.push_back(pb::Frame());                               // no content at all
  frames.push_back(JpegFrame(CorridorJpeg(1), std::nan("")));  // a time that is no time
  frames.push_back(JpegFrame(CorridorJpeg(1), -1.0));          // before the clock's zero
  frames.push_back(JpegFrame(CorridorJpeg(1), 0.0));           // 0.0 is a time: accepted
  pb::StreamConfig config;
  config.set_map("noisy");
  grpc::Status status;
  const auto answers = Stream(*places_, config, frames, &status);
  ASSERT_TRUE(status.ok()) << status.error_message();
  ASSERT_EQ(answers.size(), frames.size());
  for (size_t i = 0; i + 1 < answers.size(); ++i) {
    ASSERT_TRUE(answers[i].has_error()) << "frame " << i;
    EXPECT_EQ(answers[i].error().code(), int(grpc::StatusCode::INVALID_ARGUMENT)) << i;
    EXPECT_FALSE(answers[i].error().message().empty());
  }
  EXPECT_NE(answers[5].error().message().find("keypoints.octave"), std::string::npos)
      << answers[5].error().message();
  EXPECT_NE(answers[6].error().message().find("non-finite value at keypoint 3"), std::string::npos)
      << answers[6].error().message();
  for (size_t i : {answers.size() - 3, answers.size() - 2}) {
    EXPECT_NE(answers[i].error().message().find("frame.timestamp must be finite and >= 0"),
              std::string::npos)
        << answers[i].error().message();
  }
  ASSERT_TRUE(answers.back().has_result());
  EXPECT_EQ(answers.back().result().frame_id(), 0u);  // the failed frames added nothing
}

TEST_F(PlaceServiceTest, StreamsNeedAConfigFirstAndAnExistingMap) {
  grpc::ClientContext context;
  auto stream = places_->StreamFrames(&context);
  pb::StreamFramesRequest request;
  *request.mutable_frame() = JpegFrame(CorridorJpeg(1));
  stream->Write(request);
  stream->WritesDone();
  pb::StreamFramesResponse ignored;
  EXPECT_FALSE(stream->Read(&ignored));
  EXPECT_EQ(stream->Finish().error_code(), grpc::StatusCode::FAILED_PRECONDITION);

  pb::StreamConfig config;
  config.set_map("nowhere");
  grpc::Status status;
  EXPECT_TRUE(Stream(*places_, config, {JpegFrame(CorridorJpeg(1))}, &status).empty());
  EXPECT_EQ(status.error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_EQ(GetMap("nowhere").error_code(), grpc::StatusCode::NOT_FOUND);

  config.set_create_if_missing(true);  // bad result options end the stream before any change
  config.mutable_options()->set_top_k(51);
  EXPECT_TRUE(Stream(*places_, config, {JpegFrame(CorridorJpeg(1))}, &status).empty());
  EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(GetMap("nowhere").error_code(), grpc::StatusCode::NOT_FOUND);
}

TEST_F(PlaceServiceTest, BadUnaryInputGetsItsCodeAndTheServerKeepsServing) {
  ASSERT_TRUE(CreateMap("m").ok());
  pb::AddFrameResponse added;
  EXPECT_EQ(AddFrame("m", JpegFrame("GIF89a garbage"), &added).error_code(),
            grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(AddFrame("unknown", JpegFrame(CorridorJpeg(1)), &added).error_code(),
            grpc::StatusCode::NOT_FOUND);
  pb::Frame bad_intrinsics = JpegFrame(CorridorJpeg(1));
  bad_intrinsics.mutable_intrinsics()->set_fx(-3);
  EXPECT_EQ(AddFrame("m", bad_intrinsics, &added).error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  pb::Frame negative_time = JpegFrame(CorridorJpeg(1), -1);
  EXPECT_EQ(AddFrame("m", negative_time, &added).error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  pb::QueryPlaceRequest query;
  query.set_map("m");
  pb::QueryPlaceResponse response;
  EXPECT_EQ(places_->QueryPlace(Context().get(), query, &response).error_code(),
            grpc::StatusCode::INVALID_ARGUMENT);  // a frame without content
  pb::MapInfo info;
  ASSERT_TRUE(GetMap("m", &info).ok());
  EXPECT_EQ(info.frames(), 0u);
  ASSERT_TRUE(AddFrame("m", JpegFrame(CorridorJpeg(1)), &added).ok());
}

TEST_F(PlaceServiceTest, AnOversizedMessageIsRefusedWithResourceExhausted) {
  StopServer();
  config().max_message_bytes = 1u << 20;
  StartServer();
  ASSERT_TRUE(CreateMap("m").ok());
  pb::AddFrameResponse added;
  EXPECT_EQ(AddFrame("m", JpegFrame(std::string(2u << 20, 'x')), &added).error_code(),
            grpc::StatusCode::RESOURCE_EXHAUSTED);
  ASSERT_TRUE(AddFrame("m", JpegFrame(CorridorJpeg(1)), &added).ok());
}

TEST_F(PlaceServiceTest, MapsAndTheirSettingsSurviveARestart) {
  pb::MapSettings settings;
  settings.set_alpha(0.45);
  settings.set_geometry(pb::GEOMETRY_CHECK_EXHAUSTIVE);
  ASSERT_TRUE(CreateMap("kept", settings).ok());
  for (int n : {1, 20, 41}) {
    pb::AddFrameResponse added;
    ASSERT_TRUE(AddFrame("kept", JpegFrame(CorridorJpeg(n)), &added).ok());
  }
  RestartServer();
  pb::MapInfo info;
  ASSERT_TRUE(GetMap("kept", &info).ok());
  EXPECT_EQ(info.frames(), 3u);
  EXPECT_EQ(info.settings().alpha(), 0.45);
  EXPECT_EQ(info.settings().geometry(), pb::GEOMETRY_CHECK_EXHAUSTIVE);
  pb::QueryPlaceRequest query;
  query.set_map("kept");
  *query.mutable_frame() = JpegFrame(CorridorJpeg(20));
  pb::QueryPlaceResponse response;
  ASSERT_TRUE(places_->QueryPlace(Context().get(), query, &response).ok());
  EXPECT_EQ(response.result().status(), pb::LOOP_STATUS_LOOP_DETECTED);
  EXPECT_EQ(response.result().match_frame_id(), 1u);
  pb::AddFrameResponse added;
  ASSERT_TRUE(AddFrame("kept", JpegFrame(CorridorJpeg(60)), &added).ok());
  EXPECT_EQ(added.frame_id(), 3u);
}

// A stream of frames with intrinsics into a map that wants one keyframe to confirm a loop: the
// revisit's first loop is a candidate with its evidence (checked with the essential matrix), the
// next one is accepted with its confirmation; the setting is kept across a restart.
TEST_F(PlaceServiceTest, AConfirmedLoopComesAfterItsCandidateAndCarriesItsEvidence) {
  pb::StreamConfig config;
  config.set_map("confirmed");
  config.set_create_if_missing(true);
  config.mutable_settings()->set_temporal_matches(0);
  config.mutable_settings()->set_recent_frames(1);
  config.mutable_settings()->set_keyframe_confirmations(1);
  std::vector<pb::Frame> frames;
  for (int n : {1, 20, 1, 1}) {
    pb::Frame frame = JpegFrame(CorridorJpeg(n));
    pb::CameraIntrinsics* k = frame.mutable_intrinsics();
    k->set_fx(400);
    k->set_fy(400);
    k->set_cx(256);
    k->set_cy(192);
    frames.push_back(frame);
  }
  grpc::Status status;
  const auto answers = Stream(*places_, config, frames, &status);
  ASSERT_TRUE(status.ok()) << status.error_message();
  ASSERT_EQ(answers.size(), 4u);
  const pb::LoopResult& candidate = answers[2].result();
  EXPECT_EQ(candidate.status(), pb::LOOP_STATUS_CANDIDATE);
  EXPECT_EQ(candidate.match_frame_id(), 0u);
  EXPECT_TRUE(candidate.evidence().calibrated());
  EXPECT_EQ(candidate.evidence().inliers(), candidate.inliers());
  EXPECT_EQ(candidate.evidence().confirmations(), 0u);
  const pb::LoopResult& loop = answers[3].result();
  EXPECT_EQ(loop.status(), pb::LOOP_STATUS_LOOP_DETECTED);
  EXPECT_EQ(loop.evidence().confirmations(), 1u);
  EXPECT_GT(loop.evidence().spread(), 0.0);
  EXPECT_GE(loop.evidence().in_front(), 0.9);
  RestartServer();
  pb::MapInfo info;
  ASSERT_TRUE(GetMap("confirmed", &info).ok());
  EXPECT_EQ(info.settings().keyframe_confirmations(), 1u);
  // A number that would hold every loop back for ever is refused, and no map is made.
  pb::MapSettings forever;
  forever.set_keyframe_confirmations(4000000000u);
  const grpc::Status refused = CreateMap("forever", forever);
  EXPECT_EQ(refused.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(refused.error_message().find("keyframe_confirmations"), std::string::npos)
      << refused.error_message();
  EXPECT_EQ(GetMap("forever", &info).error_code(), grpc::StatusCode::NOT_FOUND);
}

TEST_F(PlaceServiceTest, AKeyframeMapKeepsItsPresetAcrossARestartAndAnUnknownPresetIsRefused) {
  pb::MapSettings settings;
  settings.set_preset("keyframes");
  settings.set_recent_frames(7);
  ASSERT_TRUE(CreateMap("slam", settings).ok());
  ASSERT_TRUE(CreateMap("video").ok());
  pb::MapSettings unknown;
  unknown.set_preset("sideways");
  const grpc::Status refused = CreateMap("bad", unknown);
  EXPECT_EQ(refused.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(refused.error_message().find("setting preset = 'sideways'"), std::string::npos)
      << refused.error_message();
  RestartServer();
  pb::MapInfo info;
  ASSERT_TRUE(GetMap("slam", &info).ok());
  EXPECT_EQ(info.settings().preset(), "keyframes");
  EXPECT_EQ(info.settings().recent_frames(), 7u) << "the map's own value over the preset's 3";
  ASSERT_TRUE(GetMap("video", &info).ok());
  EXPECT_EQ(info.settings().preset(), "default");
  EXPECT_EQ(info.settings().recent_frames(), 20u);
  EXPECT_EQ(GetMap("bad", &info).error_code(), grpc::StatusCode::NOT_FOUND);
}

// Robot A's map holds corridor frames 1 and 20, robot B's frame 60; robot C, in the same group,
// has been elsewhere. B's view of frame 41 (a revisit of 1) is looked up across the fleet.
TEST_F(PlaceServiceTest, AQueryAcrossAGroupFindsThePlaceInAnotherRobotsMap) {
  CreateFleet({"robot-c"});
  RestartServer();  // the group is kept with the maps
  pb::MapInfo info;
  ASSERT_TRUE(GetMap("robot-c", &info).ok());
  EXPECT_EQ(info.settings().group(), "fleet");

  pb::QueryPlaceRequest query;
  query.set_map("robot-b");
  query.set_add_frame(true);
  query.set_search_group("fleet");
  query.mutable_options()->set_include_relative_pose(true);
  *query.mutable_frame() = JpegFrame(CorridorJpeg(41));
  pb::CameraIntrinsics* k = query.mutable_frame()->mutable_intrinsics();  // 512 x 384 pinhole
  k->set_fx(400);
  k->set_fy(400);
  k->set_cx(256);
  k->set_cy(192);
  pb::QueryPlaceResponse response;
  ASSERT_TRUE(places_->QueryPlace(Context().get(), query, &response).ok());
  ASSERT_EQ(response.inter_map_size(), 1) << "only robot A has been there ('elsewhere' is not "
                                             "in the group, robot B's own loops are in result)";
  const pb::InterMapMatch& match = response.inter_map(0);
  EXPECT_EQ(match.map(), "robot-a");
  EXPECT_EQ(match.result().status(), pb::LOOP_STATUS_LOOP_DETECTED);
  EXPECT_EQ(match.result().match_frame_id(), 0u);
  EXPECT_EQ(match.result().match_client_frame_id(), "a-1");
  EXPECT_GE(match.result().inliers(), 12u);
  EXPECT_TRUE(match.result().has_relative_pose());
  EXPECT_EQ(response.result().frame_id(), 1u) << "the frame joined robot B's own map";
  ASSERT_TRUE(GetMap("robot-a", &info).ok());
  EXPECT_EQ(info.frames(), 2u) << "searching a map adds nothing to it";

  // The same by name, in a stream: every frame is looked up in robot A's map too.
  pb::StreamConfig config;
  config.set_map("robot-c");
  config.add_search_maps("robot-a");
  config.add_search_maps("robot-c");  // its own map: not searched again
  grpc::Status status;
  const auto answers =
      Stream(*places_, config, {JpegFrame(CorridorJpeg(41)), JpegFrame(CorridorJpeg(60))}, &status);
  ASSERT_TRUE(status.ok()) << status.error_message();
  ASSERT_EQ(answers.size(), 2u);
  ASSERT_EQ(answers[0].inter_map_size(), 1);
  EXPECT_EQ(answers[0].inter_map(0).map(), "robot-a");
  EXPECT_EQ(answers[0].inter_map(0).result().match_frame_id(), 0u);
  for (const pb::InterMapMatch& m : answers[1].inter_map()) EXPECT_NE(m.map(), "robot-c");
}

TEST_F(PlaceServiceTest, AnUnknownMapOrGroupInTheSearchSetIsNotFoundAndAddsNothing) {
  ASSERT_TRUE(CreateMap("robot-a").ok());
  for (const auto& [maps, group, named] :
       {std::tuple{std::vector<std::string>{"ghost"}, std::string(), std::string("'ghost'")},
        std::tuple{std::vector<std::string>{}, std::string("no-fleet"),
                   std::string("'no-fleet'")}}) {
    pb::QueryPlaceRequest query;
    query.set_map("robot-a");
    query.set_add_frame(true);
    for (const std::string& m : maps) query.add_search_maps(m);
    query.set_search_group(group);
    *query.mutable_frame() = JpegFrame(CorridorJpeg(1));
    pb::QueryPlaceResponse response;
    const grpc::Status refused = places_->QueryPlace(Context().get(), query, &response);
    EXPECT_EQ(refused.error_code(), grpc::StatusCode::NOT_FOUND);
    EXPECT_NE(refused.error_message().find(named), std::string::npos) << refused.error_message();

    pb::StreamConfig config;
    config.set_map("robot-a");
    for (const std::string& m : maps) config.add_search_maps(m);
    config.set_search_group(group);
    grpc::Status status;
    Stream(*places_, config, {JpegFrame(CorridorJpeg(1))}, &status);
    EXPECT_EQ(status.error_code(), grpc::StatusCode::NOT_FOUND);
    EXPECT_NE(status.error_message().find(named), std::string::npos) << status.error_message();
  }
  pb::MapInfo info;
  ASSERT_TRUE(GetMap("robot-a", &info).ok());
  EXPECT_EQ(info.frames(), 0u);
  pb::MapSettings bad;
  bad.set_group("a fleet");
  const grpc::Status refused = CreateMap("robot-b", bad);
  EXPECT_EQ(refused.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(refused.error_message().find("group"), std::string::npos) << refused.error_message();

  // More than 100 maps to search is INVALID_ARGUMENT, and adds nothing either.
  pb::MapSettings crowd;
  crowd.set_group("crowd");
  for (int i = 0; i < 101; ++i) ASSERT_TRUE(CreateMap("m" + std::to_string(i), crowd).ok());
  pb::QueryPlaceRequest query;
  query.set_map("robot-a");
  query.set_add_frame(true);
  query.set_search_group("crowd");
  *query.mutable_frame() = JpegFrame(CorridorJpeg(1));
  pb::QueryPlaceResponse response;
  const grpc::Status crowded = places_->QueryPlace(Context().get(), query, &response);
  EXPECT_EQ(crowded.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(crowded.error_message().find("at most 100"), std::string::npos)
      << crowded.error_message();
  ASSERT_TRUE(GetMap("robot-a", &info).ok());
  EXPECT_EQ(info.frames(), 0u);
}

TEST_F(PlaceServiceTest, RelocalizeFindsAFewFramesInTheMapsOfAGroupAndAddsNothing) {
  CreateFleet();

  pb::RelocalizeRequest request;
  request.set_group("fleet");
  for (int n : {41, 60}) {
    pb::Frame* frame = request.add_frames();
    *frame = JpegFrame(CorridorJpeg(n));
    frame->set_client_frame_id("q-" + std::to_string(n));
  }
  pb::RelocalizeResponse response;
  ASSERT_TRUE(places_->Relocalize(Context().get(), request, &response).ok());
  std::map<std::string, pb::Relocalization> by_map;
  for (const pb::Relocalization& place : response.places()) by_map[place.map()] = place;
  ASSERT_TRUE(by_map.count("robot-a") && by_map.count("robot-b")) << response.DebugString();
  EXPECT_FALSE(by_map.count("elsewhere")) << "not in the group";
  const pb::Relocalization& a = by_map["robot-a"];
  EXPECT_EQ(a.frame_index(), 0u);
  EXPECT_EQ(a.client_frame_id(), "q-41");
  EXPECT_EQ(a.result().status(), pb::LOOP_STATUS_LOOP_DETECTED);
  EXPECT_EQ(a.result().match_client_frame_id(), "a-1");
  EXPECT_GE(a.result().inliers(), 12u);
  const pb::Relocalization& b = by_map["robot-b"];
  EXPECT_EQ(b.frame_index(), 1u) << "robot B has seen frame 60 only";
  EXPECT_EQ(b.result().match_frame_id(), 0u);
  for (int i = 1; i < response.places_size(); ++i) {  // best first
    const pb::Relocalization &before = response.places(i - 1), &after = response.places(i);
    EXPECT_TRUE(before.frames_recognised() > after.frames_recognised() ||
                (before.frames_recognised() == after.frames_recognised() &&
                 before.result().inliers() >= after.result().inliers()));
  }
  EXPECT_GT(response.timing().features_ms(), 0);

  // A map named besides the group joins the set; max_results keeps the best.
  request.add_maps("elsewhere");
  request.set_max_results(1);
  pb::RelocalizeResponse best;
  ASSERT_TRUE(places_->Relocalize(Context().get(), request, &best).ok());
  ASSERT_EQ(best.places_size(), 1);
  request.set_max_results(0);
  pb::RelocalizeResponse all;
  ASSERT_TRUE(places_->Relocalize(Context().get(), request, &all).ok());
  EXPECT_EQ(all.places_size(), response.places_size() + 1) << "'elsewhere' has seen frame 41";
  EXPECT_EQ(best.places(0).map(), all.places(0).map());
  for (const auto& [name, frames] :
       {std::pair{"robot-a", 2u}, {"robot-b", 1u}, {"elsewhere", 1u}}) {
    pb::MapInfo info;
    ASSERT_TRUE(GetMap(name, &info).ok());
    EXPECT_EQ(info.frames(), frames) << name << ": relocalising adds nothing";
  }
}

TEST_F(PlaceServiceTest, ARelocalizeWithoutFramesOrMapsOrWithABadFrameIsRefusedNamingIt) {
  ASSERT_TRUE(CreateMap("robot-a").ok());
  const auto relocalize = [&](const std::vector<pb::Frame>& frames,
                              const std::vector<std::string>& maps, const std::string& group) {
    pb::RelocalizeRequest request;
    for (const pb::Frame& f : frames) *request.add_frames() = f;
    for (const std::string& m : maps) request.add_maps(m);
    request.set_group(group);
    pb::RelocalizeResponse response;
    return places_->Relocalize(Context().get(), request, &response);
  };
  const pb::Frame frame = JpegFrame(CorridorJpeg(1));
  const pb::Frame broken = JpegFrame("\xff\xd8 this is not a JPEG");
  for (const auto& [status, code, named] : {
           std::tuple{relocalize({}, {"robot-a"}, ""), grpc::StatusCode::INVALID_ARGUMENT,
                      "frames"},
           {relocalize(std::vector<pb::Frame>(11, frame), {"robot-a"}, ""),
            grpc::StatusCode::INVALID_ARGUMENT, "not 11"},
           {relocalize({frame}, {}, ""), grpc::StatusCode::INVALID_ARGUMENT, "maps or a group"},
           {relocalize({frame}, {"robot-a", "ghost"}, ""), grpc::StatusCode::NOT_FOUND, "'ghost'"},
           {relocalize({frame}, {}, "no-fleet"), grpc::StatusCode::NOT_FOUND, "'no-fleet'"},
           {relocalize({frame, broken}, {"robot-a"}, ""), grpc::StatusCode::INVALID_ARGUMENT,
            "frames[1]"},
       }) {
    EXPECT_EQ(status.error_code(), code) << named << ": " << status.error_message();
    EXPECT_NE(status.error_message().find(named), std::string::npos) << status.error_message();
  }
}

// A fleet's token file: robot A writes its own maps and reads its group's; the operator reaches
// every map.
TEST_F(PlaceServiceTest, AScopedTokenReachesOnlyItsOwnMapsAndReadsItsGroups) {
  constexpr char kRobotA[] = "robot-a-token-0123456789", kOperator[] = "operator-token-0123456789";
  const std::string tokens = data_dir_.Sub("tokens.yaml");
  std::ofstream(tokens) << "tokens:\n"
                        << "  - name: robot-a\n    token: " << kRobotA << "\n"
                        << "    rights: [write]\n"
                        << "    maps: {write: [\"robot-a*\"], read: [\"group:fleet\"]}\n"
                        << "  - name: operator\n    token: " << kOperator << "\n"
                        << "    rights: [write]\n";
  StopServer();
  config().token_file = tokens;
  StartServer();
  const auto denied_naming = [](const grpc::Status& status, const std::string& map) {
    return status.error_code() == grpc::StatusCode::PERMISSION_DENIED &&
           status.error_message().find("'" + map + "'") != std::string::npos;
  };
  const auto create = [&](const char* token, const std::string& name, const std::string& group) {
    pb::CreateMapRequest request;
    request.set_name(name);
    if (!group.empty()) request.mutable_settings()->set_group(group);
    pb::CreateMapResponse response;
    return places_->CreateMap(Context(token).get(), request, &response);
  };
  const auto add = [&](const char* token, const std::string& map, int frame) {
    pb::AddFrameRequest request;
    request.set_map(map);
    *request.mutable_frame() = JpegFrame(CorridorJpeg(frame));
    pb::AddFrameResponse response;
    return places_->AddFrame(Context(token).get(), request, &response);
  };
  const auto frames_of = [&](const std::string& map) {
    pb::GetMapRequest request;
    request.set_name(map);
    pb::GetMapResponse response;
    EXPECT_TRUE(places_->GetMap(Context(kOperator).get(), request, &response).ok()) << map;
    return response.map().frames();
  };
  ASSERT_TRUE(create(kOperator, "robot-b", "fleet").ok());
  ASSERT_TRUE(create(kOperator, "secret", "").ok());
  ASSERT_TRUE(add(kOperator, "robot-b", 1).ok());
  ASSERT_TRUE(add(kOperator, "secret", 1).ok());
  ASSERT_TRUE(create(kRobotA, "robot-a", "fleet").ok());
  ASSERT_TRUE(create(kRobotA, "robot-a-tuesday", "").ok());  // the prefix
  EXPECT_TRUE(denied_naming(create(kRobotA, "other", "fleet"), "other"));
  EXPECT_TRUE(denied_naming(add(kRobotA, "robot-b", 41), "robot-b"));
  ASSERT_TRUE(add(kRobotA, "robot-a", 20).ok());

  pb::ListMapsResponse listed;
  ASSERT_TRUE(places_->ListMaps(Context(kRobotA).get(), {}, &listed).ok());
  std::vector<std::string> names;
  for (const pb::MapInfo& m : listed.maps()) names.push_back(m.name());
  EXPECT_EQ(names, (std::vector<std::string>{"robot-a", "robot-a-tuesday", "robot-b"}));
  ASSERT_TRUE(places_->ListMaps(Context(kOperator).get(), {}, &listed).ok());
  EXPECT_EQ(listed.maps_size(), 4);

  // Its own map with its group's searched: allowed; with a map outside its reach: refused, and
  // the frame is not added.
  pb::QueryPlaceRequest query;
  query.set_map("robot-a");
  query.set_add_frame(true);
  query.set_search_group("fleet");
  *query.mutable_frame() = JpegFrame(CorridorJpeg(41));
  pb::QueryPlaceResponse answer;
  ASSERT_TRUE(places_->QueryPlace(Context(kRobotA).get(), query, &answer).ok());
  ASSERT_EQ(answer.inter_map_size(), 1);
  EXPECT_EQ(answer.inter_map(0).map(), "robot-b");
  query.add_search_maps("secret");
  EXPECT_TRUE(denied_naming(places_->QueryPlace(Context(kRobotA).get(), query, &answer), "secret"));
  EXPECT_EQ(frames_of("robot-a"), 2u);
  query.clear_search_maps();
  query.set_map("robot-b");
  EXPECT_TRUE(
      denied_naming(places_->QueryPlace(Context(kRobotA).get(), query, &answer), "robot-b"));
  query.set_add_frame(false);  // reading its group's map is allowed
  EXPECT_TRUE(places_->QueryPlace(Context(kRobotA).get(), query, &answer).ok());

  pb::RelocalizeRequest relocalize;
  *relocalize.add_frames() = JpegFrame(CorridorJpeg(41));
  relocalize.set_group("fleet");
  pb::RelocalizeResponse places;
  EXPECT_TRUE(places_->Relocalize(Context(kRobotA).get(), relocalize, &places).ok());
  relocalize.add_maps("secret");
  EXPECT_TRUE(
      denied_naming(places_->Relocalize(Context(kRobotA).get(), relocalize, &places), "secret"));

  pb::GetMapRequest get;
  get.set_name("secret");
  pb::GetMapResponse got;
  EXPECT_TRUE(denied_naming(places_->GetMap(Context(kRobotA).get(), get, &got), "secret"));
  pb::DeleteMapRequest remove;
  remove.set_name("robot-b");
  pb::DeleteMapResponse removed;
  EXPECT_TRUE(
      denied_naming(places_->DeleteMap(Context(kRobotA).get(), remove, &removed), "robot-b"));
  pb::RemoveFrameRequest cull;
  cull.set_map("robot-b");
  cull.set_frame_id(0);
  pb::RemoveFrameResponse culled;
  EXPECT_TRUE(
      denied_naming(places_->RemoveFrame(Context(kRobotA).get(), cull, &culled), "robot-b"));
  EXPECT_EQ(frames_of("robot-b"), 1u);

  pb::StreamConfig config;
  config.set_map("robot-b");
  grpc::Status status;
  Stream(*places_, config, {JpegFrame(CorridorJpeg(41))}, &status, Context(kRobotA));
  EXPECT_TRUE(denied_naming(status, "robot-b")) << status.error_message();
  config.set_map("outsider");
  config.set_create_if_missing(true);
  Stream(*places_, config, {JpegFrame(CorridorJpeg(41))}, &status, Context(kRobotA));
  EXPECT_TRUE(denied_naming(status, "outsider")) << status.error_message();
  config.set_map("robot-b");
  config.set_create_if_missing(false);
  config.set_query_only(true);
  const auto answers =
      Stream(*places_, config, {JpegFrame(CorridorJpeg(41))}, &status, Context(kRobotA));
  EXPECT_TRUE(status.ok()) << status.error_message();
  EXPECT_EQ(answers.size(), 1u);
  EXPECT_EQ(frames_of("robot-b"), 1u);
  EXPECT_EQ(places_->ListMaps(Context(kOperator).get(), {}, &listed).ok() ? listed.maps_size() : 0,
            4)
      << "the refused stream created no map";
}

TEST_F(PlaceServiceTest, ASlamGetsItsKeyframeIdsTopCandidatesAndInlierPixelsBack) {
  ASSERT_TRUE(CreateMap("slam").ok());
  std::map<int, pb::Frame> frames;
  for (int n : {1, 20, 41, 60}) {
    frames[n] = FeaturesFrame(CorridorJpeg(n));
    pb::Frame frame = frames[n];
    frame.set_client_frame_id("kf-" + std::to_string(n));
    pb::AddFrameResponse added;
    ASSERT_TRUE(AddFrame("slam", frame, &added).ok());
    EXPECT_EQ(added.client_frame_id(), "kf-" + std::to_string(n));
  }
  pb::QueryPlaceRequest query;
  query.set_map("slam");
  *query.mutable_frame() = frames[41];
  query.mutable_frame()->set_client_frame_id("probe");
  query.mutable_options()->set_top_k(3);
  query.mutable_options()->set_include_correspondences(true);
  pb::QueryPlaceResponse response;
  ASSERT_TRUE(places_->QueryPlace(Context().get(), query, &response).ok());
  const pb::LoopResult& result = response.result();
  ASSERT_EQ(result.status(), pb::LOOP_STATUS_LOOP_DETECTED);
  EXPECT_EQ(result.match_frame_id(), 2u);
  EXPECT_EQ(result.match_client_frame_id(), "kf-41");  // the match's, not the query's
  EXPECT_EQ(response.client_frame_id(), "probe");
  ASSERT_GE(result.candidates_size(), 1);
  EXPECT_LE(result.candidates_size(), 3);
  const std::map<uint64_t, std::string> client_ids = {
      {0, "kf-1"}, {1, "kf-20"}, {2, "kf-41"}, {3, "kf-60"}};
  for (int i = 0; i < result.candidates_size(); ++i) {
    const pb::Candidate& c = result.candidates(i);
    EXPECT_EQ(c.client_frame_id(), client_ids.at(c.frame_id()));
    if (i > 0) {
      EXPECT_LE(c.score(), result.candidates(i - 1).score());
    }
    EXPECT_EQ(c.has_inliers(), c.frame_id() == result.match_frame_id());
  }
  EXPECT_EQ(result.candidates(0).frame_id(), 2u);  // the same image scores best
  EXPECT_EQ(result.candidates(0).inliers(), result.inliers());
  ASSERT_EQ(result.inlier_correspondences_size(), int(result.inliers()));
  const pb::Keypoints& query_keys = frames[41].features().keypoints();  // as sent and stored
  for (const pb::Correspondence& c : result.inlier_correspondences()) {
    ASSERT_LT(int(c.query_index()), query_keys.x_size());
    ASSERT_LT(int(c.match_index()), query_keys.x_size());
    EXPECT_EQ(c.query_x(), query_keys.x(int(c.query_index())));
    EXPECT_EQ(c.query_y(), query_keys.y(int(c.query_index())));
    EXPECT_EQ(c.match_x(), query_keys.x(int(c.match_index())));
    EXPECT_EQ(c.match_y(), query_keys.y(int(c.match_index())));
  }

  // The SLAM's keyframes covisible with the query (here the same image, frame 2) are left out:
  // never a candidate, never the match.
  query.mutable_frame()->add_exclude_frame_ids(2);
  query.mutable_frame()->add_exclude_frame_ids(uint64_t{1} << 40);  // no map holds it: ignored
  ASSERT_TRUE(places_->QueryPlace(Context().get(), query, &response).ok());
  EXPECT_NE(response.result().match_frame_id(), 2u);
  for (const pb::Candidate& c : response.result().candidates()) EXPECT_NE(c.frame_id(), 2u);
  for (int i = 0; i < 1000; ++i) query.mutable_frame()->add_exclude_frame_ids(uint64_t(i));
  const grpc::Status too_many = places_->QueryPlace(Context().get(), query, &response);
  EXPECT_EQ(too_many.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(too_many.error_message().find("exclude_frame_ids"), std::string::npos)
      << too_many.error_message();
  query.mutable_frame()->clear_exclude_frame_ids();

  query.mutable_options()->set_top_k(51);  // above the documented maximum
  EXPECT_EQ(places_->QueryPlace(Context().get(), query, &response).error_code(),
            grpc::StatusCode::INVALID_ARGUMENT);
}

TEST_F(PlaceServiceTest, RemovedFramesAreNeverCandidatesAgainAcrossARestart) {
  ASSERT_TRUE(CreateMap("cull").ok());
  for (int n : {1, 20, 41, 60}) {
    pb::Frame frame = JpegFrame(CorridorJpeg(n), n);
    frame.set_client_frame_id("kf-" + std::to_string(n));
    pb::AddFrameResponse added;
    ASSERT_TRUE(AddFrame("cull", frame, &added).ok());
  }
  const auto remove = [this](const std::string& map, std::optional<uint64_t> id,
                             std::optional<std::string> client_id, pb::RemoveFrameResponse* out) {
    pb::RemoveFrameRequest request;
    request.set_map(map);
    if (id.has_value()) request.set_frame_id(*id);
    if (client_id.has_value()) request.set_client_frame_id(*client_id);
    return places_->RemoveFrame(Context().get(), request, out);
  };
  pb::RemoveFrameResponse removed;
  ASSERT_TRUE(remove("cull", 2, std::nullopt, &removed).ok());
  EXPECT_EQ(
      std::vector<uint64_t>(removed.removed_frame_ids().begin(), removed.removed_frame_ids().end()),
      std::vector<uint64_t>{2});
  ASSERT_TRUE(remove("cull", std::nullopt, "kf-60", &removed).ok());
  EXPECT_EQ(
      std::vector<uint64_t>(removed.removed_frame_ids().begin(), removed.removed_frame_ids().end()),
      std::vector<uint64_t>{3});
  EXPECT_EQ(remove("cull", 2, std::nullopt, &removed).error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_EQ(remove("cull", 99, std::nullopt, &removed).error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_EQ(remove("cull", std::nullopt, "kf-60", &removed).error_code(),
            grpc::StatusCode::NOT_FOUND);
  EXPECT_EQ(remove("nowhere", 0, std::nullopt, &removed).error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_EQ(remove("cull", std::nullopt, std::nullopt, &removed).error_code(),
            grpc::StatusCode::INVALID_ARGUMENT);

  RestartServer();
  pb::MapInfo info;
  ASSERT_TRUE(GetMap("cull", &info).ok());
  EXPECT_EQ(info.frames(), 2u);
  EXPECT_EQ(info.next_frame_id(), 4u);
  pb::QueryPlaceRequest query;
  query.set_map("cull");
  *query.mutable_frame() = JpegFrame(CorridorJpeg(41));
  query.mutable_options()->set_top_k(50);
  pb::QueryPlaceResponse response;
  ASSERT_TRUE(places_->QueryPlace(Context().get(), query, &response).ok());
  EXPECT_NE(response.result().match_frame_id(), 2u);
  for (const pb::Candidate& c : response.result().candidates()) EXPECT_LT(c.frame_id(), 2u);
  *query.mutable_frame() = JpegFrame(CorridorJpeg(20));  // the kept frames keep their client ids
  ASSERT_TRUE(places_->QueryPlace(Context().get(), query, &response).ok());
  EXPECT_EQ(response.result().status(), pb::LOOP_STATUS_LOOP_DETECTED);
  EXPECT_EQ(response.result().match_frame_id(), 1u);
  EXPECT_EQ(response.result().match_client_frame_id(), "kf-20");
}

TEST_F(PlaceServiceTest, AFullQueueAnswersResourceExhaustedWithGrpcsRetryPushback) {
  StopServer();
  config().workers = 1;
  config().queue_capacity = 1;
  StartServer();
  ASSERT_TRUE(CreateMap("busy").ok());
  constexpr int kCalls = 16;
  std::mutex mutex;
  std::condition_variable done;
  int finished = 0, ok = 0, busy = 0, hinted = 0;
  std::vector<std::unique_ptr<grpc::ClientContext>> contexts;
  std::vector<pb::AddFrameRequest> requests(kCalls);
  std::vector<pb::AddFrameResponse> responses(kCalls);
  const std::string jpeg = CorridorJpeg(1);
  for (int i = 0; i < kCalls; ++i) {
    contexts.push_back(Context());
    requests[i].set_map("busy");
    *requests[i].mutable_frame() = JpegFrame(jpeg);
  }
  for (int i = 0; i < kCalls; ++i) {
    grpc::ClientContext* context = contexts[i].get();
    places_->async()->AddFrame(context, &requests[i], &responses[i],
                               [&, context](grpc::Status status) {
                                 std::lock_guard lock(mutex);
                                 if (status.ok()) ++ok;
                                 if (status.error_code() == grpc::StatusCode::RESOURCE_EXHAUSTED) {
                                   ++busy;
                                   const auto& trailers = context->GetServerTrailingMetadata();
                                   const auto hint = trailers.find("grpc-retry-pushback-ms");
                                   if (hint != trailers.end() && hint->second == "100") ++hinted;
                                 }
                                 ++finished;
                                 done.notify_all();
                               });
  }
  std::unique_lock lock(mutex);
  done.wait(lock, [&] { return finished == kCalls; });
  EXPECT_GT(busy, 0);
  EXPECT_EQ(hinted, busy);
  EXPECT_EQ(ok + busy, kCalls);
  lock.unlock();
  pb::MapInfo info;
  ASSERT_TRUE(GetMap("busy", &info).ok());
  EXPECT_EQ(info.frames(), uint64_t(ok));  // refused calls added nothing
}

TEST_F(PlaceServiceTest, ARepeatedRequestIdIsAnsweredWithTheFirstAnswerAndChangesNothing) {
  ASSERT_TRUE(CreateMap("idem").ok());
  pb::AddFrameRequest request;
  request.set_map("idem");
  *request.mutable_frame() = JpegFrame(CorridorJpeg(1));
  request.set_request_id("7f0c1c62-3d5e-4b8a-9d0e-2b4f6a1c9e01");
  pb::AddFrameResponse first, repeat, other;
  ASSERT_TRUE(places_->AddFrame(Context().get(), request, &first).ok());
  ASSERT_TRUE(places_->AddFrame(Context().get(), request, &repeat).ok());
  EXPECT_EQ(repeat.SerializeAsString(), first.SerializeAsString());  // the same frame_id, timing
  pb::MapInfo info;
  ASSERT_TRUE(GetMap("idem", &info).ok());
  EXPECT_EQ(info.frames(), 1u);

  request.set_request_id("another id");
  ASSERT_TRUE(places_->AddFrame(Context().get(), request, &other).ok());
  EXPECT_NE(other.frame_id(), first.frame_id());
  request.clear_request_id();  // no id: every call applies
  ASSERT_TRUE(places_->AddFrame(Context().get(), request, &other).ok());
  ASSERT_TRUE(GetMap("idem", &info).ok());
  EXPECT_EQ(info.frames(), 3u);

  // QueryPlace with add_frame is remembered; a relocalisation query just runs again.
  pb::QueryPlaceRequest query;
  query.set_map("idem");
  *query.mutable_frame() = JpegFrame(CorridorJpeg(20));
  query.set_add_frame(true);
  query.set_request_id("query-1");
  pb::QueryPlaceResponse queried, requeried;
  const grpc::Status queried_status = places_->QueryPlace(Context().get(), query, &queried);
  ASSERT_TRUE(queried_status.ok()) << queried_status.error_message();
  ASSERT_TRUE(places_->QueryPlace(Context().get(), query, &requeried).ok());
  EXPECT_EQ(requeried.result().frame_id(), queried.result().frame_id());
  ASSERT_TRUE(GetMap("idem", &info).ok());
  EXPECT_EQ(info.frames(), 4u);

  // The repeat of a deletion or a creation gets the first answer, not NOT_FOUND or
  // ALREADY_EXISTS.
  pb::DeleteMapRequest remove;
  remove.set_name("idem");
  remove.set_request_id("delete-1");
  pb::DeleteMapResponse removed, removed_again;
  ASSERT_TRUE(places_->DeleteMap(Context().get(), remove, &removed).ok());
  ASSERT_TRUE(places_->DeleteMap(Context().get(), remove, &removed_again).ok());
  EXPECT_EQ(removed_again.frames_deleted(), 4u);
  pb::CreateMapRequest create;
  create.set_name("idem2");
  create.set_request_id("create-1");
  pb::CreateMapResponse created, created_again;
  ASSERT_TRUE(places_->CreateMap(Context().get(), create, &created).ok());
  ASSERT_TRUE(places_->CreateMap(Context().get(), create, &created_again).ok());
  EXPECT_EQ(created_again.map().id(), created.map().id());
  create.set_request_id("create-2");  // a new id is a new call
  EXPECT_EQ(places_->CreateMap(Context().get(), create, &created_again).error_code(),
            grpc::StatusCode::ALREADY_EXISTS);
}

TEST_F(PlaceServiceTest, AFailedCallIsNotRememberedAndBadRequestIdsAreRefused) {
  pb::AddFrameRequest request;
  request.set_map("later");
  *request.mutable_frame() = JpegFrame(CorridorJpeg(1));
  request.set_request_id("retry-me");
  pb::AddFrameResponse response;
  EXPECT_EQ(places_->AddFrame(Context().get(), request, &response).error_code(),
            grpc::StatusCode::NOT_FOUND);
  ASSERT_TRUE(CreateMap("later").ok());
  EXPECT_TRUE(places_->AddFrame(Context().get(), request, &response).ok());  // runs again

  for (const std::string& bad : {std::string(129, 'x'), std::string("line\nbreak")}) {
    request.set_request_id(bad);
    EXPECT_EQ(places_->AddFrame(Context().get(), request, &response).error_code(),
              grpc::StatusCode::INVALID_ARGUMENT);
  }
  pb::MapInfo info;
  ASSERT_TRUE(GetMap("later", &info).ok());
  EXPECT_EQ(info.frames(), 1u);
}

}  // namespace
}  // namespace recog::server::testing

namespace recog::server::testing {
namespace {

// A server of shard "shard_a" serves the maps the placement table gives it, refuses the others
// naming their owner, and follows the table when it is reloaded.
// Metric loops: frames rendered from a scene of known geometry (tools/evaluation/metric_sequence.h,
// the corridor photos on planes at 1.6, 2.6 and 4 m), with their exact depth or right image.
const cv::Matx33d kK(525, 0, 319.5, 0, 525, 239.5, 0, 0, 1);
const cv::Size kSize(640, 480);
constexpr double kBaseline = 0.12;

cv::Mat CorridorPhoto(int n) {
  const std::string jpeg = CorridorJpeg(n);
  return cv::imdecode(cv::Mat(1, int(jpeg.size()), CV_8U, (void*)jpeg.data()),
                      cv::IMREAD_GRAYSCALE);
}

cli::RenderedFrame Render(const cli::CameraPose& pose, const cv::Matx33d& K = kK) {
  cv::Mat back;
  cv::hconcat(CorridorPhoto(41), CorridorPhoto(60), back);
  const std::vector<cli::TexturedPlane> scene = {
      {back, {0, 0, 4.0}, {1, 0, 0}, {0, 1, 0}, 6.0, 2.25},
      {CorridorPhoto(1), {-0.7, 0.1, 2.6}, cli::Yaw(25) * cv::Vec3d(1, 0, 0), {0, 1, 0}, 1.6, 1.2},
      {CorridorPhoto(20), {0.55, -0.2, 1.6}, {1, 0, 0}, {0, 1, 0}, 0.9, 0.675},
  };
  auto frame = cli::RenderPlanes(scene, K, kSize, pose, kBaseline);
  EXPECT_TRUE(frame.ok()) << frame.status().ToString();
  return std::move(frame).value();
}

// The rendered image with the pinhole intrinsics it was rendered with.
pb::Frame CalibratedFrame(const cli::RenderedFrame& rendered, const cv::Matx33d& K = kK) {
  pb::Frame frame = client::FrameFromImage(rendered.image).value();
  pb::CameraIntrinsics* k = frame.mutable_intrinsics();
  k->set_fx(K(0, 0));
  k->set_fy(K(1, 1));
  k->set_cx(K(0, 2));
  k->set_cy(K(1, 2));
  return frame;
}

pb::Frame RgbdFrame(const cli::RenderedFrame& rendered, const cv::Matx33d& K = kK) {
  pb::Frame frame = CalibratedFrame(rendered, K);
  EXPECT_TRUE(client::AttachDepth(rendered.depth_mm, 1000, &frame).ok());
  return frame;
}

// Checks a verified metric loop against the true pose of the query relative to the match:
// translation within 3 % of the distance between the cameras, rotation within 0.3°.
void ExpectMetricPose(const pb::LoopResult& result, const cli::CameraPose& query,
                      const cli::CameraPose& match) {
  ASSERT_EQ(result.status(), pb::LOOP_STATUS_LOOP_DETECTED);
  const pb::MetricLoop& metric = result.metric();
  ASSERT_TRUE(metric.checked());
  ASSERT_TRUE(metric.verified());
  EXPECT_GE(metric.inliers(), 12u);
  EXPECT_GE(metric.correspondences(), metric.inliers());
  EXPECT_LT(metric.rms_error_px(), 2.0);
  ASSERT_EQ(metric.pose().rotation_size(), 9);
  ASSERT_EQ(metric.pose().translation_size(), 3);
  ASSERT_EQ(metric.covariance_size(), 36);
  cv::Matx33d R_true, R;
  cv::Vec3d t_true, t;
  cli::RelativePose(query, match, &R_true, &t_true);
  for (int i = 0; i < 9; ++i) R.val[i] = metric.pose().rotation(i);
  for (int i = 0; i < 3; ++i) t[i] = metric.pose().translation(i);
  cv::Vec3d rotation_error;
  cv::Rodrigues(cv::Mat(R * R_true.t()), rotation_error);
  std::printf("metric loop: %u inliers, translation error %.2f %% of %.3f m, rotation %.3f deg\n",
              metric.inliers(), 100 * cv::norm(t - t_true) / cv::norm(query.center - match.center),
              cv::norm(query.center - match.center), cv::norm(rotation_error) * 180 / CV_PI);
  EXPECT_LT(cv::norm(rotation_error) * 180 / CV_PI, 0.3);
  EXPECT_LT(cv::norm(t - t_true), 0.03 * cv::norm(query.center - match.center))
      << "t " << t << " true " << t_true;
  for (int i = 0; i < 6; ++i) EXPECT_GT(metric.covariance(i * 7), 0.0) << "variance " << i;
}

TEST_F(PlaceServiceTest, RgbdAndStereoFramesGiveMetricLoopsCloseToTheTruth) {
  // Keyframes along x at yaw 0 with depth (AddFrame); a revisit 0.25 m closer, 0.08 m lower and
  // turned 3°, sent with intrinsics only (QueryPlace), then with depth through a stream.
  const std::vector<cli::CameraPose> keyframes = {
      {cli::Yaw(0), {-0.3, 0, 0}}, {cli::Yaw(0), {0, 0, 0}}, {cli::Yaw(0), {0.3, 0, 0}}};
  const cli::CameraPose revisit{cli::Yaw(3), {0.05, 0.08, 0.25}};
  const cli::RenderedFrame query = Render(revisit);
  pb::MapSettings settings;
  settings.set_temporal_matches(0);
  settings.set_recent_frames(1);
  ASSERT_TRUE(CreateMap("rgbd", settings).ok());
  std::vector<pb::Frame> stream_frames;
  for (const cli::CameraPose& pose : keyframes) {
    const pb::Frame frame = RgbdFrame(Render(pose));
    pb::AddFrameResponse added;
    ASSERT_TRUE(AddFrame("rgbd", frame, &added).ok());
    stream_frames.push_back(frame);
  }
  pb::QueryPlaceRequest request;
  request.set_map("rgbd");
  *request.mutable_frame() = CalibratedFrame(query);
  pb::QueryPlaceResponse response;
  ASSERT_TRUE(places_->QueryPlace(Context().get(), request, &response).ok());
  ASSERT_TRUE(response.result().has_match_frame_id());
  const uint64_t match = response.result().match_frame_id();
  ASSERT_LT(match, keyframes.size());
  ExpectMetricPose(response.result(), revisit, keyframes[match]);

  *request.mutable_frame() = JpegFrame(CorridorJpeg(1));  // no intrinsics: no 3D check
  ASSERT_TRUE(places_->QueryPlace(Context().get(), request, &response).ok());
  EXPECT_FALSE(response.result().has_metric());

  // A writing stream (Detect) on a fresh map: the revisit, with depth, closes a metric loop.
  stream_frames.push_back(RgbdFrame(query));
  pb::StreamConfig config;
  config.set_map("rgbd-stream");
  config.set_create_if_missing(true);
  *config.mutable_settings() = settings;
  grpc::Status status;
  const auto answers = Stream(*places_, config, stream_frames, &status);
  ASSERT_TRUE(status.ok()) << status.error_message();
  ASSERT_EQ(answers.size(), stream_frames.size());
  ASSERT_TRUE(answers.back().has_result()) << answers.back().error().message();
  const pb::LoopResult& loop = answers.back().result();
  ASSERT_TRUE(loop.has_match_frame_id());
  ExpectMetricPose(loop, revisit, keyframes[loop.match_frame_id()]);

  // Stereo keyframes: the same revisit finds a metric loop against points from disparities.
  ASSERT_TRUE(CreateMap("stereo").ok());
  for (const cli::CameraPose& pose : keyframes) {
    const cli::RenderedFrame rendered = Render(pose);
    pb::Frame frame = CalibratedFrame(rendered);
    ASSERT_TRUE(client::AttachStereoRight(rendered.right, kBaseline, &frame).ok());
    pb::AddFrameResponse added;
    ASSERT_TRUE(AddFrame("stereo", frame, &added).ok());
  }
  request.set_map("stereo");
  *request.mutable_frame() = CalibratedFrame(query);
  ASSERT_TRUE(places_->QueryPlace(Context().get(), request, &response).ok());
  ASSERT_TRUE(response.result().has_match_frame_id());
  ExpectMetricPose(response.result(), revisit, keyframes[response.result().match_frame_id()]);
}

// A rig map whose camera has a stereo partner: the views of its keyframes carry their right
// images, and a revisit's plain view closes a metric loop whose body pose (the camera's: the rig's
// one camera sits at the body's origin) is the truth.
TEST_F(PlaceServiceTest, ARigViewWithItsStereoPartnerGivesAMetricBodyPose) {
  const std::vector<cli::CameraPose> keyframes = {
      {cli::Yaw(0), {-0.3, 0, 0}}, {cli::Yaw(0), {0, 0, 0}}, {cli::Yaw(0), {0.3, 0, 0}}};
  const cli::CameraPose revisit{cli::Yaw(3), {0.05, 0.08, 0.25}};
  pb::MapSettings settings;
  *settings.add_rig() = client::MakeRigCamera("left", kSize, kK, {}, cv::Matx33d::eye(), {});
  ASSERT_TRUE(CreateMap("stereo-rig", settings).ok());
  const auto view = [](const cli::RenderedFrame& rendered) {
    pb::Frame frame = CalibratedFrame(rendered);
    frame.clear_intrinsics();  // the rig has them
    return frame;
  };
  for (const cli::CameraPose& pose : keyframes) {
    const cli::RenderedFrame rendered = Render(pose);
    pb::Frame left = view(rendered);
    ASSERT_TRUE(client::AttachStereoRight(rendered.right, kBaseline, &left).ok());
    pb::Frame frame;
    ASSERT_TRUE(client::AddRigView("left", left, &frame).ok());
    pb::AddFrameResponse added;
    ASSERT_TRUE(AddFrame("stereo-rig", frame, &added).ok());
  }
  pb::QueryPlaceRequest request;
  request.set_map("stereo-rig");
  ASSERT_TRUE(client::AddRigView("left", view(Render(revisit)), request.mutable_frame()).ok());
  pb::QueryPlaceResponse response;
  ASSERT_TRUE(places_->QueryPlace(Context().get(), request, &response).ok());
  const pb::LoopResult& result = response.result();
  ASSERT_EQ(result.status(), pb::LOOP_STATUS_LOOP_DETECTED);
  ASSERT_LT(result.match_frame_id(), keyframes.size());  // one camera: one id a rig frame
  ASSERT_EQ(result.rig().pairs_size(), 1);
  EXPECT_TRUE(result.rig().pairs(0).metric());
  ASSERT_TRUE(result.rig().metric());
  ASSERT_EQ(result.rig().covariance_size(), 36);
  cv::Matx33d R_true, R;
  cv::Vec3d t_true, t;
  const cli::CameraPose& match = keyframes[result.match_frame_id()];
  cli::RelativePose(revisit, match, &R_true, &t_true);
  for (int i = 0; i < 9; ++i) R.val[i] = result.rig().body_pose().rotation(i);
  for (int i = 0; i < 3; ++i) t[i] = result.rig().body_pose().translation(i);
  cv::Vec3d rotation_error;
  cv::Rodrigues(cv::Mat(R * R_true.t()), rotation_error);
  EXPECT_LT(cv::norm(rotation_error) * 180 / CV_PI, 0.3);
  EXPECT_LT(cv::norm(t - t_true), 0.03 * cv::norm(revisit.center - match.center))
      << "t " << t << " true " << t_true;
}

// The other side has the depth: robot A's map was built with intrinsics only (the server keeps
// each frame's camera matrix), robot B relocalises in it with an RGB-D frame of its own camera
// (other intrinsics). The metric pose is solved from B's points and A's pixels, in the same
// convention as above; the two-view relative pose normalises each side with its own camera.
TEST_F(PlaceServiceTest, AnRgbdQueryGetsTheMetricPoseInAMapBuiltWithoutDepth) {
  const std::vector<cli::CameraPose> keyframes = {
      {cli::Yaw(0), {-0.3, 0, 0}}, {cli::Yaw(0), {0, 0, 0}}, {cli::Yaw(0), {0.3, 0, 0}}};
  const cli::CameraPose revisit{cli::Yaw(3), {0.05, 0.08, 0.25}};
  ASSERT_TRUE(CreateMap("calibrated").ok());
  ASSERT_TRUE(CreateMap("uncalibrated").ok());
  for (const cli::CameraPose& pose : keyframes) {
    const cli::RenderedFrame rendered = Render(pose);
    pb::AddFrameResponse added;
    ASSERT_TRUE(AddFrame("calibrated", CalibratedFrame(rendered), &added).ok());
    ASSERT_TRUE(
        AddFrame("uncalibrated", client::FrameFromImage(rendered.image).value(), &added).ok());
  }
  pb::RelocalizeRequest request;
  request.add_maps("calibrated");
  request.add_maps("uncalibrated");
  const cv::Matx33d robot_b_camera(600, 0, 330, 0, 590, 250, 0, 0, 1);
  *request.add_frames() = RgbdFrame(Render(revisit, robot_b_camera), robot_b_camera);
  request.mutable_options()->set_include_relative_pose(true);
  pb::RelocalizeResponse response;
  ASSERT_TRUE(places_->Relocalize(Context().get(), request, &response).ok());
  std::map<std::string, pb::LoopResult> by_map;
  for (const pb::Relocalization& place : response.places()) by_map[place.map()] = place.result();
  ASSERT_TRUE(by_map.count("calibrated") && by_map.count("uncalibrated")) << response.DebugString();
  const pb::LoopResult& calibrated = by_map["calibrated"];
  ASSERT_LT(calibrated.match_frame_id(), keyframes.size());
  ExpectMetricPose(calibrated, revisit, keyframes[calibrated.match_frame_id()]);
  // T_match<-query up to scale: the inverse rotation of the metric pose's, the direction of its
  // inverse translation.
  cv::Matx33d R_true;
  cv::Vec3d t_true;
  cli::RelativePose(revisit, keyframes[calibrated.match_frame_id()], &R_true, &t_true);
  ASSERT_EQ(calibrated.relative_pose().rotation_size(), 9);
  cv::Matx33d R;
  cv::Vec3d t;
  for (int i = 0; i < 9; ++i) R.val[i] = calibrated.relative_pose().rotation(i);
  for (int i = 0; i < 3; ++i) t[i] = calibrated.relative_pose().translation(i);
  cv::Vec3d rotation_error;
  cv::Rodrigues(cv::Mat(R * R_true), rotation_error);  // R should be R_true^T
  EXPECT_LT(cv::norm(rotation_error) * 180 / CV_PI, 1.0);
  EXPECT_GT(t.dot(cv::normalize(-(R_true.t() * t_true))), 0.98) << "t " << t;
  // Frames added without intrinsics have no camera to project the query's points into.
  EXPECT_FALSE(by_map["uncalibrated"].metric().checked());
}

TEST_F(PlaceServiceTest, DepthAndStereoThatCannotGoWithTheFrameAreRefusedAndAddNothing) {
  ASSERT_TRUE(CreateMap("strict").ok());
  const cli::RenderedFrame rendered = Render({});
  const pb::Frame good = RgbdFrame(rendered);
  std::vector<std::pair<pb::Frame, std::string>> bad;  // frame, words its error must contain
  pb::Frame wrong_size = CalibratedFrame(rendered);
  cv::Mat small;
  cv::resize(rendered.depth_mm, small, {320, 240}, 0, 0, cv::INTER_NEAREST);
  ASSERT_TRUE(client::AttachDepth(small, 1000, &wrong_size).ok());
  bad.emplace_back(wrong_size, "aligned with the 640x480 image");
  pb::Frame eight_bit = CalibratedFrame(rendered);
  std::vector<uchar> png;
  cv::Mat depth8;
  rendered.depth_mm.convertTo(depth8, CV_8U, 1.0 / 16);
  ASSERT_TRUE(cv::imencode(".png", depth8, png));
  eight_bit.mutable_depth()->set_encoded(std::string(png.begin(), png.end()));
  bad.emplace_back(eight_bit, "16-bit");
  pb::Frame no_baseline = CalibratedFrame(rendered);
  ASSERT_TRUE(client::AttachStereoRight(rendered.right, kBaseline, &no_baseline).ok());
  no_baseline.mutable_right()->clear_baseline_m();
  bad.emplace_back(no_baseline, "baseline_m");
  pb::Frame no_intrinsics = good;
  no_intrinsics.clear_intrinsics();
  bad.emplace_back(no_intrinsics, "needs frame.intrinsics");
  pb::Frame distorted = good;
  distorted.mutable_intrinsics()->add_distortion(0.1);
  for (int i = 0; i < 3; ++i) distorted.mutable_intrinsics()->add_distortion(0);
  bad.emplace_back(distorted, "without distortion");
  pb::Frame short_data = good;
  short_data.mutable_depth()->mutable_raw()->mutable_data()->resize(100);
  bad.emplace_back(short_data, "frame.depth.raw.data has 100 bytes");
  pb::Frame stereo_features = FeaturesFrame(CorridorJpeg(1));
  *stereo_features.mutable_intrinsics() = good.intrinsics();
  ASSERT_TRUE(client::AttachStereoRight(rendered.right, kBaseline, &stereo_features).ok());
  bad.emplace_back(stereo_features, "needs the left image");
  for (const auto& [frame, words] : bad) {
    pb::AddFrameResponse added;
    const grpc::Status status = AddFrame("strict", frame, &added);
    EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << words;
    EXPECT_NE(status.error_message().find(words), std::string::npos) << status.error_message();
    pb::QueryPlaceRequest query;
    query.set_map("strict");
    query.set_add_frame(true);
    *query.mutable_frame() = frame;
    pb::QueryPlaceResponse response;
    EXPECT_EQ(places_->QueryPlace(Context().get(), query, &response).error_code(),
              grpc::StatusCode::INVALID_ARGUMENT)
        << words;
  }
  pb::MapInfo info;
  ASSERT_TRUE(GetMap("strict", &info).ok());
  EXPECT_EQ(info.frames(), 0u);

  // Client features with depth work: their keypoints index the depth image.
  const client::OrbFeatures orb = client::ExtractOrbFeatures(rendered.image).value();
  pb::Frame features =
      client::FrameFromFeatures(orb.keypoints, orb.descriptors, rendered.image.size()).value();
  *features.mutable_intrinsics() = good.intrinsics();
  ASSERT_TRUE(client::AttachDepth(rendered.depth_mm, 1000, &features).ok());
  pb::AddFrameResponse added;
  ASSERT_TRUE(AddFrame("strict", features, &added).ok());
  features.mutable_features()->set_image_width(320);  // but not a depth of another size
  EXPECT_EQ(AddFrame("strict", features, &added).error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  ASSERT_TRUE(AddFrame("strict", good, &added).ok());
  ASSERT_TRUE(GetMap("strict", &info).ok());
  EXPECT_EQ(info.frames(), 2u);
}

// A front + rear rig of the corridor images' size (512x384): the rear camera looks back, 0.4 m
// behind the front one.
pb::MapSettings FrontRearRig() {
  pb::MapSettings settings;
  settings.set_recent_frames(1);
  for (const bool rear : {false, true}) {
    pb::RigCameraSettings* camera = settings.add_rig();
    camera->set_name(rear ? "rear" : "front");
    camera->set_width(512);
    camera->set_height(384);
    camera->mutable_intrinsics()->set_fx(500);
    camera->mutable_intrinsics()->set_fy(500);
    camera->mutable_intrinsics()->set_cx(256);
    camera->mutable_intrinsics()->set_cy(192);
    const double s = rear ? -1 : 1;
    for (const double v : {s, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, s}) {
      camera->mutable_body_pose()->add_rotation(v);
    }
    for (const double v : {0.0, 0.0, 0.4 * s}) camera->mutable_body_pose()->add_translation(v);
  }
  return settings;
}

// A JPEG of blurred noise of the corridor images' size: a view no other image shares.
std::string UnseenJpeg(int seed) {
  cv::Mat noise(384 / 8, 512 / 8, CV_8U);
  cv::RNG rng(uint64_t(seed) + 1);
  rng.fill(noise, cv::RNG::UNIFORM, 0, 256);
  cv::Mat image;
  cv::resize(noise, image, {512, 384}, 0, 0, cv::INTER_NEAREST);
  cv::GaussianBlur(image, image, cv::Size(3, 3), 0);
  std::vector<uchar> jpeg;
  EXPECT_TRUE(cv::imencode(".jpg", image, jpeg));
  return std::string(jpeg.begin(), jpeg.end());
}

pb::Frame RigFrame(const std::string& front_jpeg, const std::string& rear_jpeg) {
  pb::Frame frame;
  for (const auto& [camera, jpeg] : {std::pair{"front", &front_jpeg}, {"rear", &rear_jpeg}}) {
    pb::Frame* view = frame.add_views();
    view->set_camera_id(camera);
    view->set_encoded_image(*jpeg);
  }
  return frame;
}

TEST_F(PlaceServiceTest, ARigMapFindsWithItsRearCameraWhatItsFrontCameraSawAcrossARestart) {
  pb::MapSettings skewed = FrontRearRig();
  skewed.mutable_rig(1)->mutable_body_pose()->set_rotation(1, 0.2);  // not a rotation
  const grpc::Status refused = CreateMap("skewed", skewed);
  EXPECT_EQ(refused.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(refused.error_message().find("'rear'"), std::string::npos) << refused.error_message();
  EXPECT_EQ(GetMap("skewed").error_code(), grpc::StatusCode::NOT_FOUND);
  pb::MapSettings short_pose = FrontRearRig();
  short_pose.mutable_rig(0)->mutable_body_pose()->mutable_translation()->RemoveLast();
  const grpc::Status pose_values = CreateMap("short-pose", short_pose);
  EXPECT_EQ(pose_values.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(pose_values.error_message().find("settings.rig[0] ('front').body_pose"),
            std::string::npos)
      << pose_values.error_message();
  pb::MapSettings no_size = FrontRearRig();
  no_size.mutable_rig(1)->set_width(0);
  const grpc::Status size = CreateMap("no-size", no_size);
  EXPECT_EQ(size.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(size.error_message().find("settings.rig[1] ('rear')"), std::string::npos)
      << size.error_message();
  pb::MapSettings odd_distortion = FrontRearRig();
  odd_distortion.mutable_rig(1)->mutable_intrinsics()->add_distortion(0.1);  // 1 value
  EXPECT_EQ(CreateMap("odd-distortion", odd_distortion).error_code(),
            grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(GetMap("short-pose").error_code(), grpc::StatusCode::NOT_FOUND);

  ASSERT_TRUE(CreateMap("rig", FrontRearRig()).ok());
  // The way out: the front camera sees the corridor, the rear one views nobody sees again.
  const int corridor[] = {1, 20, 41};
  for (int i = 0; i < 3; ++i) {
    pb::Frame frame = RigFrame(CorridorJpeg(corridor[i]), UnseenJpeg(i));
    frame.set_client_frame_id("out-" + std::to_string(i));
    pb::AddFrameResponse added;
    ASSERT_TRUE(AddFrame("rig", frame, &added).ok());
    EXPECT_EQ(added.frame_id(), uint64_t(2 * i));  // a rig frame takes one id per camera
    EXPECT_GT(added.num_features(), 300u);
  }
  RestartServer();
  pb::MapInfo info;
  ASSERT_TRUE(GetMap("rig", &info).ok());
  EXPECT_EQ(info.frames(), 3u);
  ASSERT_EQ(info.settings().rig_size(), 2);
  EXPECT_EQ(info.settings().rig(1).name(), "rear");
  EXPECT_EQ(info.settings().rig(1).body_pose().rotation(0), -1.0);
  EXPECT_EQ(info.settings().rig(1).body_pose().translation(2), -0.4);

  // The way back: the rear camera sees what the front one saw in rig frame 2.
  pb::QueryPlaceRequest query;
  query.set_map("rig");
  *query.mutable_frame() = RigFrame(UnseenJpeg(10), CorridorJpeg(20));
  query.mutable_options()->set_include_correspondences(true);
  pb::QueryPlaceResponse response;
  ASSERT_TRUE(places_->QueryPlace(Context().get(), query, &response).ok());
  const pb::LoopResult& result = response.result();
  ASSERT_EQ(result.status(), pb::LOOP_STATUS_LOOP_DETECTED);
  EXPECT_EQ(result.match_frame_id(), 2u);
  EXPECT_EQ(result.match_client_frame_id(), "out-1");
  ASSERT_EQ(result.rig().pairs_size(), 1);
  const pb::RigCameraMatch& pair = result.rig().pairs(0);
  EXPECT_EQ(pair.query_camera(), "rear");
  EXPECT_EQ(pair.match_camera(), "front");
  EXPECT_GE(pair.inliers(), 16u);
  EXPECT_EQ(result.inliers(), pair.inliers());
  EXPECT_EQ(uint32_t(pair.inlier_correspondences_size()), pair.inliers());

  // Bad rig frames are refused naming the camera, and add nothing.
  std::vector<std::pair<pb::Frame, std::string>> bad;  // frame, words its error must contain
  pb::Frame missing = RigFrame(CorridorJpeg(60), UnseenJpeg(20));
  missing.mutable_views()->RemoveLast();
  bad.emplace_back(missing, "no view for camera 'rear'");
  pb::Frame unknown = RigFrame(CorridorJpeg(60), UnseenJpeg(20));
  unknown.mutable_views(1)->set_camera_id("left");
  bad.emplace_back(unknown, "camera 'left'");
  pb::Frame twice = RigFrame(CorridorJpeg(60), UnseenJpeg(20));
  twice.mutable_views(1)->set_camera_id("front");
  bad.emplace_back(twice, "'front' has two views");
  cv::Mat small(240, 320, CV_8U, cv::Scalar(128));
  std::vector<uchar> small_jpeg;
  ASSERT_TRUE(cv::imencode(".jpg", small, small_jpeg));
  bad.emplace_back(RigFrame(CorridorJpeg(60), std::string(small_jpeg.begin(), small_jpeg.end())),
                   "rig camera 'rear': its image is 320x240");
  bad.emplace_back(RigFrame(CorridorJpeg(60), "not an image"), "rig camera 'rear'");
  pb::Frame own_intrinsics = RigFrame(CorridorJpeg(60), UnseenJpeg(20));
  own_intrinsics.mutable_views(0)->mutable_intrinsics()->set_fx(400);
  bad.emplace_back(own_intrinsics, "camera 'front'");
  bad.emplace_back(JpegFrame(CorridorJpeg(60)), "is a rig map");
  for (const auto& [frame, words] : bad) {
    pb::AddFrameResponse added;
    const grpc::Status status = AddFrame("rig", frame, &added);
    EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << words;
    EXPECT_NE(status.error_message().find(words), std::string::npos)
        << words << " not in: " << status.error_message();
  }
  query.mutable_options()->set_include_relative_pose(true);
  const grpc::Status pose = places_->QueryPlace(Context().get(), query, &response);
  EXPECT_EQ(pose.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(pose.error_message().find("rig map"), std::string::npos) << pose.error_message();
  ASSERT_TRUE(CreateMap("single").ok());
  pb::AddFrameResponse added;
  EXPECT_EQ(AddFrame("single", RigFrame(CorridorJpeg(1), UnseenJpeg(1)), &added).error_code(),
            grpc::StatusCode::INVALID_ARGUMENT);
  query.mutable_options()->set_include_relative_pose(false);
  query.add_search_maps("single");
  const grpc::Status search = places_->QueryPlace(Context().get(), query, &response);
  EXPECT_EQ(search.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << search.error_message();
  ASSERT_TRUE(GetMap("rig", &info).ok());
  EXPECT_EQ(info.frames(), 3u);
}

TEST_F(PlaceServiceTest, AStreamCreatesARigMapAndRemovingARigFrameRemovesEveryCamerasImage) {
  pb::StreamConfig config;
  config.set_map("rig-stream");
  config.set_create_if_missing(true);
  *config.mutable_settings() = FrontRearRig();
  std::vector<pb::Frame> frames;
  for (const int n : {1, 20, 41}) frames.push_back(RigFrame(CorridorJpeg(n), UnseenJpeg(n)));
  frames.push_back(RigFrame(UnseenJpeg(7), CorridorJpeg(1)));
  frames.push_back(RigFrame(UnseenJpeg(8), UnseenJpeg(8)));
  frames.back().mutable_views()->RemoveLast();  // an error of its own: the stream goes on
  frames.push_back(RigFrame(UnseenJpeg(9), CorridorJpeg(41)));
  grpc::Status status;
  const auto answers = Stream(*places_, config, frames, &status);
  ASSERT_TRUE(status.ok()) << status.error_message();
  ASSERT_EQ(answers.size(), 6u);
  ASSERT_TRUE(answers[3].has_result()) << answers[3].error().message();
  EXPECT_EQ(answers[3].result().status(), pb::LOOP_STATUS_LOOP_DETECTED);
  EXPECT_EQ(answers[3].result().match_frame_id(), 0u);
  EXPECT_EQ(answers[3].result().rig().pairs(0).query_camera(), "rear");
  ASSERT_TRUE(answers[4].has_error());
  EXPECT_NE(answers[4].error().message().find("'rear'"), std::string::npos);
  ASSERT_TRUE(answers[5].has_result());
  EXPECT_EQ(answers[5].result().frame_id(), 8u);  // the refused frame took no id

  pb::RemoveFrameRequest remove;
  remove.set_map("rig-stream");
  remove.set_frame_id(4);
  pb::RemoveFrameResponse removed;
  ASSERT_TRUE(places_->RemoveFrame(Context().get(), remove, &removed).ok());
  remove.set_frame_id(5);  // the rear image of rig frame 4: not a rig frame
  EXPECT_EQ(places_->RemoveFrame(Context().get(), remove, &removed).error_code(),
            grpc::StatusCode::NOT_FOUND);
  pb::MapInfo info;
  ASSERT_TRUE(GetMap("rig-stream", &info).ok());
  EXPECT_EQ(info.frames(), 4u);
  pb::QueryPlaceRequest query;
  query.set_map("rig-stream");
  *query.mutable_frame() = RigFrame(UnseenJpeg(11), CorridorJpeg(41));
  pb::QueryPlaceResponse response;
  ASSERT_TRUE(places_->QueryPlace(Context().get(), query, &response).ok());
  EXPECT_NE(response.result().match_frame_id(), 4u) << "a removed rig frame is no candidate";

  config.set_map("rig-stream");
  config.mutable_options()->set_top_k(3);
  Stream(*places_, config, {}, &status);
  EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << status.error_message();
}

TEST_F(PlaceServiceTest, AShardServesOnlyTheMapsThePlacementTableGivesIt) {
  const std::string table = data_dir_.Sub("placement.map");
  std::ofstream(table) << "mine   shard_a;\ntheirs shard_b;\n";
  StopServer();
  config().shard = {"shard_a", table};
  StartServer();
  EXPECT_TRUE(CreateMap("mine").ok());
  const grpc::Status theirs = CreateMap("theirs");
  EXPECT_EQ(theirs.error_code(), grpc::StatusCode::FAILED_PRECONDITION);
  EXPECT_NE(theirs.error_message().find("belongs to shard 'shard_b'"), std::string::npos)
      << theirs.error_message();
  const grpc::Status unlisted = CreateMap("unlisted");
  EXPECT_EQ(unlisted.error_code(), grpc::StatusCode::FAILED_PRECONDITION);
  EXPECT_NE(unlisted.error_message().find("not in the placement table"), std::string::npos);
  pb::AddFrameResponse added;
  EXPECT_EQ(AddFrame("theirs", JpegFrame(CorridorJpeg(1)), &added).error_code(),
            grpc::StatusCode::FAILED_PRECONDITION);
  pb::StreamConfig config;
  config.set_map("theirs");
  config.set_create_if_missing(true);
  grpc::Status streamed;
  Stream(*places_, config, {JpegFrame(CorridorJpeg(1))}, &streamed);
  EXPECT_EQ(streamed.error_code(), grpc::StatusCode::FAILED_PRECONDITION);

  // The map moves to this shard: after a reload it is served; a broken table keeps the old one.
  std::ofstream(table) << "mine   shard_a;\ntheirs shard_a;\n";
  ASSERT_TRUE(server_->ReloadPlacement().ok());
  EXPECT_TRUE(CreateMap("theirs").ok());
  std::ofstream(table) << "mine shard_a\n";  // no semicolon
  EXPECT_EQ(server_->ReloadPlacement().code(), StatusCode::kInvalidArgument);
  EXPECT_TRUE(GetMap("theirs").ok());
}

// Groups are placed whole (`group:NAME shard;`): their maps are created on that shard only, and a
// search of a map or group placed on another shard is refused, never silently left out.
TEST_F(PlaceServiceTest, AGroupLivesOnItsShardAndASearchNeverLeavesItSilently) {
  const std::string table = data_dir_.Sub("placement.map");
  std::ofstream(table) << "mine shard_a;\nrobot-2 shard_a;\ntheirs shard_b;\n"
                       << "group:fleet shard_a;\ngroup:far shard_b;\n";
  StopServer();
  config().shard = {"shard_a", table};
  StartServer();
  const auto refused = [](const grpc::Status& status, const std::string& says) {
    return status.error_code() == grpc::StatusCode::FAILED_PRECONDITION &&
           status.error_message().find(says) != std::string::npos;
  };
  pb::MapSettings fleet, far, unplaced;
  fleet.set_group("fleet");
  far.set_group("far");
  unplaced.set_group("unplaced");
  ASSERT_TRUE(CreateMap("mine", fleet).ok());
  EXPECT_TRUE(refused(CreateMap("robot-2", far), "group 'far' belongs to shard 'shard_b'"));
  EXPECT_TRUE(refused(CreateMap("robot-2", unplaced), "add `group:unplaced <shard>;`"));
  pb::StreamConfig config;
  config.set_map("robot-2");
  config.set_create_if_missing(true);
  *config.mutable_settings() = far;
  grpc::Status streamed;
  Stream(*places_, config, {JpegFrame(CorridorJpeg(1))}, &streamed);
  EXPECT_TRUE(refused(streamed, "group 'far'")) << streamed.error_message();
  ASSERT_TRUE(CreateMap("robot-2", fleet).ok());
  pb::AddFrameResponse added;
  ASSERT_TRUE(AddFrame("robot-2", JpegFrame(CorridorJpeg(1)), &added).ok());

  pb::QueryPlaceRequest query;
  query.set_map("mine");
  query.set_add_frame(true);
  *query.mutable_frame() = JpegFrame(CorridorJpeg(41));
  pb::QueryPlaceResponse answer;
  query.add_search_maps("theirs");
  EXPECT_TRUE(refused(places_->QueryPlace(Context().get(), query, &answer),
                      "map 'theirs' belongs to shard 'shard_b'"));
  query.clear_search_maps();
  query.set_search_group("far");
  EXPECT_TRUE(refused(places_->QueryPlace(Context().get(), query, &answer),
                      "group 'far' belongs to shard 'shard_b'"));
  pb::MapInfo info;
  ASSERT_TRUE(GetMap("mine", &info).ok());
  EXPECT_EQ(info.frames(), 0u) << "the refused queries added nothing";
  query.set_search_group("fleet");
  ASSERT_TRUE(places_->QueryPlace(Context().get(), query, &answer).ok());
  ASSERT_EQ(answer.inter_map_size(), 1);
  EXPECT_EQ(answer.inter_map(0).map(), "robot-2");

  pb::RelocalizeRequest relocalize;
  *relocalize.add_frames() = JpegFrame(CorridorJpeg(41));
  relocalize.set_group("far");
  pb::RelocalizeResponse places;
  EXPECT_TRUE(refused(places_->Relocalize(Context().get(), relocalize, &places), "group 'far'"));
  relocalize.set_group("fleet");
  ASSERT_TRUE(places_->Relocalize(Context().get(), relocalize, &places).ok());
  EXPECT_GE(places.places_size(), 1);

  // A table that moves the group away from the maps this shard holds of it is refused.
  std::ofstream(table) << "mine shard_a;\nrobot-2 shard_a;\ngroup:fleet shard_b;\n";
  const Status moved = server_->ReloadPlacement();
  EXPECT_EQ(moved.code(), StatusCode::kFailedPrecondition);
  EXPECT_NE(moved.message().find("its map 'mine' is on this shard"), std::string::npos)
      << moved.ToString();
  EXPECT_TRUE(places_->Relocalize(Context().get(), relocalize, &places).ok()) << "old table kept";
  StopServer();  // nor does the shard start with it
  EXPECT_EQ(RecognitionServer::Start(ServerFixture::config()).status().code(),
            StatusCode::kFailedPrecondition);
}

TEST_F(PlaceServiceTest, AShardWithABrokenPlacementTableDoesNotStart) {
  StopServer();
  const std::string table = data_dir_.Sub("placement.map");
  std::ofstream(table) << "default shard_a;\n";
  config().shard = {"shard_a", table};
  EXPECT_EQ(RecognitionServer::Start(config()).status().code(), StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace recog::server::testing
