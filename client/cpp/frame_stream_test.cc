// Loopback tests of FrameStream against an in-process recogd: several frames in flight answered
// in order, through futures and callbacks, bad frames, a failing stream, the in-flight window,
// closing and cancelling.
#include <mutex>

#include "client/cpp/client_test_fixture.h"
#include "client/cpp/frame_stream.h"

namespace recog::client::testing {
namespace {

class FrameStreamTest : public ClientFixture {
 protected:
  // A stream that creates `map`, with settings under which four corridor frames can close a loop.
  static pb::StreamConfig TourConfig(const std::string& map) {
    pb::StreamConfig config;
    config.set_map(map);
    config.set_create_if_missing(true);
    config.mutable_settings()->set_temporal_matches(0);
    config.mutable_settings()->set_recent_frames(1);
    return config;
  }
};

TEST_F(FrameStreamTest, FiveFramesInFlightGetFiveAnswersInOrder) {
  auto client = Connect();
  ASSERT_NE(client, nullptr);
  Result<std::unique_ptr<FrameStream>> stream = FrameStream::Open(*client, TourConfig("tour"));
  ASSERT_TRUE(stream.ok());
  std::vector<std::future<FrameStream::Answer>> answers;
  for (int n : {1, 20, 41, 60, 1}) {
    pb::Frame frame = JpegFrame(CorridorJpeg(n));
    frame.set_client_frame_id("corridor-" + std::to_string(n));
    answers.push_back((*stream)->Send(frame));
  }
  EXPECT_GT((*stream)->in_flight(), 1u);  // nothing waited for an answer before sending on
  for (size_t i = 0; i < answers.size(); ++i) {
    FrameStream::Answer answer = answers[i].get();
    ASSERT_TRUE(answer.ok()) << answer.status().error_message();
    EXPECT_EQ(answer->sequence(), i);
    ASSERT_TRUE(answer->has_result()) << answer->error().message();
    EXPECT_EQ(answer->result().frame_id(), i);
  }
  const grpc::Status closed = (*stream)->Close();
  EXPECT_TRUE(closed.ok()) << closed.error_message();
  EXPECT_EQ(client->GetMap("tour")->frames(), 5u);
  EXPECT_EQ((*stream)->Send(JpegFrame(CorridorJpeg(1))).get().status().error_code(),
            grpc::StatusCode::FAILED_PRECONDITION);  // closed
}

TEST_F(FrameStreamTest, APreparedFrameSentTwiceIsAnsweredTwiceAndStaysIntact) {
  auto client = Connect();
  ASSERT_NE(client, nullptr);
  auto stream = FrameStream::Open(*client, TourConfig("prepared"));
  ASSERT_TRUE(stream.ok());
  const FrameStream::PreparedFrame frame = FrameStream::Prepare(JpegFrame(CorridorJpeg(1)));
  const std::string bytes = frame->frame().encoded_image();
  std::mutex mutex;
  std::vector<pb::StreamFramesResponse> answers;
  for (int i = 0; i < 2; ++i) {
    (*stream)->Send(frame, [&](FrameStream::Answer answer) {
      ASSERT_TRUE(answer.ok()) << answer.status().error_message();
      std::lock_guard lock(mutex);
      answers.push_back(std::move(answer).value());
    });
  }
  ASSERT_TRUE((*stream)->Close().ok());
  std::lock_guard lock(mutex);
  ASSERT_EQ(answers.size(), 2u);
  EXPECT_EQ(answers[0].result().frame_id(), 0u);
  EXPECT_EQ(answers[1].result().frame_id(), 1u);
  EXPECT_EQ(frame->frame().encoded_image(), bytes);  // shared, never moved from
  EXPECT_EQ(client->GetMap("prepared")->frames(), 2u);
}

TEST_F(FrameStreamTest, CallbacksGetEveryAnswerInOrderAndTheRevisitIsALoop) {
  auto client = Connect();
  ASSERT_NE(client, nullptr);
  auto stream = FrameStream::Open(*client, TourConfig("tour"));
  ASSERT_TRUE(stream.ok());
  std::mutex mutex;
  std::vector<pb::StreamFramesResponse> answers;
  for (int n : {1, 20, 41, 60, 1}) {
    (*stream)->Send(JpegFrame(CorridorJpeg(n)), [&](FrameStream::Answer answer) {
      ASSERT_TRUE(answer.ok()) << answer.status().error_message();
      std::lock_guard lock(mutex);
      answers.push_back(std::move(answer).value());
    });
  }
  ASSERT_TRUE((*stream)->Close().ok());  // every callback has run when Close returns
  std::lock_guard lock(mutex);
  ASSERT_EQ(answers.size(), 5u);
  for (size_t i = 0; i < answers.size(); ++i) EXPECT_EQ(answers[i].sequence(), i);
  EXPECT_EQ(answers[4].result().status(), pb::LOOP_STATUS_LOOP_DETECTED);
  EXPECT_EQ(answers[4].result().match_frame_id(), 0u);
}

TEST_F(FrameStreamTest, ABadFrameIsAnsweredWithItsErrorAndTheStreamGoesOn) {
  auto client = Connect();
  ASSERT_NE(client, nullptr);
  auto stream = FrameStream::Open(*client, TourConfig("tour"));
  ASSERT_TRUE(stream.ok());
  pb::Frame garbage;
  garbage.set_encoded_image("\x89PNG not really");
  auto bad = (*stream)->Send(garbage);
  auto good = (*stream)->Send(JpegFrame(CorridorJpeg(1)));
  FrameStream::Answer bad_answer = bad.get();
  ASSERT_TRUE(bad_answer.ok());
  EXPECT_EQ(bad_answer->error().code(), int(grpc::StatusCode::INVALID_ARGUMENT));
  FrameStream::Answer good_answer = good.get();
  ASSERT_TRUE(good_answer.ok());
  EXPECT_TRUE(good_answer->has_result());
  EXPECT_TRUE((*stream)->Close().ok());
}

TEST_F(FrameStreamTest, AFailingStreamFailsEveryWaitingFrameWithItsStatus) {
  auto client = Connect();
  ASSERT_NE(client, nullptr);
  pb::StreamConfig config;
  config.set_map("nowhere");  // not created, and create_if_missing is off
  auto stream = FrameStream::Open(*client, config);
  ASSERT_TRUE(stream.ok());
  std::vector<std::future<FrameStream::Answer>> answers;
  for (int n : {1, 20, 41}) answers.push_back((*stream)->Send(JpegFrame(CorridorJpeg(n))));
  for (auto& answer : answers) {
    EXPECT_EQ(answer.get().status().error_code(), grpc::StatusCode::NOT_FOUND);
  }
  EXPECT_EQ((*stream)->Close().error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_EQ((*stream)->Send(JpegFrame(CorridorJpeg(1))).get().status().error_code(),
            grpc::StatusCode::NOT_FOUND);
  EXPECT_EQ(FrameStream::Open(*client, pb::StreamConfig()).status().error_code(),
            grpc::StatusCode::INVALID_ARGUMENT);  // no map named
}

TEST_F(FrameStreamTest, AFrameBeyondTheInFlightWindowIsRefusedAtOnceAndNotSent) {
  ClientOptions options = Options();
  options.max_frames_in_flight = 2;
  auto client = Connect(options);
  ASSERT_NE(client, nullptr);
  auto stream = FrameStream::Open(*client, TourConfig("window"));
  ASSERT_TRUE(stream.ok());
  // A frame takes the server milliseconds; the three sends take microseconds.
  auto first = (*stream)->Send(JpegFrame(CorridorJpeg(1)));
  auto second = (*stream)->Send(JpegFrame(CorridorJpeg(20)));
  auto third = (*stream)->Send(JpegFrame(CorridorJpeg(41)));
  EXPECT_EQ(third.get().status().error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
  EXPECT_TRUE(first.get().ok());
  EXPECT_TRUE(second.get().ok());
  EXPECT_TRUE((*stream)->Send(JpegFrame(CorridorJpeg(60))).get().ok());  // room again
  EXPECT_TRUE((*stream)->Close().ok());
  EXPECT_EQ(client->GetMap("window")->frames(), 3u);
}

TEST_F(FrameStreamTest, CancellingEndsTheStreamAndDestroyingAnOpenStreamDoesNotHang) {
  auto client = Connect();
  ASSERT_NE(client, nullptr);
  auto stream = FrameStream::Open(*client, TourConfig("cancelled"));
  ASSERT_TRUE(stream.ok());
  ASSERT_TRUE((*stream)->Send(JpegFrame(CorridorJpeg(1))).get().ok());
  auto waiting = (*stream)->Send(JpegFrame(CorridorJpeg(20)));
  (*stream)->Cancel();
  const FrameStream::Answer answer = waiting.get();  // answered, or cancelled first
  EXPECT_TRUE(answer.ok() || answer.status().error_code() == grpc::StatusCode::CANCELLED);
  EXPECT_EQ((*stream)->Close().error_code(), grpc::StatusCode::CANCELLED);

  auto abandoned = FrameStream::Open(*client, TourConfig("abandoned"));
  ASSERT_TRUE(abandoned.ok());
  auto pending = (*abandoned)->Send(JpegFrame(CorridorJpeg(1)));
  abandoned->reset();  // cancels and waits; the future is completed either way
  EXPECT_EQ(pending.wait_for(std::chrono::seconds(0)), std::future_status::ready);
}

TEST_F(FrameStreamTest, AStreamOutlivesTheClientThatOpenedIt) {
  auto client = Connect();
  ASSERT_NE(client, nullptr);
  auto stream = FrameStream::Open(*client, TourConfig("orphan"));
  ASSERT_TRUE(stream.ok());
  client.reset();
  EXPECT_TRUE((*stream)->Send(JpegFrame(CorridorJpeg(1))).get().ok());
  EXPECT_TRUE((*stream)->Close().ok());
}

}  // namespace
}  // namespace recog::client::testing
