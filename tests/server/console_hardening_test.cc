// The console, the metrics port and the gRPC port against requests an attacker would send (issue
// 42's findings and those of the HTTP ports' probe, each with the request that found it): invalid
// UTF-8 in a path, control bytes in the Authorization header, chunked and compressed bodies,
// decompression bombs, map-scoped tokens on the admin calls, invalid UTF-8 in an uploaded model,
// DNS rebinding (on both HTTP ports), slow clients (on both), forged log lines, framing and
// sniffing, thousands of byte ranges, millions of header lines, concurrent large gateway bodies,
// and the strictness of Host, Content-Type, Content-Length and JSON keys. After each, recogd must
// still answer its ports; the attacks on memory assert how much the process grew.
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
#include <future>
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

// Sends `request` on `fd` while reading what comes back, until the server closes the connection
// (or `timeout` passes): the server may answer, and close, before it has read everything. The
// bytes the server took are *sent.
std::string Exchange(int fd, const std::string& request, std::chrono::milliseconds timeout,
                     size_t* sent = nullptr) {
  std::string received;
  size_t at = 0;
  char buffer[65536];
  const auto until = Clock::now() + timeout;
  while (Clock::now() < until) {
    pollfd entry{fd, short(POLLIN | (at < request.size() ? POLLOUT : 0)), 0};
    if (poll(&entry, 1, 50) <= 0) continue;
    if (entry.revents & (POLLIN | POLLHUP | POLLERR)) {
      const ssize_t n = recv(fd, buffer, sizeof(buffer), MSG_DONTWAIT);
      if (n == 0 || (n < 0 && errno != EAGAIN)) break;
      if (n > 0) received.append(buffer, size_t(n));
    } else if (entry.revents & POLLOUT) {
      const ssize_t n = send(fd, request.data() + at, std::min<size_t>(request.size() - at, 65536),
                             MSG_NOSIGNAL | MSG_DONTWAIT);
      if (n > 0) at += size_t(n);
    }
  }
  if (sent != nullptr) *sent = at;
  return received;
}

// One field of /proc/self/status ("VmRSS", "VmHWM"), in MiB.
double ProcessMiB(const std::string& field) {
  std::ifstream status("/proc/self/status");
  for (std::string line; std::getline(status, line);) {
    if (line.starts_with(field + ":")) return std::stod(line.substr(field.size() + 1)) / 1024;
  }
  return 0;
}

// How far the process's resident memory rose above where it was while `attack` ran (its peak,
// VmHWM, reset first), in MiB.
template <typename Attack>
double PeakGrowthMiB(Attack attack) {
  std::ofstream("/proc/self/clear_refs") << "5";  // resets VmHWM to the current RSS
  const double before = ProcessMiB("VmRSS");
  attack();
  return ProcessMiB("VmHWM") - before;
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
  ConsoleHardeningTest() {
    config().console.listen = "127.0.0.1:0";
    config().metrics_listen = "127.0.0.1:0";
  }

  int console_port() const { return server_->console_port(); }
  int metrics_port() const { return server_->metrics_port(); }
  std::string Host() const { return "127.0.0.1:" + std::to_string(console_port()); }

  // Sends `request` as it is (from `source`, to `port`: the console's by default) and returns the
  // whole response.
  std::string Raw(const std::string& request, const char* source = "127.0.0.1", int port = 0) {
    const int fd = Connect(port == 0 ? console_port() : port, source);
    if (fd < 0) return "no connection";
    SendAll(fd, request);
    std::string response = ReceiveUntilClosed(fd, std::chrono::seconds(10));
    close(fd);
    return response;
  }
  std::string Scrape(const std::string& host = "127.0.0.1") {
    return Raw("GET /metrics HTTP/1.1\r\nHost: " + host + "\r\nConnection: close\r\n\r\n",
               "127.0.0.1", metrics_port());
  }
  // A gateway call with `body` and `headers` besides Host and Content-Length.
  std::string Call(const std::string& method, const std::string& body,
                   const std::string& headers = "Content-Type: application/json\r\n") {
    return Raw("POST /api/rpc/" + method + " HTTP/1.1\r\nHost: " + Host() + "\r\n" + headers +
               "Content-Length: " + std::to_string(body.size()) + "\r\nConnection: close\r\n\r\n" +
               body);
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
    if (metrics_port() > 0) {
      EXPECT_EQ(StatusOf(Scrape()), 200);
    }
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
  // A control byte other than a tab makes the request's head malformed (400, before the gate);
  // a tab or a byte beyond ASCII reaches the gate, which refuses it (401).
  for (const std::string& authorization :
       {"Bearer\t" + std::string(kAdmin), "Bearer " + std::string(kAdmin) + "\xC3\xA9",
        std::string("Bearer \x01") + kAdmin}) {
    const int refusal = authorization.find('\x01') == std::string::npos ? 401 : 400;
    const std::string response =
        Raw("POST /api/rpc/recognition.v1.PlaceRecognition/ListMaps HTTP/1.1\r\nHost: " + Host() +
            "\r\nAuthorization: " + authorization +
            "\r\nContent-Type: application/json\r\nContent-Length: 2\r\n\r\n" + body);
    EXPECT_EQ(StatusOf(response), refusal) << response;
    EXPECT_EQ(json::parse(BodyOf(response), nullptr, false)["code"],
              refusal == 401 ? "UNAUTHENTICATED" : "INVALID_ARGUMENT");
    EXPECT_EQ(StatusOf(RawGet("/api/maps", "Authorization: " + authorization + "\r\n")), refusal);
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
      std::this_thread::sleep_for(std::chrono::milliseconds(200));  // slow is what they must be
    }
  });
  // Meanwhile another client is answered at once, again and again.
  for (int i = 0; i < 10; ++i) {
    const auto start = Clock::now();
    EXPECT_EQ(StatusOf(RawGet("/api/whoami")), 200);
    EXPECT_LT(Clock::now() - start, std::chrono::milliseconds(2000));
    std::this_thread::sleep_for(std::chrono::milliseconds(100));  // spread over the attack
  }
  // The slow ones were evicted (beyond the per-client cap, the oldest made room for the newer)
  // or cut at the minimum rate (408): the server has closed every one of them.
  int closed = 0, timed_out = 0;
  for (int fd : slow) {
    bool was_closed = false;
    const std::string got = ReceiveUntilClosed(fd, std::chrono::seconds(6), &was_closed);
    closed += was_closed;
    timed_out += StatusOf(got) == 408;
    EXPECT_NE(StatusOf(got), 200);
  }
  trickling = false;
  trickle.join();
  for (int fd : slow) close(fd);
  EXPECT_EQ(closed, 50);
  EXPECT_GE(timed_out, 1);  // the last 8 were cut by the rate, with an answer
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

// Finding 1: a Range of 2,000 ranges of one file used to build a copy of the file per range
// (2.4 GB for three.js from an 8 KB request).
TEST_F(ConsoleHardeningTest, ARangeOfThousandsOfRangesIsAnsweredWithTheFileOnce) {
  const bool vendored = std::filesystem::exists(config().console.vendor_dir + "/three/three.js");
  const std::string path = vendored ? "/vendor/three/three.js" : "/static/try.js";
  const std::string whole = BodyOf(RawGet(path));
  ASSERT_GT(whole.size(), 1000u);
  std::string ranges = "Range: bytes=0-";
  for (int i = 1; i < 2000; ++i) ranges += ",0-";
  std::string response;
  const double growth = PeakGrowthMiB([&] { response = RawGet(path, ranges + "\r\n"); });
  EXPECT_EQ(StatusOf(response), 200) << response.substr(0, 300);
  EXPECT_EQ(BodyOf(response), whole);
  EXPECT_EQ(response.find("multipart/byteranges"), std::string::npos);
  EXPECT_LT(growth, 50.0) << path;
  std::cout << "2000 ranges of " << path << " (" << whole.size() << " bytes): RSS +" << growth
            << " MiB\n";
  // One range is served as such.
  const std::string one = RawGet(path, "Range: bytes=10-19\r\n");
  EXPECT_EQ(StatusOf(one), 206) << one.substr(0, 300);
  EXPECT_EQ(BodyOf(one), whole.substr(10, 10));
  EXPECT_NE(one.find("Content-Range: bytes 10-19/" + std::to_string(whole.size())),
            std::string::npos);
  ExpectServing();
}

// Finding 2: header lines were stored as they came, without a limit (10 million: +1 GB).
TEST_F(ConsoleHardeningTest, TenMillionHeaderLinesAreRefusedWhileTheyAreRead) {
  const int fd = Connect(console_port());
  ASSERT_GE(fd, 0);
  const std::string head = "GET /api/whoami HTTP/1.1\r\nHost: " + Host() + "\r\n";
  std::string lines;
  for (int i = 0; i < 10000; ++i) lines += "X-A: a\r\n";
  std::string attack = head;  // 10,000,000 lines (80 MB), sent unless the server answers first
  for (int i = 0; i < 1000; ++i) attack += lines;
  std::string response;
  size_t sent = 0;
  const double growth =
      PeakGrowthMiB([&] { response = Exchange(fd, attack, std::chrono::seconds(10), &sent); });
  close(fd);
  EXPECT_EQ(StatusOf(response), 431) << response;
  EXPECT_NE(response.find("Content-Security-Policy"), std::string::npos) << response;
  EXPECT_NE(response.find("Connection: close"), std::string::npos);
  EXPECT_LT(sent, size_t(16) << 20) << "the server read on after its refusal";
  EXPECT_LT(growth, 50.0);
  std::cout << "header lines: " << sent << " bytes taken before the 431, RSS +" << growth
            << " MiB\n";
  // The limits themselves: 100 lines and 16 KiB pass, one more line or byte does not.
  std::string hundred;
  for (int i = 0; i < 98; ++i) hundred += "X-A: a\r\n";  // with Host and Connection: 100
  EXPECT_EQ(StatusOf(RawGet("/api/whoami", hundred)), 200);
  EXPECT_EQ(StatusOf(RawGet("/api/whoami", hundred + "X-A: a\r\n")), 431);
  // (cpp-httplib takes lines of at most 8 KiB: the bytes are spread over two lines.)
  const std::string fill = "X-Fill: " + std::string(7900, 'f') + "\r\n";
  EXPECT_EQ(StatusOf(RawGet("/api/whoami", fill + fill)), 200);
  EXPECT_EQ(
      StatusOf(RawGet("/api/whoami", fill + fill + "X-More: " + std::string(600, 'm') + "\r\n")),
      431);
  EXPECT_EQ(StatusOf(Raw("GET /" + std::string(20000, 'a') + " HTTP/1.1\r\nHost: " + Host() +
                         "\r\n\r\n")),
            431);
  ExpectServing();
}

// Finding 3: the gateway held about 5 times each body (8 concurrent 42 MB bodies: +1.6 GB).
TEST_F(ConsoleHardeningTest, ConcurrentLargeGatewayBodiesStayWithinTheBudget) {
  // A QueryPlace of `size` bytes, nearly all of them its frame's image in base64: valid JSON that
  // the gateway decodes whole (the map does not exist).
  const auto request = [&](size_t size) {
    const std::string head = R"({"map": "none", "frame": {"image": ")", tail = R"("}})";
    const std::string body =
        head + std::string((size - head.size() - tail.size()) / 4 * 4, 'A') + tail;
    return "POST /api/rpc/recognition.v1.PlaceRecognition/QueryPlace HTTP/1.1\r\nHost: " + Host() +
           "\r\nContent-Type: application/json\r\nContent-Length: " + std::to_string(body.size()) +
           "\r\nConnection: close\r\n\r\n" + body;
  };
  const auto concurrently = [&](const std::string& text, std::map<int, int>* statuses) {
    std::vector<std::future<std::string>> answers;
    for (int i = 0; i < 8; ++i) {
      answers.push_back(std::async(std::launch::async, [&, i] {
        const std::string source = "127.0.0." + std::to_string(2 + i);
        const int fd = Connect(console_port(), source.c_str());
        std::string answer = Exchange(fd, text, std::chrono::seconds(20));
        close(fd);
        return answer;
      }));
    }
    for (auto& answer : answers) ++(*statuses)[StatusOf(answer.get())];
  };
  // 42 MB each: over console.max_body_bytes, refused before a byte of the body is read.
  std::map<int, int> over;
  const std::string huge = request(42'000'000);
  const double over_growth = PeakGrowthMiB([&] { concurrently(huge, &over); });
  EXPECT_EQ(over[413], 8);
  // 16 MiB each, the most one call may send: two fit in the 32 MiB budget at once, the others
  // are told to retry (or come when it is free again).
  std::map<int, int> at_limit;
  const std::string largest = request(size_t(16) << 20);
  const double growth = PeakGrowthMiB([&] { concurrently(largest, &at_limit); });
  // Decoded and called: refused by the service (no such map, or not an image).
  const int decoded = at_limit[400] + at_limit[404];
  EXPECT_EQ(decoded + at_limit[503], 8);
  EXPECT_GE(decoded, 2);
  std::cout << "8 x 42 MB bodies: RSS +" << over_growth << " MiB; 8 x 16 MiB: " << decoded
            << " decoded, " << at_limit[503] << " x 503, RSS +" << growth << " MiB\n";
  // The request strings themselves (42 and 16 MB) are the test's, not the server's.
  EXPECT_LT(over_growth, 50.0);
  EXPECT_LT(growth, 200.0);
  // The budget's refusal says why, and closes the connection: held with a body half sent.
  StopServer();
  config().console.max_body_bytes = 1 << 20;
  config().console.max_inflight_body_bytes = 1 << 20;
  StartServer();
  const std::string held = request(1 << 20);
  const auto hold = [&] {
    const int fd = Connect(console_port());
    EXPECT_TRUE(SendAll(fd, held.substr(0, held.size() / 2)));
    return fd;
  };
  int holder = hold();
  std::string busy;
  const auto until = Clock::now() + std::chrono::seconds(5);
  while (StatusOf(busy) != 503 && Clock::now() < until) {
    busy = Raw(request(1000));
    // A probe that reserved its 1000 bytes first leaves the holder refused (503, closed): the
    // budget is then free, so hold it again.
    pollfd answered{holder, POLLIN, 0};
    if (poll(&answered, 1, 0) > 0) {
      close(holder);
      holder = hold();
    }
  }
  EXPECT_EQ(StatusOf(busy), 503) << busy;
  EXPECT_NE(BodyOf(busy).find("retry later"), std::string::npos) << busy;
  EXPECT_NE(busy.find("Retry-After: 1"), std::string::npos);
  close(holder);
  const auto again = Clock::now() + std::chrono::seconds(5);
  while (StatusOf(busy) == 503 && Clock::now() < again) busy = Raw(request(1000));
  // The budget is free again once the holder is gone: the call is decoded and refused.
  EXPECT_TRUE(StatusOf(busy) == 400 || StatusOf(busy) == 404) << busy;
  ExpectServing();
}

// Finding 4: 40 slow connections from five addresses (a byte every 2 s) held the console's 32
// places, and 2 the metrics port's: everyone else got 503, or no scrape.
TEST_F(ConsoleHardeningTest, SlowClientsFromAFewAddressesCannotStarveEitherPort) {
  std::atomic<bool> attacking{true};
  std::atomic<int> cut{0};
  // The attacker keeps 40 connections to the console and 2 to the metrics port open, opening a
  // new one whenever one is closed, each sending its request a byte every 2 s.
  std::thread attacker([&] {
    struct Slow {
      int port;
      std::string source;
      int fd = -1;
      size_t next = 0;  // the byte of the request it sends next
      Clock::time_point due = Clock::now();
    };
    std::vector<Slow> slow;
    for (int i = 0; i < 40; ++i) {
      slow.push_back(
          Slow{.port = console_port(), .source = "127.0.0." + std::to_string(2 + i % 5)});
    }
    for (int i = 0; i < 2; ++i) slow.push_back(Slow{.port = metrics_port(), .source = "127.0.0.7"});
    const std::string request = "GET /metrics HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n";
    while (attacking) {
      for (Slow& s : slow) {
        char sink[4096];
        const ssize_t got = s.fd < 0 ? 1 : recv(s.fd, sink, sizeof(sink), MSG_DONTWAIT);
        if (got == 0 || (got < 0 && errno != EAGAIN)) {
          close(s.fd);
          s.fd = -1;
          ++cut;
        }
        if (s.fd < 0) {
          s.fd = Connect(s.port, s.source.c_str());
          s.next = 0;
          s.due = Clock::now();
        }
        if (s.fd >= 0 && Clock::now() >= s.due) {
          send(s.fd, request.data() + s.next % request.size(), 1, MSG_NOSIGNAL | MSG_DONTWAIT);
          ++s.next;
          s.due = Clock::now() + std::chrono::seconds(2);
        }
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(20));  // the attack's pace
    }
    for (Slow& s : slow) close(s.fd);
  });
  // Meanwhile other clients (one of them from an attacker's address, as behind a proxy) are
  // answered on both ports, again and again, each well within 2 s.
  for (int i = 0; i < 8; ++i) {
    const auto start = Clock::now();
    const std::string whoami =
        Raw("GET /api/whoami HTTP/1.1\r\nHost: " + Host() + "\r\nConnection: close\r\n\r\n",
            i % 2 == 0 ? "127.0.0.1" : "127.0.0.2");
    EXPECT_EQ(StatusOf(whoami), 200) << "request " << i << " got '" << whoami << "'";
    const std::string scrape = Scrape();
    EXPECT_EQ(StatusOf(scrape), 200) << "scrape " << i << " got '" << scrape.substr(0, 200) << "'";
    EXPECT_LT(Clock::now() - start, std::chrono::milliseconds(2000));
    std::this_thread::sleep_for(std::chrono::milliseconds(300));  // spread over the attack
  }
  attacking = false;
  attacker.join();
  // The slow ones were cut (at the minimum rate, after a second), not served for ever.
  EXPECT_GE(cut.load(), 42);
  ExpectServing();
}

// Finding 4 again, without the minimum rate: a full console makes room by closing the connection
// that has waited longest for its request's headers, across clients and within one address; when
// every place serves a request, a new connection is refused with 503 (and, finding 6, the
// security headers of every answer).
TEST_F(ConsoleHardeningTest, AFullConsoleEvictsTheConnectionWaitingLongestForItsHeaders) {
  StopServer();
  config().console.min_bytes_per_s = 0;
  config().console.header_timeout_ms = 60000;
  config().console.request_timeout_ms = 60000;
  config().console.max_connections = 4;
  config().console.max_connections_per_client = 2;
  StartServer();
  // Whether the server has closed `fd` (within `wait`).
  const auto closed_by_server = [](int fd, std::chrono::milliseconds wait) {
    bool closed = false;
    ReceiveUntilClosed(fd, wait, &closed);
    return closed;
  };
  // Four clients send half a request each and wait: every place is taken.
  const std::string half = "GET /api/whoami HTTP/1.1\r\nHost: " + Host() + "\r\n";
  std::vector<int> slow;
  for (const char* source : {"127.0.0.2", "127.0.0.3", "127.0.0.4", "127.0.0.3"}) {
    slow.push_back(Connect(console_port(), source));
    ASSERT_TRUE(SendAll(slow.back(), half));
    // A connection's wait is counted from when its thread takes it up, which may come in another
    // order than the connections when they arrive together: spaced, "longest waiting" is theirs.
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  // All four are being served (no refusal), then a new client takes the oldest one's place.
  for (int fd : slow) EXPECT_FALSE(closed_by_server(fd, std::chrono::milliseconds(50)));
  EXPECT_EQ(StatusOf(RawGet("/api/whoami")), 200);
  EXPECT_TRUE(closed_by_server(slow[0], std::chrono::seconds(2)));
  // Within one address (a proxy's): its third connection takes the place of its oldest.
  const int third = Connect(console_port(), "127.0.0.3");
  const std::string proxied = Exchange(
      third, "GET /api/whoami HTTP/1.1\r\nHost: " + Host() + "\r\nConnection: close\r\n\r\n",
      std::chrono::seconds(5));
  close(third);
  EXPECT_EQ(StatusOf(proxied), 200) << proxied;
  EXPECT_TRUE(closed_by_server(slow[1], std::chrono::seconds(2)));
  for (int fd : slow) close(fd);
  // Four requests whose bodies are coming: nothing to evict, so a fifth client gets 503 at once.
  // The threads of the connections just closed may still be finishing (a refused request's
  // client is given a moment to stop sending): a request refused meanwhile is sent again.
  std::vector<int> busy;
  for (const char* source : {"127.0.0.2", "127.0.0.3", "127.0.0.4", "127.0.0.5"}) {
    const auto give_up = Clock::now() + std::chrono::seconds(5);
    do {
      const int fd = Connect(console_port(), source);
      ASSERT_TRUE(SendAll(
          fd,
          "POST /api/rpc/recognition.v1.PlaceRecognition/ListMaps HTTP/1.1\r\n"
          "Host: " +
              Host() + "\r\nContent-Type: application/json\r\nContent-Length: 100\r\n\r\n{"));
      if (!closed_by_server(fd, std::chrono::milliseconds(300))) {
        busy.push_back(fd);
        break;
      }
      close(fd);
    } while (Clock::now() < give_up);
  }
  ASSERT_EQ(busy.size(), 4u) << "the four requests were not all taken up";
  std::string refused;
  const auto until = Clock::now() + std::chrono::seconds(5);
  while (StatusOf(refused) != 503 && Clock::now() < until) refused = RawGet("/api/whoami");
  EXPECT_EQ(StatusOf(refused), 503) << refused;
  EXPECT_NE(refused.find("Content-Security-Policy: default-src 'self'"), std::string::npos)
      << refused;
  EXPECT_NE(refused.find("X-Frame-Options: DENY"), std::string::npos);
  for (int fd : busy) close(fd);
  ExpectServing();
}

// Finding 5: the metrics port answered any Host, so a rebinding page could read map names.
TEST_F(ConsoleHardeningTest, TheMetricsPortAnswersOnlyItsOwnHosts) {
  const std::string port = std::to_string(metrics_port());
  EXPECT_EQ(StatusOf(Scrape("rebind.attacker.example:" + port)), 403);
  EXPECT_EQ(StatusOf(Scrape("127.0.0.1:1@evil.example")), 403);
  EXPECT_EQ(StatusOf(Scrape("")), 403);
  EXPECT_EQ(StatusOf(Scrape("localhost:" + port)), 200);
  EXPECT_EQ(StatusOf(Scrape("[::1]:" + port)), 200);
  const std::string scraped = Scrape("127.0.0.1:" + port);
  EXPECT_EQ(StatusOf(scraped), 200);
  EXPECT_NE(scraped.find("recog_build_info"), std::string::npos);
  EXPECT_NE(scraped.find("X-Content-Type-Options: nosniff"), std::string::npos);
  const auto on_metrics = [&](const std::string& request) {
    return StatusOf(Raw(request, "127.0.0.1", metrics_port()));
  };
  EXPECT_EQ(on_metrics("POST /metrics HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Length: 0\r\n\r\n"),
            405);
  EXPECT_EQ(on_metrics("GET /other HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n"), 404);
  EXPECT_EQ(on_metrics("GET /metrics HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Length: 4\r\n\r\nbody"),
            400);
  StopServer();
  config().metrics.hosts = {"prometheus-target.example"};
  StartServer();
  EXPECT_EQ(StatusOf(Scrape("prometheus-target.example:9464")), 200);
  EXPECT_EQ(StatusOf(Scrape("other.example")), 403);
}

// Finding 6: what the console let through or said that it should not.
TEST_F(ConsoleHardeningTest, HostContentTypeContentLengthAndJsonKeysAreReadStrictly) {
  // Host is host[:port] and nothing else.
  for (const std::string host :
       {"127.0.0.1:1@evil.example", "127.0.0.1 evil.example", "127.0.0.1:99999",
        "127.0.0.1:", "127.0.0.1:8080/x", "evil.example%2F127.0.0.1", "[::1", "[::1]x"}) {
    EXPECT_EQ(StatusOf(Raw("GET /api/whoami HTTP/1.1\r\nHost: " + host +
                           "\r\nConnection: close\r\n\r\n")),
              403)
        << host;
  }
  // Content-Type: exactly application/json, with parameters or none.
  const std::string list = "recognition.v1.PlaceRecognition/ListMaps";
  EXPECT_EQ(StatusOf(Call(list, "{}", "Content-Type: application/jsonp\r\n")), 415);
  EXPECT_EQ(StatusOf(Call(list, "{}", "Content-Type: application/json-seq\r\n")), 415);
  EXPECT_EQ(StatusOf(Call(list, "{}", "Content-Type: application/json; charset=utf-8\r\n")), 200);
  EXPECT_EQ(StatusOf(Call(list, "{}", "Content-Type: Application/JSON\r\n")), 200);
  // A key named twice is refused, naming it.
  const std::string twice =
      Call("recognition.v1.PlaceRecognition/GetMap", R"({"name": "tour", "name": "other"})");
  EXPECT_EQ(StatusOf(twice), 400) << twice;
  EXPECT_NE(BodyOf(twice).find("the key 'name' twice"), std::string::npos) << twice;
  EXPECT_EQ(StatusOf(Call("recognition.v1.PlaceRecognition/QueryPlace",
                          R"({"map": "m", "frame": {"image": "", "image": "QQ=="}})")),
            400);
  EXPECT_EQ(StatusOf(Call(list, std::string(200, '[') + std::string(200, ']'))), 400);
  // Content-Length is plain digits as sent: httplib would decode "%32" into 2.
  for (const std::string length : {"%32", "+2", "0x2", "2, 2", "2 2", ""}) {
    const std::string response =
        Raw("POST /api/rpc/" + list + " HTTP/1.1\r\nHost: " + Host() +
            "\r\nContent-Type: application/json\r\nContent-Length: " + length + "\r\n\r\n{}");
    EXPECT_EQ(StatusOf(response), 400) << length << ": " << response;
  }
  EXPECT_EQ(StatusOf(Raw("POST /api/rpc/" + list + " HTTP/1.1\r\nHost: " + Host() +
                         "\r\nContent-Type: application/json\r\nContent-Length: 2\r\n"
                         "Content-Length: 2\r\n\r\n{}")),
            400);
  // Other header values are not decoded either: a Host of "%31%32%37.0.0.1" is no address.
  EXPECT_EQ(StatusOf(Raw("GET /api/whoami HTTP/1.1\r\nHost: %31%32%37.0.0.1\r\n"
                         "Connection: close\r\n\r\n")),
            403);
  // Malformed heads: a bare LF, a space before the colon, a folded line.
  for (const std::string line : {"X-A: a\n", "Host : 127.0.0.1\r\n", " folded\r\n"}) {
    EXPECT_EQ(StatusOf(RawGet("/api/whoami", line)), 400) << line;
  }
}

TEST_F(ConsoleHardeningTest, ErrorsNeverEchoTheRequest) {
  ASSERT_TRUE(CreateMap("echo").ok());
  const std::string marker = "EchoMarker";
  const std::vector<std::string> answers = {
      RawGet("/api/maps/" + marker + "/loops"),
      RawGet("/api/maps/" + marker + "%0A%3Cb%3E/loops"),
      RawGet("/api/maps/echo/frames/" + marker + "/thumbnail"),
      RawGet("/api/models/" + marker),
      RawGet("/api/models/" + marker + "/points?max=" + marker),
      RawGet("/api/" + marker),
      RawGet("/static/" + marker + ".js"),
      Call("recognition.v1." + marker + "/Get", "{}"),
      Call("recognition.v1.PlaceRecognition/GetMap", R"({")" + marker + R"(": 1})"),
      Call("recognition.v1.PlaceRecognition/GetMap", R"({"name": )" + marker + "}"),
      Call("recognition.v1.PlaceRecognition/GetMap", R"({"name": 1, ")" + marker + R"(": 1})"),
      Call("recognition.v1.PlaceRecognition/GetMap", R"({"name": ")" + marker + R"("})"),
      Call("recognition.v1.PlaceRecognition/GetMap",
           R"({"name": ")" + marker + std::string(5000, 'x') + R"("})"),
  };
  for (const std::string& answer : answers) {
    EXPECT_GE(StatusOf(answer), 400) << answer;
    EXPECT_EQ(BodyOf(answer).find(marker), std::string::npos) << answer;
  }
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
