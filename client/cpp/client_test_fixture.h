// ClientFixture: the server tests' ServerFixture (tests/server/server_fixture.h) — a recogd in
// this process on a loopback port and a fresh data directory — plus RecognitionClients connected
// to it, and the corridor frames of tests/data/ in the forms the client sends.
#pragma once

#include <memory>
#include <string>

#include <gtest/gtest.h>

#include "client/cpp/recognition_client.h"
#include "tests/server/server_fixture.h"

namespace recog::client::testing {

using recog::server::testing::CorridorJpeg;
using recog::server::testing::JpegFrame;
using recog::server::testing::PosterView;
using recog::server::testing::ReadFileBytes;

class ClientFixture : public recog::server::testing::ServerFixture {
 protected:
  // Options that reach the fixture's server, with a 30 s deadline.
  ClientOptions Options() const {
    ClientOptions options;
    options.target = "127.0.0.1:" + std::to_string(server_->port());
    options.deadline = std::chrono::seconds(30);
    return options;
  }

  // A client with `options` (the fixture's by default); null, with a test failure, when Connect
  // refuses them.
  static std::unique_ptr<RecognitionClient> Connect(const ClientOptions& options) {
    Result<std::unique_ptr<RecognitionClient>> client = RecognitionClient::Connect(options);
    EXPECT_TRUE(client.ok()) << client.status().error_message();
    return client.ok() ? std::move(client).value() : nullptr;
  }
  std::unique_ptr<RecognitionClient> Connect() { return Connect(Options()); }
};

}  // namespace recog::client::testing
