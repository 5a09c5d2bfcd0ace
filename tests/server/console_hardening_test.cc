// The console and the gRPC port against requests an attacker would send (issue 42's findings, each
// with the request that found it): invalid UTF-8 in a path, control bytes in the Authorization
// header, chunked and compressed bodies, decompression bombs, map-scoped tokens on the admin
// calls, invalid UTF-8 in an uploaded model, DNS rebinding, slow clients, forged log lines,
// framing and sniffing. After each, recogd must still answer both ports.
#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <xxhash.h>

#include <httplib.h>
#include <spdlog/sinks/ostream_sink.h>
#include <nlohmann/json.hpp>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <thread>

#include "recognition/v1/admin.grpc.pb.h"
#include "server/console/rpc_gateway.h"
#include "tests/server/server_fixture.h"
#include "tests/testing/model_files.h"

namespace recog::server::testing {
namespace {

using nlohmann::json;
using Clock = std::chrono::steady_clock;

constexpr char kAdmin[] = "admin-token-0123456789", kRobotA[] = "robot-a-token-0123456789";

// A TCP connection to 127.0.0.1:`port` from `source` (any 127.x.y.z address), or -1.
int Connect(int port, const char* source = "127.0.0.1") {
  const int fd = socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in local{};
  local.sin_family = AF_INET;
  inet_pton(AF_INET, source, &local.sin_addr);
  sockaddr_in remote{};
  remote.sin_family = AF_INET;
  remote.sin_port = htons(uint16_t(port));
  inet_pton(AF_INET, "127.0.0.1", &remote.sin_addr);
  if (bind(fd, reinterpret_cast<sockaddr*>(&local), sizeof(local)) != 0 ||
      connect(fd, reinterpret_cast<sockaddr*>(&remote), sizeof(remote)) != 0) {
    close(fd);
    return -1;
  }
  return fd;
}

bool SendAll(int fd, const std::string& bytes) {
  size_t sent = 0;
  while (sent < bytes.size()) {
    const ssize_t n = send(fd, bytes.data() + sent, bytes.size() - sent, MSG_NOSIGNAL);
    if (n <= 0) return false;
    sent += size_t(n);
  }
  return true;
}

// What arrives on `fd` until the server closes it (or resets it: *closed) or `timeout` passes.
std::string ReceiveUntilClosed(int fd, std::chrono::milliseconds timeout, bool* closed = nullptr) {
  std::string received;
  const auto until = Clock::now() + timeout;
  char buffer[4096];
  if (closed != nullptr) *closed = false;
  while (Clock::now() < until) {
    pollfd entry{fd, POLLIN, 0};
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(until - Clock::now());
    if (poll(&entry, 1, int(std::max<int64_t>(1, left.count()))) <= 0) break;
    const ssize_t n = recv(fd, buffer, sizeof(buffer), 0);
    if (n <= 0) {
      if (closed != nullptr) *closed = true;
      break;
    }
    received.append(buffer, size_t(n));
  }
  return received;
}

// The status code of a raw HTTP response, 0 for none.
int StatusOf(const std::string& response) {
  if (!response.starts_with("HTTP/1.1 ") || response.size() < 12) return 0;
  return std::stoi(response.substr(9, 3));
}

std::string BodyOf(const std::string& response) {
  const size_t end = response.find("\r\n\r\n");
  return end == std::string::npos ? std::string() : response.substr(end + 4);
}

// The log lines recogd writes while it lives, as text.
class CapturedLog {
 public:
  CapturedLog() : sink_(std::make_shared<spdlog::sinks::ostream_sink_mt>(text_)) {
    sink_->set_pattern("%v");
    spdlog::default_logger()->sinks().push_back(sink_);
    spdlog::set_level(spdlog::level::debug);
  }
  ~CapturedLog() {
    auto& sinks = spdlog::default_logger()->sinks();
    sinks.erase(std::find(sinks.begin(), sinks.end(), sink_));
    spdlog::set_level(spdlog::level::warn);
  }
  std::string Text() {
    spdlog::default_logger()->flush();
    return text_.str();
  }

 private:
  std::ostringstream text_;
  std::shared_ptr<spdlog::sinks::ostream_sink_mt> sink_;
};

class ConsoleHardeningTest : public ServerFixture {
 protected:
  ConsoleHardeningTest() { config().console.listen = "127.0.0.1:0"; }

  int console_port() const { return server_->console_port(); }
  std::string Host() const { return "127.0.0.1:" + std::to_string(console_port()); }

  // Sends `request` as it is (from `source`) and returns the whole response.
  std::string Raw(const std::string& request, const char* source = "127.0.0.1") {
    const int fd = Connect(console_port(), source);
    if (fd < 0) return "no connection";
    SendAll(fd, request);
    std::string response = ReceiveUntilClosed(fd, std::chrono::seconds(10));
    close(fd);
    return response;
  }
  std::string RawGet(const std::string& path, const std::string& headers = {}) {
    return Raw("GET " + path + " HTTP/1.1\r\nHost: " + Host() + "\r\nConnection: close\r\n" +
               headers + "\r\n");
  }

  // Restarts recogd with a token file: admin (write, every map) and robot-a (writes robot-a*).
  void UseTokens() {
    const std::string tokens = data_dir_.Sub("tokens.yaml");
    std::ofstream(tokens) << "tokens:\n"
                          << "  - name: admin\n    token: " << kAdmin << "\n    rights: [write]\n"
                          << "  - name: robot-a\n    token: " << kRobotA
                          << "\n    rights: [write]\n    maps:\n      write: ['robot-a*']\n";
    StopServer();
    config().token_file = tokens;
    StartServer();
  }

  // Both ports answer: a real frame over gRPC, and the console's whoami.
  void ExpectServing(const std::string& token = {}) {
    pb::QueryPlaceRequest query;
    query.set_map("alive-check");
    *query.mutable_frame() = JpegFrame(CorridorJpeg(1));
    pb::CreateMapRequest create;
    create.set_name("alive-check");
    pb::CreateMapResponse created;
    const grpc::Status made = places_->CreateMap(Context(token).get(), create, &created);
    ASSERT_TRUE(made.ok() || made.error_code() == grpc::StatusCode::ALREADY_EXISTS)
        << made.error_message();
    pb::QueryPlaceResponse answer;
    const grpc::Status queried = places_->QueryPlace(Context(token).get(), query, &answer);
    EXPECT_TRUE(queried.ok()) << queried.error_message();
    EXPECT_EQ(StatusOf(RawGet("/api/whoami")), 200);
  }
};

TEST_F(ConsoleHardeningTest, InvalidUtf8InAnApiPathIsAJsonErrorNotACrash) {
  for (const std::string path : {"/api/%FF", "/api/maps/%FF/loops", "/api/models/%C3%28",
                                 "/api/maps/%FF%FE/frames/%FF/thumbnail"}) {
    const std::string response = RawGet(path);
    EXPECT_EQ(StatusOf(response), 404) << path << ": " << response;
    const json body = json::parse(BodyOf(response), nullptr, false);
    ASSERT_FALSE(body.is_discarded()) << response;
    EXPECT_EQ(body["code"], "NOT_FOUND");
  }
  ExpectServing();
}

TEST_F(ConsoleHardeningTest, InvalidUtf8InAnApiPathIsAJsonErrorWithTokensToo) {
  UseTokens();
  EXPECT_EQ(StatusOf(RawGet("/api/%FF")), 404);
  EXPECT_EQ(StatusOf(RawGet("/api/maps/%FF/loops")), 401);
  EXPECT_EQ(StatusOf(RawGet("/api/maps/%FF/loops",
                            "Authorization: Bearer " + std::string(kAdmin) + "\r\n")),
            404);
  ExpectServing(kAdmin);
}

TEST_F(ConsoleHardeningTest, AnAuthorizationHeaderWithATabOrANonAsciiByteIsRefusedUnlogged) {
  UseTokens();
  CapturedLog log;
  const std::string body = "{}";
  for (const std::string& authorization :
       {"Bearer\t" + std::string(kAdmin), "Bearer " + std::string(kAdmin) + "\xC3\xA9",
        std::string("Bearer \x01") + kAdmin}) {
    const std::string response =
        Raw("POST /api/rpc/recognition.v1.PlaceRecognition/ListMaps HTTP/1.1\r\nHost: " + Host() +
            "\r\nAuthorization: " + authorization +
            "\r\nContent-Type: application/json\r\nContent-Length: 2\r\n\r\n" + body);
    EXPECT_EQ(StatusOf(response), 401) << response;
    EXPECT_EQ(json::parse(BodyOf(response), nullptr, false)["code"], "UNAUTHENTICATED");
    EXPECT_EQ(StatusOf(RawGet("/api/maps", "Authorization: " + authorization + "\r\n")), 401);
  }
  ExpectServing(kAdmin);
  EXPECT_EQ(log.Text().find(kAdmin), std::string::npos);
}

TEST_F(ConsoleHardeningTest, ChunkedOrCompressedBodiesAreRefusedBeforeTheyAreRead) {
  UseTokens();
  const std::string head =
      "POST /api/rpc/recognition.v1.PlaceRecognition/ListMaps HTTP/1.1\r\n"
      "Host: " +
      Host() + "\r\nContent-Type: application/json\r\n";
  // 200 MiB announced in chunks, without a token: only the first chunk's start is ever sent, and
  // the refusal comes without waiting for the rest.
  const int fd = Connect(console_port());
  ASSERT_GE(fd, 0);
  ASSERT_TRUE(
      SendAll(fd, head + "Transfer-Encoding: chunked\r\n\r\nC800000\r\n" + std::string(4096, '{')));
  const auto start = Clock::now();
  const std::string chunked = ReceiveUntilClosed(fd, std::chrono::seconds(5));
  close(fd);
  EXPECT_EQ(StatusOf(chunked), 411) << chunked;
  EXPECT_LT(Clock::now() - start, std::chrono::seconds(3));
  // 200 MiB announced with Content-Length: refused at once as well.
  const int big = Connect(console_port());
  ASSERT_TRUE(SendAll(big, head + "Content-Length: 209715200\r\n\r\n{"));
  const std::string too_large = ReceiveUntilClosed(big, std::chrono::seconds(5));
  close(big);
  EXPECT_EQ(StatusOf(too_large), 413) << too_large;
  // A gzip body would be inflated without bound.
  EXPECT_EQ(StatusOf(Raw(head + "Authorization: Bearer " + kAdmin +
                         "\r\nContent-Encoding: gzip\r\nContent-Length: 2\r\n\r\n{}")),
            415);
  // Without a token, nothing of a body is read: 401 before it.
  EXPECT_EQ(StatusOf(Raw(head + "Content-Length: 2\r\n\r\n{}")), 401);
  // A body on anything but the gateway's calls.
  EXPECT_EQ(StatusOf(Raw("GET /api/whoami HTTP/1.1\r\nHost: " + Host() +
                         "\r\nContent-Length: 5\r\n\r\nhello")),
            400);
  EXPECT_EQ(StatusOf(Raw("DELETE /api/maps HTTP/1.1\r\nHost: " + Host() + "\r\n\r\n")), 405);
  ExpectServing(kAdmin);
}

// The first bytes of a PNG declaring 20000 x 20000 grey pixels, with a short IDAT: a
// decompression bomb's header (decoding used to allocate its 400 MB before failing).
std::string PngBombHeader() {
  std::string ihdr("IHDR", 4);
  for (uint32_t v : {20000u, 20000u}) {
    for (int shift = 24; shift >= 0; shift -= 8) ihdr += char((v >> shift) & 0xFF);
  }
  ihdr += std::string("\x08\x00\x00\x00\x00", 5);
  std::string bytes("\x89PNG\r\n\x1a\n\0\0\0\x0d", 12);
  bytes += ihdr + std::string(4, '\0');  // CRC left wrong: the header is refused before it
  return bytes + std::string("\0\0\0\x02IDAT\x78\x9c\0\0\0\0", 14);
}

TEST_F(ConsoleHardeningTest, AnImageDeclaringTooManyPixelsIsRefusedBeforeItIsDecoded) {
  ASSERT_TRUE(CreateMap("bomb").ok());
  pb::QueryPlaceRequest request;
  request.set_map("bomb");
  *request.mutable_frame() = JpegFrame(PngBombHeader());
  pb::QueryPlaceResponse response;
  const grpc::Status refused = places_->QueryPlace(Context().get(), request, &response);
  EXPECT_EQ(refused.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(refused.error_message().find("too large (20000x20000"), std::string::npos)
      << refused.error_message();
  // The same through the console.
  const std::string json_request = ToJson(request);
  const std::string answer =
      Raw("POST /api/rpc/recognition.v1.PlaceRecognition/QueryPlace HTTP/1.1\r\nHost: " + Host() +
          "\r\nContent-Type: application/json\r\nContent-Length: " +
          std::to_string(json_request.size()) + "\r\nConnection: close\r\n\r\n" + json_request);
  EXPECT_EQ(StatusOf(answer), 400) << answer;
  EXPECT_NE(answer.find("20000x20000"), std::string::npos) << answer;
  ExpectServing();
}

TEST_F(ConsoleHardeningTest, AdminCallsNeedATokenThatReachesEveryMap) {
  UseTokens();
  auto admin = pb::Admin::NewStub(channel_);
  pb::VerifyResponse verified;
  EXPECT_EQ(admin->Verify(Context(kRobotA).get(), pb::VerifyRequest(), &verified).error_code(),
            grpc::StatusCode::PERMISSION_DENIED);
  pb::StoreStatusResponse store;
  EXPECT_EQ(
      admin->StoreStatus(Context(kRobotA).get(), pb::StoreStatusRequest(), &store).error_code(),
      grpc::StatusCode::PERMISSION_DENIED);
  auto context = Context(kRobotA);
  auto checkpoint = admin->Checkpoint(context.get(), pb::CheckpointRequest());
  pb::CheckpointResponse chunk;
  int chunks = 0;
  while (checkpoint->Read(&chunk)) ++chunks;
  const grpc::Status refused = checkpoint->Finish();
  EXPECT_EQ(refused.error_code(), grpc::StatusCode::PERMISSION_DENIED);
  EXPECT_NE(refused.error_message().find("robot-a"), std::string::npos);
  EXPECT_EQ(chunks, 0);
  // The console's gateway holds the same rule.
  const std::string response =
      Raw("POST /api/rpc/recognition.v1.Admin/Verify HTTP/1.1\r\nHost: " + Host() +
          "\r\nAuthorization: Bearer " + kRobotA +
          "\r\nContent-Type: application/json\r\nContent-Length: 2\r\n\r\n{}");
  EXPECT_EQ(StatusOf(response), 403) << response;
  // An unscoped token may.
  EXPECT_TRUE(admin->Verify(Context(kAdmin).get(), pb::VerifyRequest(), &verified).ok());
  EXPECT_TRUE(admin->StoreStatus(Context(kAdmin).get(), pb::StoreStatusRequest(), &store).ok());
}

// `model` (an encoded .robj) with `from` replaced by `to` (as many bytes) and its checksums
// computed again: a file as a writer could craft it.
std::string Patched(std::string model, const std::string& from, const std::string& to) {
  const size_t at = model.find(from);
  EXPECT_NE(at, std::string::npos);
  model.replace(at, to.size(), to);
  constexpr size_t kHeader = 40;
  const uint64_t body = XXH3_64bits(model.data() + kHeader, model.size() - kHeader);
  std::memcpy(model.data() + 24, &body, 8);
  const uint64_t header = XXH3_64bits(model.data(), 32);
  std::memcpy(model.data() + 32, &header, 8);
  return model;
}

TEST_F(ConsoleHardeningTest, AModelWhoseClassIsNotUtf8IsRefusedAndTheListingStillWorks) {
  const std::string bytes =
      Patched(recog::testing::ModelFile("crate", {1}, "QQQQ"), "QQQQ", "\xFF\xFE\xFF\xFE");
  const grpc::Status refused = PutModel(bytes, "crate");
  EXPECT_EQ(refused.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(refused.error_message().find("UTF-8"), std::string::npos) << refused.error_message();
  pb::ListModelsResponse listed;
  EXPECT_TRUE(models_->ListModels(Context().get(), pb::ListModelsRequest(), &listed).ok());
  EXPECT_EQ(listed.models_size(), 0);
  EXPECT_EQ(
      StatusOf(Raw("POST /api/rpc/recognition.v1.ObjectRepository/ListModels HTTP/1.1\r\n"
                   "Host: " +
                   Host() + "\r\nContent-Type: application/json\r\nContent-Length: 2\r\n\r\n{}")),
      200);
}

TEST_F(ConsoleHardeningTest, ARequestForAnotherHostOrFromAnotherOriginIsRefused) {
  const int port = console_port();
  const auto get = [&](const std::string& host, const std::string& origin = {}) {
    return StatusOf(Raw("GET /api/whoami HTTP/1.1\r\nHost: " + host + "\r\n" +
                        (origin.empty() ? "" : "Origin: " + origin + "\r\n") +
                        "Connection: close\r\n\r\n"));
  };
  // A page that rebinds its own name to 127.0.0.1 sends its name.
  EXPECT_EQ(get("rebind.attacker.example:" + std::to_string(port)), 403);
  EXPECT_EQ(get("rebind.attacker.example"), 403);
  EXPECT_EQ(get(""), 403);
  EXPECT_EQ(get("127.0.0.1:" + std::to_string(port)), 200);
  EXPECT_EQ(get("localhost:" + std::to_string(port)), 200);
  EXPECT_EQ(get("[::1]:" + std::to_string(port)), 200);
  EXPECT_EQ(get(Host(), "http://" + Host()), 200);
  EXPECT_EQ(get(Host(), "http://rebind.attacker.example"), 403);
  EXPECT_EQ(get(Host(), "null"), 403);
  // A write from another origin, without tokens: refused, nothing created.
  const std::string create = R"({"name": "forged"})";
  EXPECT_EQ(StatusOf(Raw("POST /api/rpc/recognition.v1.PlaceRecognition/CreateMap HTTP/1.1\r\n"
                         "Host: " +
                         Host() +
                         "\r\nOrigin: http://attacker.example\r\n"
                         "Content-Type: application/json\r\nContent-Length: " +
                         std::to_string(create.size()) + "\r\n\r\n" + create)),
            403);
  EXPECT_EQ(GetMap("forged").error_code(), grpc::StatusCode::NOT_FOUND);
  // A name the operator lists is accepted.
  StopServer();
  config().console.hosts = {"recog.example.com"};
  StartServer();
  EXPECT_EQ(get("recog.example.com"), 200);
  EXPECT_EQ(get("Recog.Example.Com:443"), 200);
  EXPECT_EQ(get("other.example.com"), 403);
}

TEST_F(ConsoleHardeningTest, SlowClientsCannotStarveTheConsole) {
  StopServer();
  // The slow clients' deadline, 4 s, is far from the fast client's bound, 2 s: a starved console
  // answers after the deadline, a fair one well before it, even under a sanitizer on a busy
  // machine.
  config().console.request_timeout_ms = 4000;
  StartServer();
  // 50 connections from another address trickle their headers a byte at a time.
  std::vector<int> slow;
  for (int i = 0; i < 50; ++i) {
    const int fd = Connect(console_port(), "127.0.0.2");
    ASSERT_GE(fd, 0);
    SendAll(fd, "GET /api/whoami HTTP/1.1\r\nHost: " + Host() + "\r\n");
    slow.push_back(fd);
  }
  std::atomic<bool> trickling{true};
  std::thread trickle([&] {
    while (trickling) {
      for (int fd : slow) send(fd, "X", 1, MSG_NOSIGNAL | MSG_DONTWAIT);
      std::this_thread::sleep_for(std::chrono::milliseconds(200));
    }
  });
  // Meanwhile another client is answered at once, again and again.
  for (int i = 0; i < 10; ++i) {
    const auto start = Clock::now();
    EXPECT_EQ(StatusOf(RawGet("/api/whoami")), 200);
    EXPECT_LT(Clock::now() - start, std::chrono::milliseconds(2000));
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  // The slow ones were refused (beyond the per-client cap: 503, or a reset when no thread was
  // free) or cut at their deadline: the server has closed every one of them.
  int closed = 0, unavailable = 0;
  for (int fd : slow) {
    bool was_closed = false;
    const std::string got = ReceiveUntilClosed(fd, std::chrono::seconds(6), &was_closed);
    closed += was_closed;
    unavailable += StatusOf(got) == 503;
    EXPECT_NE(StatusOf(got), 200);
  }
  trickling = false;
  trickle.join();
  for (int fd : slow) close(fd);
  EXPECT_EQ(closed, 50);
  EXPECT_GE(unavailable, 1);  // the refusals are sent without waiting: some arrive before a reset
  ExpectServing();
}

TEST_F(ConsoleHardeningTest, ANameWithANewlineCannotForgeALogLine) {
  CapturedLog log;
  const std::string forged = "x\nrequest=forged method=/Admin/Delete code=OK";
  EXPECT_EQ(GetMap(forged).error_code(), grpc::StatusCode::NOT_FOUND);
  const std::string text = log.Text();
  EXPECT_EQ(text.find("\nrequest=forged"), std::string::npos) << text;
  EXPECT_NE(text.find("x\\x0Arequest=forged"), std::string::npos) << text;
}

TEST_F(ConsoleHardeningTest, EveryAnswerForbidsFramingAndSniffingAndOnlyTheConsolesFilesAreServed) {
  for (const std::string path : {"/static/index.html", "/api/whoami", "/api/nothing"}) {
    const std::string response = RawGet(path);
    EXPECT_NE(response.find("Content-Security-Policy: default-src 'self'"), std::string::npos)
        << path << ": " << response;
    EXPECT_NE(response.find("frame-ancestors 'none'"), std::string::npos) << path;
    EXPECT_NE(response.find("X-Content-Type-Options: nosniff"), std::string::npos) << path;
    EXPECT_NE(response.find("X-Frame-Options: DENY"), std::string::npos) << path;
  }
  for (const std::string path : {"/static/main.js", "/static/api.js", "/static/dom.js",
                                 "/static/format.js", "/static/linechart.js", "/static/maps.js"}) {
    EXPECT_EQ(StatusOf(RawGet(path)), 200) << path;
  }
  for (const std::string path :
       {"/static/main.js%00.html", "/static/app.js", "/static/../../CMakeLists.txt",
        "/static/%2e%2e/%2e%2e/CMakeLists.txt", "/static/",
        "/vendor/three/../../../../etc/passwd"}) {
    EXPECT_EQ(StatusOf(RawGet(path)), 404) << path;
  }
  const std::string script = RawGet("/api/%3Cscript%3Ealert(1)%3C%2Fscript%3E%00.html");
  EXPECT_EQ(StatusOf(script), 404);
  EXPECT_NE(script.find("Content-Type: application/json"), std::string::npos) << script;
  EXPECT_EQ(script.find("text/html"), std::string::npos) << script;
}

TEST(ConsoleTlsTest, TheConsoleAnswersOverTlsWithTheServersCertificate) {
  recog::testing::TempDir dir("console-tls");
  ServerConfig config;
  config.listen = "127.0.0.1:0";
  config.data_dir = dir.path().string();
  config.metrics_listen = "";
  config.console.listen = "127.0.0.1:0";
  config.tls.cert = recog::testing::ProjectTestData("tls/server.crt");
  config.tls.key = recog::testing::ProjectTestData("tls/server.key");
  auto server = RecognitionServer::Start(config);
  ASSERT_TRUE(server.ok()) << server.status().ToString();
  httplib::SSLClient client("127.0.0.1", (*server)->console_port());
  client.enable_server_certificate_verification(false);
  client.set_read_timeout(10);
  for (int i = 0; i < 3; ++i) {  // kept alive between requests
    httplib::Result who = client.Get("/api/whoami");
    ASSERT_TRUE(who) << httplib::to_string(who.error());
    EXPECT_EQ(who->status, 200);
    EXPECT_EQ(json::parse(who->body)["authenticated"], true);
  }
  // A plain-text request to the TLS port gets nothing, and the port still serves.
  const int fd = Connect((*server)->console_port());
  SendAll(fd, "GET /api/whoami HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n");
  EXPECT_EQ(StatusOf(ReceiveUntilClosed(fd, std::chrono::seconds(5))), 0);
  close(fd);
  EXPECT_EQ(client.Get("/api/whoami")->status, 200);
}

}  // namespace
}  // namespace recog::server::testing
