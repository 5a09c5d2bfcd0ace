// Tests of ClientOptions::Validate and of what RecognitionClient::Connect checks before it
// returns: option values, token files and TLS files.
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <functional>

#include <gtest/gtest.h>

#include "client/cpp/recognition_client.h"
#include "tests/testing/data_paths.h"

namespace recog::client {
namespace {

TEST(ClientOptionsTest, TheDefaultsReachALocalServerAndAreValid) {
  const ClientOptions options;
  EXPECT_TRUE(options.Validate().ok());
  EXPECT_EQ(options.target, "127.0.0.1:50051");
  EXPECT_FALSE(options.tls.enabled);
  EXPECT_EQ(options.deadline, std::chrono::seconds(10));
  EXPECT_TRUE(options.retries);
  EXPECT_EQ(options.max_message_bytes, 32u << 20);
}

TEST(ClientOptionsTest, EachBadFieldIsRefusedByName) {
  const std::vector<std::pair<std::string, std::function<void(ClientOptions&)>>> cases = {
      {"target", [](ClientOptions& o) { o.target.clear(); }},
      {"token", [](ClientOptions& o) { o.token = "has space-0123456789"; }},
      {"token_file",
       [](ClientOptions& o) {
         o.token = "a-token-0123456789";
         o.token_file = "token.txt";
       }},
      {"tls.enabled", [](ClientOptions& o) { o.tls.ca_file = "ca.crt"; }},
      {"tls.key_file",
       [](ClientOptions& o) {
         o.tls.enabled = true;
         o.tls.cert_file = "client.crt";
       }},
      {"deadline", [](ClientOptions& o) { o.deadline = std::chrono::milliseconds(0); }},
      {"transfer_deadline", [](ClientOptions& o) { o.transfer_deadline = {}; }},
      {"max_message_bytes", [](ClientOptions& o) { o.max_message_bytes = 1000; }},
      {"max_frames_in_flight", [](ClientOptions& o) { o.max_frames_in_flight = 0; }},
      {"shard", [](ClientOptions& o) { o.shard = "shard-a"; }},
  };
  for (const auto& [field, spoil] : cases) {
    ClientOptions options;
    spoil(options);
    const grpc::Status status = options.Validate();
    EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << field;
    EXPECT_NE(status.error_message().find(field), std::string::npos)
        << field << ": " << status.error_message();
    EXPECT_EQ(RecognitionClient::Connect(options).status().error_code(),
              grpc::StatusCode::INVALID_ARGUMENT);
  }
}

class ConnectTest : public ::testing::Test {
 protected:
  ~ConnectTest() override { std::filesystem::remove(token_file_); }
  // Options whose token file holds `content`.
  ClientOptions WithTokenFile(const std::string& content) {
    std::ofstream(token_file_, std::ios::binary) << content;
    ClientOptions options;
    options.token_file = token_file_;
    return options;
  }
  const std::string token_file_ =
      (std::filesystem::temp_directory_path() / ("recog_client_token_" + std::to_string(getpid())))
          .string();
};

TEST_F(ConnectTest, ATokenFileNeedsOneTokenOfVisibleCharacters) {
  EXPECT_TRUE(RecognitionClient::Connect(WithTokenFile(" \ta-token-0123456789\r\n")).ok());
  EXPECT_EQ(RecognitionClient::Connect(WithTokenFile(" \n\n")).status().error_code(),
            grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(RecognitionClient::Connect(WithTokenFile("two tokens")).status().error_code(),
            grpc::StatusCode::INVALID_ARGUMENT);
  ClientOptions missing;
  missing.token_file = token_file_ + ".missing";
  EXPECT_EQ(RecognitionClient::Connect(missing).status().error_code(), grpc::StatusCode::NOT_FOUND);
}

TEST_F(ConnectTest, TlsFilesAreReadByConnect) {
  ClientOptions options;
  options.tls.enabled = true;
  EXPECT_TRUE(RecognitionClient::Connect(options).ok());  // the system's trust store
  options.tls.ca_file = recog::testing::ProjectTestData("tls/ca.crt");
  options.tls.cert_file = recog::testing::ProjectTestData("tls/client.crt");
  options.tls.key_file = recog::testing::ProjectTestData("tls/client.key");
  EXPECT_TRUE(RecognitionClient::Connect(options).ok());
  options.tls.key_file += ".missing";
  EXPECT_EQ(RecognitionClient::Connect(options).status().error_code(), grpc::StatusCode::NOT_FOUND);
}

}  // namespace
}  // namespace recog::client
