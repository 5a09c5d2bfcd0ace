// A lost answer, for real: a TCP proxy (tests/testing/tcp_proxy.h) between the client and an
// in-process recogd forwards an AddFrame and cuts the connection when the server's answer starts,
// after the server applied the frame. gRPC retries the call (UNAVAILABLE), with the same
// request_id, and the server answers the retry from its request log: the frame is in the map once.
// With the log turned off, the same scenario adds the frame twice, which shows that the cut came
// after the frame was applied.
#include <gtest/gtest.h>

#include "client/cpp/client_test_fixture.h"
#include "tests/testing/tcp_proxy.h"

namespace recog::client::testing {
namespace {

class IdempotencyTest : public ClientFixture {
 protected:
  std::unique_ptr<RecognitionClient> ConnectThrough(const recog::testing::TcpProxy& proxy) {
    ClientOptions options = Options();
    options.target = "127.0.0.1:" + std::to_string(proxy.port());
    return Connect(options);
  }
};

TEST_F(IdempotencyTest, AFrameWhoseAnswerWasLostIsRetriedAndAddedOnce) {
  recog::testing::TcpProxy proxy(server_->port());
  auto client = ConnectThrough(proxy);
  ASSERT_NE(client, nullptr);
  ASSERT_TRUE(client->CreateMap("lost").ok());
  const pb::Frame frame = JpegFrame(CorridorJpeg(1));

  proxy.CutAtNextAnswer();
  Result<pb::AddFrameResponse> first = client->AddFrame("lost", frame);  // a fresh request id
  ASSERT_TRUE(first.ok()) << first.status().error_message();
  EXPECT_EQ(proxy.answers_cut(), 1);
  EXPECT_EQ(client->GetMap("lost")->frames(), 1u);

  // The same id again, as a retry of the whole call would send it: the first answer, no frame.
  proxy.CutAtNextAnswer();
  Result<pb::AddFrameResponse> mine = client->AddFrame("lost", frame, "robot-7/keyframe-42");
  ASSERT_TRUE(mine.ok()) << mine.status().error_message();
  EXPECT_EQ(proxy.answers_cut(), 2);
  Result<pb::AddFrameResponse> again = client->AddFrame("lost", frame, "robot-7/keyframe-42");
  ASSERT_TRUE(again.ok()) << again.status().error_message();
  EXPECT_EQ(again->frame_id(), mine->frame_id());
  EXPECT_NE(mine->frame_id(), first->frame_id());
  EXPECT_EQ(client->GetMap("lost")->frames(), 2u);

  // A different id is a different call.
  Result<pb::AddFrameResponse> other = client->AddFrame("lost", frame, "robot-7/keyframe-43");
  ASSERT_TRUE(other.ok()) << other.status().error_message();
  EXPECT_NE(other->frame_id(), mine->frame_id());
  EXPECT_EQ(client->GetMap("lost")->frames(), 3u);
}

TEST_F(IdempotencyTest, WithoutTheRequestLogTheRetryOfALostAnswerAddsTheFrameTwice) {
  StopServer();
  config().request_log_entries = 0;
  StartServer();
  recog::testing::TcpProxy proxy(server_->port());
  auto client = ConnectThrough(proxy);
  ASSERT_NE(client, nullptr);
  ASSERT_TRUE(client->CreateMap("twice").ok());
  proxy.CutAtNextAnswer();
  ASSERT_TRUE(client->AddFrame("twice", JpegFrame(CorridorJpeg(1))).ok());
  EXPECT_EQ(proxy.answers_cut(), 1);
  EXPECT_EQ(client->GetMap("twice")->frames(), 2u);
}

}  // namespace
}  // namespace recog::client::testing
