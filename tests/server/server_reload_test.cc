// Loopback tests of recogd's operations: a reload (RecognitionServer::Reload, recogd's SIGHUP) of
// rotated certificates and tokens, malformed files on reload, the standard gRPC server metrics, and
// the systemd notifications of the real binary (NOTIFY_SOCKET) around SIGHUP and SIGTERM.
#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <sys/wait.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <thread>

#include <gmock/gmock.h>

#include "server/app/server_tls.h"
#include "tests/server/server_fixture.h"
#include "tests/testing/metrics_scrape.h"
#include "tests/testing/unix_socket.h"
#include "tests/testing/wait.h"

extern char** environ;

namespace recog::server::testing {
namespace {

using recog::testing::FetchMetrics;

namespace fs = std::filesystem;
using ::testing::HasSubstr;
using ::testing::Not;

constexpr char kOldToken[] = "old-robot-token-0123456789";
constexpr char kNewToken[] = "new-robot-token-0123456789";

std::string TokenFile(const char* token) {
  return std::string("tokens:\n  - name: robot-7\n    token: ") + token + "\n    rights: [write]\n";
}

std::string TlsData(const std::string& name) {
  return ReadFileBytes(recog::testing::ProjectTestData("tls/" + name));
}

void WriteText(const fs::path& path, const std::string& text) {
  std::ofstream(path, std::ios::binary | std::ios::trunc) << text;
}

class ServerReloadTest : public ServerFixture {
 protected:
  ServerReloadTest() : files_("reload_files") {}

  // A fresh channel (its own connection) to the fixture's server over TLS, trusting only
  // `ca_pem`, presenting the test client certificate.
  std::shared_ptr<grpc::Channel> TlsChannel(const std::string& ca_pem) const {
    grpc::SslCredentialsOptions options{ca_pem, TlsData("client.key"), TlsData("client.crt")};
    grpc::ChannelArguments args;
    args.SetInt(GRPC_ARG_USE_LOCAL_SUBCHANNEL_POOL, 1);
    return grpc::CreateCustomChannel("localhost:" + std::to_string(server_->port()),
                                     grpc::SslCredentials(options), args);
  }

  static grpc::Status ListMaps(const std::shared_ptr<grpc::Channel>& channel,
                               const std::string& token = {}) {
    pb::ListMapsResponse listed;
    return pb::PlaceRecognition::NewStub(channel)->ListMaps(Context(token).get(), {}, &listed);
  }

  // Whether a new connection trusting `ca_pem` succeeds before the deadline (the certificate
  // provider re-reads the files every second).
  bool NewConnectionsSucceedWith(const std::string& ca_pem) const {
    return recog::testing::WaitUntil([&] { return ListMaps(TlsChannel(ca_pem)).ok(); },
                                     recog::testing::kEventTimeout, std::chrono::milliseconds(100));
  }

  recog::testing::TempDir files_;  // the server's certificate, key and token files
};

TEST_F(ServerReloadTest, ARotatedCertificateServesNewConnectionsAfterAReload) {
  StopServer();
  const fs::path cert = files_.path() / "server.crt", key = files_.path() / "server.key";
  WriteText(cert, TlsData("server.crt"));
  WriteText(key, TlsData("server.key"));
  config().tls = {cert.string(), key.string(), recog::testing::ProjectTestData("tls/ca.crt")};
  StartServer();
  const std::string old_ca = TlsData("ca.crt"), new_ca = TlsData("rotated/ca.crt");
  const std::shared_ptr<grpc::Channel> before = TlsChannel(old_ca);
  ASSERT_TRUE(ListMaps(before).ok());
  EXPECT_FALSE(ListMaps(TlsChannel(new_ca)).ok());

  // A malformed certificate, then a key of another certificate: refused, the old one serves.
  WriteText(cert, "-----BEGIN CERTIFICATE-----\nnot base64\n-----END CERTIFICATE-----\n");
  Status reloaded = server_->Reload();
  EXPECT_EQ(reloaded.code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(reloaded.message(), HasSubstr("tls.cert"));
  WriteText(cert, TlsData("rotated/server.crt"));
  reloaded = server_->Reload();
  EXPECT_EQ(reloaded.code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(reloaded.message(), HasSubstr("is not the key of"));
  // The behaviour under test takes time: after two refresh periods the certificate provider has
  // re-read the files, and must still serve the pair it had.
  std::this_thread::sleep_for(std::chrono::seconds(2 * ServerTls::kRefreshSeconds));
  EXPECT_TRUE(ListMaps(TlsChannel(old_ca)).ok());

  // The rotated pair: new connections trust only the new CA; mutual TLS still holds.
  WriteText(key, TlsData("rotated/server.key"));
  ASSERT_TRUE(server_->Reload().ok());
  EXPECT_TRUE(NewConnectionsSucceedWith(new_ca));
  EXPECT_FALSE(ListMaps(TlsChannel(old_ca)).ok());
  grpc::ChannelArguments args;
  args.SetInt(GRPC_ARG_USE_LOCAL_SUBCHANNEL_POOL, 1);
  auto without_client_cert = grpc::CreateCustomChannel(
      "localhost:" + std::to_string(server_->port()),
      grpc::SslCredentials(grpc::SslCredentialsOptions{new_ca, "", ""}), args);
  EXPECT_FALSE(ListMaps(without_client_cert).ok());
  EXPECT_TRUE(ListMaps(before).ok()) << "a connection made before the reload keeps working";
}

TEST_F(ServerReloadTest, ReloadedTokensAdmitTheNewTokenAndRefuseTheRemovedOne) {
  StopServer();
  const fs::path tokens = files_.path() / "tokens.yaml";
  WriteText(tokens, TokenFile(kOldToken));
  config().token_file = tokens.string();
  StartServer();
  ASSERT_TRUE(ListMaps(channel_, kOldToken).ok());
  EXPECT_EQ(ListMaps(channel_, kNewToken).error_code(), grpc::StatusCode::UNAUTHENTICATED);

  WriteText(tokens, TokenFile(kNewToken));
  ASSERT_TRUE(server_->Reload().ok());
  EXPECT_TRUE(ListMaps(channel_, kNewToken).ok());
  EXPECT_EQ(ListMaps(channel_, kOldToken).error_code(), grpc::StatusCode::UNAUTHENTICATED);

  WriteText(tokens, "tokens:\n  - name: robot-7\n    token: [not, a, string]\n");
  EXPECT_EQ(server_->Reload().code(), StatusCode::kInvalidArgument);
  EXPECT_TRUE(ListMaps(channel_, kNewToken).ok()) << "a bad file keeps the tokens in use";
}

TEST_F(ServerReloadTest, TheStandardGrpcMetricsCountStartsMessagesAndCodes) {
  StopServer();
  config().metrics_listen = "127.0.0.1:0";
  StartServer();
  ASSERT_TRUE(CreateMap("m").ok());
  EXPECT_EQ(CreateMap("m").error_code(), grpc::StatusCode::ALREADY_EXISTS);
  grpc::ClientContext context;
  auto stream = places_->StreamFrames(&context);
  pb::StreamFramesRequest request;
  request.mutable_config()->set_map("m");
  ASSERT_TRUE(stream->Write(request));
  ASSERT_TRUE(stream->WritesDone());
  ASSERT_TRUE(stream->Finish().ok());

  const std::string metrics = FetchMetrics(server_->metrics_port());
  const std::string create =
      "grpc_method=\"CreateMap\",grpc_service=\"recognition.v1.PlaceRecognition\","
      "grpc_type=\"unary\"}";
  const std::string stream_frames =
      "grpc_method=\"StreamFrames\",grpc_service=\"recognition.v1.PlaceRecognition\","
      "grpc_type=\"bidi_stream\"}";
  for (const std::string& line : std::vector<std::string>{
           "grpc_server_started_total{" + create + " 2",
           "grpc_server_handled_total{grpc_code=\"OK\"," + create + " 1",
           "grpc_server_handled_total{grpc_code=\"ALREADY_EXISTS\"," + create + " 1",
           "grpc_server_msg_received_total{" + create + " 2",
           "grpc_server_msg_sent_total{" + create + " 1",  // no message with an error
           "grpc_server_handling_seconds_count{" + create + " 2",
           "grpc_server_started_total{" + stream_frames + " 1",
           "grpc_server_handled_total{grpc_code=\"OK\"," + stream_frames + " 1",
           "grpc_server_msg_received_total{" + stream_frames + " 1",
           "grpc_server_msg_sent_total{" + stream_frames + " 0",
           // Every method has its series from the start; the project's own metrics stay.
           "grpc_server_started_total{grpc_method=\"DeleteModel\","
           "grpc_service=\"recognition.v1.ObjectRepository\",grpc_type=\"unary\"} 0",
           "recog_rpc_duration_seconds_count{code=\"OK\",method=\"/recognition.v1."
           "PlaceRecognition/CreateMap\"} 1",
       }) {
    EXPECT_THAT(metrics, HasSubstr("\n" + line + "\n"));
  }
  EXPECT_THAT(metrics, Not(HasSubstr("grpc_service=\"grpc.health.v1.Health\"")));
}

// The real binary under a stand-in for systemd: a unix datagram socket named by NOTIFY_SOCKET.
class NotifySocket {
 public:
  explicit NotifySocket(const fs::path& path) : path_(path) {
    fd_ = socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0);
    sockaddr_un address{};
    address.sun_family = AF_UNIX;
    std::snprintf(address.sun_path, sizeof(address.sun_path), "%s", path.c_str());
    bound_ = bind(fd_, reinterpret_cast<sockaddr*>(&address), sizeof(address)) == 0;
  }
  ~NotifySocket() {
    close(fd_);
    fs::remove(path_);
  }
  bool bound() const { return bound_; }

  // The next datagram, "" when none comes within `seconds`.
  std::string Next(int seconds = 60) {
    pollfd ready{fd_, POLLIN, 0};
    if (poll(&ready, 1, seconds * 1000) != 1) return {};
    char buffer[512];
    const ssize_t n = recv(fd_, buffer, sizeof(buffer), 0);
    return n > 0 ? std::string(buffer, size_t(n)) : std::string();
  }

 private:
  fs::path path_;
  int fd_ = -1;
  bool bound_ = false;
};

TEST_F(ServerReloadTest, RecogdNotifiesSystemdAndReloadsTokensOnSighup) {
  StopServer();  // the store is the child's now
  const fs::path tokens = files_.path() / "tokens.yaml";
  WriteText(tokens, TokenFile(kOldToken));
  // sun_path holds 108 bytes: the socket goes in a short directory.
  const fs::path socket_path =
      fs::temp_directory_path() / ("recog_notify_" + std::to_string(getpid()));
  NotifySocket notify(socket_path);
  ASSERT_TRUE(notify.bound()) << socket_path;

  const std::string listen = recog::testing::UnixSocketAddress(files_.path());
  std::vector<std::string> args = {RECOGD_PATH,
                                   "--listen",
                                   listen,
                                   "--data-dir",
                                   data_dir_.path().string(),
                                   "--metrics-listen",
                                   "",
                                   "--token-file",
                                   tokens.string(),
                                   "--log-level",
                                   "warn"};
  std::vector<char*> argv;
  for (std::string& a : args) argv.push_back(a.data());
  argv.push_back(nullptr);
  std::vector<std::string> env = {"NOTIFY_SOCKET=" + socket_path.string()};
  for (char** e = environ; *e != nullptr; ++e) env.emplace_back(*e);
  std::vector<char*> envp;
  for (std::string& e : env) envp.push_back(e.data());
  envp.push_back(nullptr);
  pid_t child = 0;
  ASSERT_EQ(posix_spawn(&child, RECOGD_PATH, nullptr, nullptr, argv.data(), envp.data()), 0);

  EXPECT_THAT(notify.Next(), HasSubstr("READY=1"));
  auto channel = grpc::CreateChannel(listen, grpc::InsecureChannelCredentials());
  EXPECT_TRUE(ListMaps(channel, kOldToken).ok()) << "READY=1 means serving";

  WriteText(tokens, TokenFile(kNewToken));
  kill(child, SIGHUP);
  EXPECT_THAT(notify.Next(), HasSubstr("RELOADING=1"));
  EXPECT_THAT(notify.Next(), HasSubstr("READY=1"));
  EXPECT_TRUE(ListMaps(channel, kNewToken).ok());
  EXPECT_EQ(ListMaps(channel, kOldToken).error_code(), grpc::StatusCode::UNAUTHENTICATED);

  kill(child, SIGTERM);
  EXPECT_THAT(notify.Next(), HasSubstr("STOPPING=1"));
  int status = 0;
  ASSERT_EQ(waitpid(child, &status, 0), child);
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << status;
}

}  // namespace
}  // namespace recog::server::testing
