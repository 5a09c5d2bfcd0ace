#include "server/console/request_gate.h"

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

// Whether `content_type` is application/json, with parameters (charset) or none.
bool IsJsonType(const std::string& content_type) {
  const std::string type = Lower(content_type.substr(0, content_type.find(';')));
  const size_t first = type.find_first_not_of(" \t"), last = type.find_last_not_of(" \t");
  return first != std::string::npos && type.substr(first, last - first + 1) == "application/json";
}

}  // namespace

RequestGate::RequestGate(const std::vector<std::string>& hosts, bool https, size_t max_body_bytes,
                         const TokenAuthenticator* auth)
    : hosts_(hosts), https_(https), max_body_bytes_(max_body_bytes), auth_(auth) {}

std::optional<HttpReply> RequestGate::Check(const httplib::Request& request) const {
  if (request.get_header_value_count("Host") != 1 ||
      !hosts_.AcceptsHeader(request.get_header_value("Host"))) {
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
  if (!IsJsonType(request.get_header_value("Content-Type"))) {
    return Refusal(415, grpc::StatusCode::INVALID_ARGUMENT,
                   "the body must be JSON sent as Content-Type: application/json");
  }
  if (const StatusOr<Caller> caller = auth_->Authenticate(authorization); !caller.ok()) {
    return Refusal(401, grpc::StatusCode::UNAUTHENTICATED, caller.status().message());
  }
  return std::nullopt;
}

}  // namespace recog::server
