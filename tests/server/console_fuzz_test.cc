// The console fuzzed as an attacker would: a bounded random request generator against a recogd in
// this process (CI runs it in the AddressSanitizer + UndefinedBehaviorSanitizer build too), with
// tokens off and on. Requests start from the seeds of tests/server/console_fuzz_corpus/ (a request
// line, headers, a blank line, a body; {HOST}, {AUTH}, {LENGTH} and {JPEG} are filled in) and are
// mutated: methods, paths (invalid UTF-8, NUL, traversal, huge numbers), headers (control bytes,
// duplicates, chunked and compressed bodies, other hosts and origins, lengths that lie), bodies
// (bytes flipped or cut, JSON values replaced, image headers declaring huge sizes), and gateway
// calls with JSON made up from each unary method's request type. Nothing is asserted of the
// answers; the server must answer every request or close the connection, never die, and answer a
// real frame on both ports at the end.
//
// Environment: RECOG_CONSOLE_FUZZ_REQUESTS (default 5000 per case), RECOG_CONSOLE_FUZZ_SEED
// (default 1). The long run quoted in docs/server.md:
//   RECOG_CONSOLE_FUZZ_REQUESTS=50000 build-asan/tests/server_console_fuzz_test
#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <google/protobuf/descriptor.h>
#include <httplib.h>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <random>

#include "server/console/rpc_gateway.h"
#include "tests/server/server_fixture.h"
#include "tests/testing/model_files.h"

namespace recog::server::testing {
namespace {

using nlohmann::json;
namespace protobuf = google::protobuf;

constexpr char kAdmin[] = "admin-token-0123456789", kReader[] = "reader-token-0123456789",
               kScoped[] = "scoped-token-0123456789";

size_t EnvNumber(const char* name, size_t fallback) {
  const char* value = std::getenv(name);
  return value != nullptr && *value != '\0' ? size_t(std::strtoull(value, nullptr, 10)) : fallback;
}

// A seed of the corpus: the request line's method and target, the header lines, the body.
struct Seed {
  std::string method, target;
  std::vector<std::string> headers;
  std::string body;
};

std::vector<Seed> LoadCorpus() {
  std::vector<std::filesystem::path> files;
  for (const auto& entry : std::filesystem::directory_iterator(
           std::string(RECOG_SOURCE_DIR) + "/tests/server/console_fuzz_corpus")) {
    files.push_back(entry.path());
  }
  std::sort(files.begin(), files.end());
  std::vector<Seed> seeds;
  for (const auto& file : files) {
    std::ifstream in(file, std::ios::binary);
    std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    Seed seed;
    const size_t blank = text.find("\n\n");
    seed.body = blank == std::string::npos ? "" : text.substr(blank + 2);
    std::istringstream head(text.substr(0, blank));
    std::string line;
    std::getline(head, line);
    seed.method = line.substr(0, line.find(' '));
    seed.target = line.substr(line.find(' ') + 1);
    while (std::getline(head, line)) {
      if (!line.empty()) seed.headers.push_back(line);
    }
    seeds.push_back(std::move(seed));
  }
  return seeds;
}

// `bytes` in base64, as protobuf's JSON writes a bytes field.
std::string Base64(const std::string& bytes) {
  pb::Frame frame;
  frame.set_encoded_image(bytes);
  return json::parse(ToJson(frame))["encoded_image"];
}

// Values that have broken parsers before.
const std::vector<std::string>& Interesting() {
  static const std::vector<std::string> values = {
      "%FF",
      "%00",
      "%C3%28",
      "%ED%A0%80",
      "..",
      "%2e%2e%2f",
      "//",
      "\xFF\xFE",
      "\t",
      "\r",
      "\x01",
      "\xC3\xA9",
      "a\nb",
      "-1",
      "0",
      "4294967296",
      "18446744073709551616",
      "99999999999999999999999",
      "1e309",
      "NaN",
      "null",
      "true",
      "[]",
      "{}",
      "\"",
      "\\",
      "\\u0000",
      "\\ud800",
      std::string(5000, 'a'),
      "group:",
      "*",
      "robot-a*",
      "crate",
      "fuzz",
      "iVBORw0KGgoAAAANSUhEUgAATiAAAE4gCAAAAAA=",      // PNG header, 20000 x 20000
      "/9j/4AAQSkZJRgABAQAAAQABAAD/wAALCE4gTiABAREA",  // JPEG header, 20000 x 20000
  };
  return values;
}

// Makes up requests: seeds mutated, and gateway calls of every unary method.
class RequestMaker {
 public:
  RequestMaker(uint64_t seed, std::string host, std::vector<std::string> tokens, std::string jpeg)
      : random_(seed),
        host_(std::move(host)),
        tokens_(std::move(tokens)),
        jpeg_(Base64(jpeg)),
        seeds_(LoadCorpus()) {
    const protobuf::DescriptorPool* pool = protobuf::DescriptorPool::generated_pool();
    for (const char* name : {"recognition.v1.PlaceRecognition", "recognition.v1.ObjectRecognition",
                             "recognition.v1.ObjectRepository", "recognition.v1.Admin"}) {
      const protobuf::ServiceDescriptor* service = pool->FindServiceByName(name);
      for (int i = 0; service != nullptr && i < service->method_count(); ++i) {
        methods_.push_back(service->method(i));
      }
    }
  }

  size_t seeds() const { return seeds_.size(); }

  std::string Next() {
    Seed request = Pick() < 0.25 ? GatewayCall() : seeds_[Index(seeds_.size())];
    const int mutations = int(Index(4));
    for (int i = 0; i < mutations; ++i) Mutate(&request);
    return Assemble(request);
  }

 private:
  double Pick() { return std::uniform_real_distribution<double>(0, 1)(random_); }
  size_t Index(size_t n) { return std::uniform_int_distribution<size_t>(0, n - 1)(random_); }
  const std::string& AnyInteresting() { return Interesting()[Index(Interesting().size())]; }

  std::string AuthorizationLine() {
    if (tokens_.empty() || Pick() < 0.1) return "";
    const std::string token = tokens_[Index(tokens_.size())];
    const double p = Pick();
    if (p < 0.8) return "Authorization: Bearer " + token;
    if (p < 0.9) return "Authorization: Bearer\t" + token;
    return "Authorization: " + AnyInteresting();
  }

  // A JSON value for a field of `field`'s type, right or (sometimes) wrong.
  json Value(const protobuf::FieldDescriptor* field, int depth) {
    if (Pick() < 0.15) return json(AnyInteresting());
    switch (field->cpp_type()) {
      case protobuf::FieldDescriptor::CPPTYPE_MESSAGE:
        return depth > 3 ? json::object() : Message(field->message_type(), depth + 1);
      case protobuf::FieldDescriptor::CPPTYPE_STRING:
        if (field->type() == protobuf::FieldDescriptor::TYPE_BYTES) {
          return Pick() < 0.5 ? jpeg_ : AnyInteresting();
        }
        return Pick() < 0.5 ? std::string("fuzz") : AnyInteresting();
      case protobuf::FieldDescriptor::CPPTYPE_BOOL:
        return Pick() < 0.5;
      case protobuf::FieldDescriptor::CPPTYPE_ENUM:
        return field->enum_type()
            ->value(int(Index(size_t(field->enum_type()->value_count()))))
            ->name();
      case protobuf::FieldDescriptor::CPPTYPE_FLOAT:
      case protobuf::FieldDescriptor::CPPTYPE_DOUBLE:
        return std::uniform_real_distribution<double>(-1e6, 1e6)(random_);
      default:
        return int64_t(std::uniform_int_distribution<int64_t>(-10, 100000)(random_));
    }
  }

  json Message(const protobuf::Descriptor* type, int depth) {
    json message = json::object();
    for (int i = 0; i < type->field_count(); ++i) {
      if (Pick() < 0.5) continue;
      const protobuf::FieldDescriptor* field = type->field(i);
      if (field->is_repeated()) {
        json values = json::array();
        for (size_t n = Index(4); n > 0; --n) values.push_back(Value(field, depth));
        message[field->name()] = values;
      } else {
        message[field->name()] = Value(field, depth);
      }
    }
    return message;
  }

  Seed GatewayCall() {
    const protobuf::MethodDescriptor* method = methods_[Index(methods_.size())];
    Seed call;
    call.method = "POST";
    call.target = "/api/rpc/" + method->service()->full_name() + "/" + method->name();
    call.headers = {"Host: {HOST}", "{AUTH}", "Content-Type: application/json",
                    "Content-Length: {LENGTH}"};
    call.body =
        Message(method->input_type(), 0).dump(-1, ' ', false, json::error_handler_t::replace);
    return call;
  }

  void Mutate(Seed* request) {
    const size_t kind = Index(9);
    std::string& body = request->body;
    switch (kind) {
      case 0: {  // the method
        static const char* const kMethods[] = {"GET",   "POST",    "HEAD",   "PUT", "DELETE",
                                               "PATCH", "OPTIONS", "G\x01T", "",    "TRACE"};
        request->method = kMethods[Index(std::size(kMethods))];
        break;
      }
      case 1: {  // the path: something inserted somewhere
        const size_t at = Index(request->target.size() + 1);
        request->target.insert(at, AnyInteresting());
        break;
      }
      case 2:  // a header added
        request->headers.push_back(std::vector<std::string>{
            "Content-Length: " + AnyInteresting(), "Transfer-Encoding: chunked",
            "Content-Encoding: gzip", "Host: attacker.example", "Origin: http://attacker.example",
            "Origin: null", "Expect: 100-continue", "Content-Type: text/plain",
            "Connection: keep-alive", "X-" + AnyInteresting() + ": " + AnyInteresting(),
            "Range: bytes=0-1,5-" + AnyInteresting()}[Index(11)]);
        break;
      case 3:  // a header dropped or duplicated
        if (!request->headers.empty()) {
          const size_t i = Index(request->headers.size());
          if (Pick() < 0.5) {
            request->headers.erase(request->headers.begin() + long(i));
          } else {
            request->headers.push_back(request->headers[i]);
          }
        }
        break;
      case 4:  // a header's value changed
        if (!request->headers.empty()) {
          std::string& line = request->headers[Index(request->headers.size())];
          line = line.substr(0, line.find(':') + 1) + " " + AnyInteresting();
        }
        break;
      case 5:  // bytes of the body flipped
        for (size_t n = 1 + Index(8); n > 0 && !body.empty(); --n) {
          body[Index(body.size())] = char(Index(256));
        }
        break;
      case 6:  // the body cut
        body.resize(Index(body.size() + 1));
        break;
      case 7: {  // a JSON value replaced
        json parsed = json::parse(body, nullptr, false);
        if (parsed.is_object() && !parsed.empty()) {
          auto it = parsed.begin();
          std::advance(it, long(Index(parsed.size())));
          *it = Pick() < 0.5 ? json(AnyInteresting()) : json::parse("[[[[[[[[[[1]]]]]]]]]]");
          body = parsed.dump(-1, ' ', false, json::error_handler_t::replace);
        }
        break;
      }
      default:  // something inserted into the body
        body.insert(Index(body.size() + 1), AnyInteresting());
        break;
    }
  }

  std::string Assemble(const Seed& request) {
    std::string text = request.method + " " + request.target + " HTTP/1.1\r\n";
    for (std::string line : request.headers) {
      if (line == "{AUTH}") line = AuthorizationLine();
      Replace(&line, "{HOST}", host_);
      if (line == "Content-Length: {LENGTH}") {
        // Mostly the truth; sometimes less, rarely more (the server then waits for its deadline).
        const double p = Pick();
        const size_t length = p < 0.9     ? request.body.size()
                              : p < 0.998 ? request.body.size() / 2
                                          : request.body.size() + 10;
        line = "Content-Length: " + std::to_string(length);
      }
      if (!line.empty()) text += line + "\r\n";
    }
    std::string body = request.body;
    Replace(&body, "{JPEG}", jpeg_);
    return text + "Connection: close\r\n\r\n" + body;
  }

  static void Replace(std::string* text, const std::string& from, const std::string& to) {
    for (size_t at = text->find(from); at != std::string::npos; at = text->find(from, at)) {
      text->replace(at, from.size(), to);
      at += to.size();
    }
  }

  std::mt19937_64 random_;
  std::string host_;
  std::vector<std::string> tokens_;
  std::string jpeg_;  // base64
  std::vector<Seed> seeds_;
  std::vector<const protobuf::MethodDescriptor*> methods_;
};

class ConsoleFuzzTest : public ServerFixture {
 protected:
  ConsoleFuzzTest() {
    config().console.listen = "127.0.0.1:0";
    config().console.request_timeout_ms = 1000;
    config().console.max_connections_per_client = 32;
  }

  // Whether `response` holds a whole answer: its headers and the Content-Length they announce.
  static bool Complete(const std::string& response, bool head) {
    const size_t end = response.find("\r\n\r\n");
    if (end == std::string::npos) return false;
    std::string headers = response.substr(0, end);
    std::transform(headers.begin(), headers.end(), headers.begin(),
                   [](unsigned char c) { return char(std::tolower(c)); });
    const size_t length = headers.find("\r\ncontent-length: ");
    if (head || headers.starts_with("http/1.1 100")) return !headers.starts_with("http/1.1 100");
    if (length == std::string::npos) return false;
    return response.size() - end - 4 >= std::strtoull(headers.c_str() + length + 18, nullptr, 10);
  }

  // Sends `request` on a new connection and reads its answer (until it is whole or the server
  // closes the connection); false when the server could not be reached at all.
  bool Send(const std::string& request, std::string* response) {
    const int fd = socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in address{};
    address.sin_family = AF_INET;
    address.sin_port = htons(uint16_t(server_->console_port()));
    inet_pton(AF_INET, "127.0.0.1", &address.sin_addr);
    if (connect(fd, reinterpret_cast<sockaddr*>(&address), sizeof(address)) != 0) {
      close(fd);
      return false;
    }
    send(fd, request.data(), request.size(), MSG_NOSIGNAL);
    response->clear();
    char buffer[8192];
    const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(5);
    while (std::chrono::steady_clock::now() < until) {
      pollfd entry{fd, POLLIN, 0};
      if (poll(&entry, 1, 200) <= 0) continue;
      const ssize_t n = recv(fd, buffer, sizeof(buffer), 0);
      if (n <= 0) break;
      response->append(buffer, size_t(n));
      if (Complete(*response, request.starts_with("HEAD "))) break;
    }
    close(fd);
    return true;
  }

  // `requests` made-up requests; then both ports answer a real frame.
  void Fuzz(const std::vector<std::string>& tokens, const std::string& token) {
    const size_t requests = EnvNumber("RECOG_CONSOLE_FUZZ_REQUESTS", 5000);
    const uint64_t seed = EnvNumber("RECOG_CONSOLE_FUZZ_SEED", 1);
    ASSERT_TRUE(CreateMap("fuzz", token).ok());
    ASSERT_TRUE(PutModel(recog::testing::ModelFile("crate", {1}, "box"), "crate", token).ok());
    cv::Mat small;
    cv::resize(cv::imread(recog::testing::ProjectTestData("corridor/1.jpg"), cv::IMREAD_GRAYSCALE),
               small, cv::Size(128, 96));
    std::vector<uchar> jpeg;
    cv::imencode(".jpg", small, jpeg);
    RequestMaker maker(seed, "127.0.0.1:" + std::to_string(server_->console_port()), tokens,
                       std::string(jpeg.begin(), jpeg.end()));
    ASSERT_GE(maker.seeds(), 20u);
    size_t answered = 0;
    std::map<std::string, size_t> statuses;
    for (size_t i = 0; i < requests; ++i) {
      const std::string request = maker.Next();
      std::string response;
      ASSERT_TRUE(Send(request, &response))
          << "the console stopped answering at request " << i << " (seed " << seed << "):\n"
          << request;
      answered += response.starts_with("HTTP/1.1 ");
      ++statuses[response.starts_with("HTTP/1.1 ") ? response.substr(9, 3) : "none"];
    }
    std::string summary;
    for (const auto& [status, count] : statuses)
      summary += " " + status + ": " + std::to_string(count);
    std::cout << requests << " requests (seed " << seed << "), answers by status:" << summary
              << "\n";
    // The requests reached the handlers, not only the gate: calls answered and calls refused by
    // the services' own checks.
    EXPECT_GT(statuses["200"], requests / 20);
    EXPECT_GT(statuses["400"] + statuses["404"], requests / 20);
    // Most requests get an answer (the others were closed: cut short, or a TLS-less garbage line).
    EXPECT_GT(answered, requests / 2);
    std::string whoami;
    ASSERT_TRUE(
        Send("GET /api/whoami HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n", &whoami));
    EXPECT_TRUE(whoami.starts_with("HTTP/1.1 200")) << whoami;
    // The fuzzer may have deleted its map: a map of its own for the last frame.
    ASSERT_TRUE(CreateMap("after-fuzz", token).ok());
    const grpc::Status queried = QueryCorridorFrame("after-fuzz", 20, token);
    EXPECT_TRUE(queried.ok()) << queried.error_message();
  }

  grpc::Status CreateMap(const std::string& name, const std::string& token) {
    pb::CreateMapRequest request;
    request.set_name(name);
    request.mutable_settings()->set_keep_thumbnails(true);
    pb::CreateMapResponse response;
    return places_->CreateMap(Context(token).get(), request, &response);
  }
};

TEST_F(ConsoleFuzzTest, RandomRequestsWithoutTokensLeaveTheServerServing) { Fuzz({}, ""); }

TEST_F(ConsoleFuzzTest, RandomRequestsWithTokensLeaveTheServerServing) {
  const std::string tokens = data_dir_.Sub("tokens.yaml");
  std::ofstream(tokens) << "tokens:\n"
                        << "  - name: admin\n    token: " << kAdmin << "\n    rights: [write]\n"
                        << "  - name: reader\n    token: " << kReader << "\n    rights: [read]\n"
                        << "  - name: scoped\n    token: " << kScoped
                        << "\n    rights: [write]\n    maps:\n      write: ['fuzz*']\n";
  StopServer();
  config().token_file = tokens;
  StartServer();
  Fuzz({kAdmin, kReader, kScoped, "not-a-token-0123456789"}, kAdmin);
}

}  // namespace
}  // namespace recog::server::testing
