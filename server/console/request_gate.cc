#include "server/console/request_gate.h"

#include <arpa/inet.h>

#include <algorithm>
#include <cctype>
#include <charconv>

#include <httplib.h>

#include "core/common/text.h"

namespace recog::server {
namespace {

constexpr char kRpcPrefix[] = "/api/rpc/";

std::string Lower(std::string text) {
  std::transform(text.begin(), text.end(), text.begin(),
                 [](unsigned char c) { return char(std::tolower(c)); });
  return text;
}

HttpReply Refusal(int http_status, grpc::StatusCode code, const std::string& message) {
  HttpReply reply = ErrorReply({code, message});
  reply.status = http_status;
  return reply;
}

// The host of a Host header value ("name:port", "[v6]:port", "name"), lower case; nullopt when
// malformed.
std::optional<std::string> HostOf(const std::string& authority) {
  if (authority.empty()) return std::nullopt;
  std::string host;
  if (authority.front() == '[') {
    const size_t close = authority.find(']');
    if (close == std::string::npos) return std::nullopt;
    host = authority.substr(0, close + 1);
    const std::string rest = authority.substr(close + 1);
    if (!rest.empty() && rest.front() != ':') return std::nullopt;
  } else {
    host = authority.substr(0, authority.find(':'));
  }
  return Lower(host);
}

bool IsIpLiteral(const std::string& host) {
  unsigned char address[16];
  if (host.size() > 2 && host.front() == '[' && host.back() == ']') {
    return inet_pton(AF_INET6, host.substr(1, host.size() - 2).c_str(), address) == 1;
  }
  return inet_pton(AF_INET, host.c_str(), address) == 1;
}

}  // namespace

RequestGate::RequestGate(std::vector<std::string> hosts, bool https, size_t max_body_bytes,
                         const TokenAuthenticator* auth)
    : https_(https), max_body_bytes_(max_body_bytes), auth_(auth) {
  for (std::string& host : hosts) hosts_.push_back(Lower(std::move(host)));
}

bool RequestGate::AcceptsHost(const std::string& host) const {
  // A rebinding page reaches the console through a name of its own; an address cannot be rebound.
  return IsIpLiteral(host) || host == "localhost" ||
         std::find(hosts_.begin(), hosts_.end(), host) != hosts_.end();
}

std::optional<HttpReply> RequestGate::Check(const httplib::Request& request) const {
  const std::string authority = request.get_header_value("Host");
  const std::optional<std::string> host = HostOf(authority);
  if (request.get_header_value_count("Host") != 1 || !host.has_value() || !AcceptsHost(*host)) {
    return Refusal(403, grpc::StatusCode::PERMISSION_DENIED,
                   "the console answers to its addresses, localhost and the names of "
                   "console.hosts, not to the Host of this request");
  }
  if (auto refused = CheckOrigin(request)) return refused;
  if (auto refused = CheckBody(request)) return refused;
  if (request.path.starts_with("/api/")) return CheckApi(request);
  return std::nullopt;
}

std::optional<HttpReply> RequestGate::CheckOrigin(const httplib::Request& request) const {
  if (!request.has_header("Origin")) return std::nullopt;  // not sent by a browser's page
  const std::string own =
      std::string(https_ ? "https://" : "http://") + Lower(request.get_header_value("Host"));
  if (Lower(request.get_header_value("Origin")) == own) return std::nullopt;
  return Refusal(403, grpc::StatusCode::PERMISSION_DENIED,
                 "requests from another origin than the console's own are refused");
}

std::optional<HttpReply> RequestGate::CheckBody(const httplib::Request& request) const {
  if (request.method != "GET" && request.method != "HEAD" && request.method != "POST") {
    return Refusal(405, grpc::StatusCode::UNIMPLEMENTED,
                   "the console answers GET, HEAD and POST only");
  }
  if (request.has_header("Transfer-Encoding")) {
    return Refusal(411, grpc::StatusCode::INVALID_ARGUMENT,
                   "chunked bodies are not accepted: send the body with a Content-Length");
  }
  const std::string encoding = Lower(request.get_header_value("Content-Encoding"));
  if (!encoding.empty() && encoding != "identity") {
    return Refusal(415, grpc::StatusCode::INVALID_ARGUMENT,
                   "compressed bodies are not accepted (Content-Encoding)");
  }
  if (request.get_header_value_count("Content-Length") > 1) {
    return Refusal(400, grpc::StatusCode::INVALID_ARGUMENT, "Content-Length is given twice");
  }
  const std::string length_text = request.get_header_value("Content-Length");
  if (request.method == "POST" && length_text.empty()) {
    // cpp-httplib would read such a body until the connection closes.
    return Refusal(411, grpc::StatusCode::INVALID_ARGUMENT,
                   "a POST needs a Content-Length (0 for no body)");
  }
  uint64_t length = 0;
  if (!length_text.empty()) {
    const auto [end, error] =
        std::from_chars(length_text.data(), length_text.data() + length_text.size(), length);
    if (error != std::errc() || end != length_text.data() + length_text.size()) {
      return Refusal(400, grpc::StatusCode::INVALID_ARGUMENT, "Content-Length is not a number");
    }
  }
  if (length > max_body_bytes_) {
    return Refusal(413, grpc::StatusCode::RESOURCE_EXHAUSTED,
                   "the request is larger than the console takes (" +
                       std::to_string(max_body_bytes_) + " bytes)");
  }
  if (length > 0 && !(request.method == "POST" && request.path.starts_with(kRpcPrefix))) {
    return Refusal(400, grpc::StatusCode::INVALID_ARGUMENT, "only POST /api/rpc/... takes a body");
  }
  return std::nullopt;
}

std::optional<HttpReply> RequestGate::CheckApi(const httplib::Request& request) const {
  const std::string authorization = request.get_header_value("Authorization");
  if (!IsPrintableAscii(authorization)) {
    return Refusal(401, grpc::StatusCode::UNAUTHENTICATED,
                   "the Authorization header must be printable ASCII ('Bearer <token>')");
  }
  if (request.method != "POST" || !request.path.starts_with(kRpcPrefix)) return std::nullopt;
  // Only JSON bodies: another site's page can send a form or text/plain to this address without
  // asking, but not application/json (the browser asks first, and the console answers no CORS).
  if (!request.get_header_value("Content-Type").starts_with("application/json")) {
    return Refusal(415, grpc::StatusCode::INVALID_ARGUMENT,
                   "the body must be JSON sent as Content-Type: application/json");
  }
  if (const StatusOr<Caller> caller = auth_->Authenticate(authorization); !caller.ok()) {
    return Refusal(401, grpc::StatusCode::UNAUTHENTICATED, caller.status().message());
  }
  return std::nullopt;
}

}  // namespace recog::server
