// RpcGateway: the console's HTTP/JSON face of recogd's unary RPCs.
//
// POST /api/rpc/<package.Service>/<Method> carries the request message as JSON (protobuf's JSON
// mapping; field names as in the .proto files); the gateway parses it into the method's request
// type, calls the method on the server's own services through an in-process gRPC channel (so
// authentication, readiness, the worker pool, metrics and the log line are exactly those of a
// gRPC client's call: there is no second implementation), and prints the response as JSON with
// the proto field names and every field. The caller's `Authorization` header goes with the call
// as its metadata. Streaming methods are not served (NOT_FOUND). Thread-safe.
//
// The JSON is turned into the request's wire bytes directly (no message is built on this side)
// and those bytes go to the channel without a copy: a body of N bytes costs about 3N besides
// itself while it is checked, decoded and called, the service's copy of the request included. An
// object that names a key twice (protobuf's parser would keep one value silently) is refused,
// naming the key. Error messages name no part of the request: not the method asked for, not what
// the body held (beyond a key that is a field-like name).
#pragma once

#include <chrono>
#include <memory>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include <google/protobuf/message.h>
#include <google/protobuf/util/type_resolver.h>
#include <grpcpp/grpcpp.h>
#include <nlohmann/json_fwd.hpp>

namespace recog::server {

// What an HTTP handler answers.
struct HttpReply {
  int status = 200;
  std::string content_type = "application/json";
  std::string body;
  std::vector<std::pair<std::string, std::string>> headers = {};  // beside Content-Type
};

// `json` as text. Strings that are not UTF-8 (a path or a name a client sent) have their bad bytes
// replaced by U+FFFD instead of making the dump throw.
std::string JsonText(const nlohmann::json& json);

// {"code": "NOT_FOUND", "message": "..."} with the HTTP status of the gRPC code (HttpStatusOf).
HttpReply ErrorReply(const grpc::Status& status);
// 400 for INVALID_ARGUMENT and OUT_OF_RANGE, 401, 403, 404, 409 for ALREADY_EXISTS and ABORTED,
// 412 FAILED_PRECONDITION, 429 RESOURCE_EXHAUSTED, 499 CANCELLED, 503 UNAVAILABLE, 504
// DEADLINE_EXCEEDED, 501 UNIMPLEMENTED, 500 otherwise.
int HttpStatusOf(grpc::StatusCode code);

// A message as the console's JSON (proto field names, default values printed).
std::string ToJson(const google::protobuf::Message& message);

class RpcGateway {
 public:
  static constexpr std::chrono::seconds kDeadline{60};

  explicit RpcGateway(std::shared_ptr<grpc::Channel> channel);
  ~RpcGateway();

  // Calls `method` ("recognition.v1.PlaceRecognition/ListMaps") with the JSON `body`, as the
  // caller of `authorization` (the HTTP header's value, "" for none). The caller bounds the
  // body's size (and the bodies decoded at once: ByteBudget).
  HttpReply Call(std::string_view method, std::string_view body,
                 const std::string& authorization) const;

  // The same with a request message already built; `response` must be of the method's response
  // type. For the console's own views, which start from an RPC's answer.
  grpc::Status Call(std::string_view method, const google::protobuf::Message& request,
                    google::protobuf::Message* response, const std::string& authorization) const;

 private:
  // The call with its request already in wire bytes.
  grpc::Status CallBytes(std::string_view method, const grpc::ByteBuffer& request,
                         google::protobuf::Message* response,
                         const std::string& authorization) const;

  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<google::protobuf::util::TypeResolver> types_;  // of the generated messages
};

}  // namespace recog::server
