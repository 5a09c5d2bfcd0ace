#include "server/console/rpc_gateway.h"

#include <future>

#include <google/protobuf/descriptor.h>
#include <google/protobuf/util/json_util.h>
#include <grpcpp/generic/generic_stub.h>
#include <nlohmann/json.hpp>

#include "core/common/text.h"
#include "wire/grpc_code_names.h"

namespace recog::server {
namespace {

namespace protobuf = google::protobuf;

grpc::ByteBuffer Serialize(const protobuf::Message& message) {
  const std::string bytes = message.SerializeAsString();
  grpc::Slice slice(bytes);
  return grpc::ByteBuffer(&slice, 1);
}

bool Parse(const grpc::ByteBuffer& buffer, protobuf::Message* message) {
  std::vector<grpc::Slice> slices;
  if (!buffer.Dump(&slices).ok()) return false;
  std::string bytes;
  for (const grpc::Slice& slice : slices) {
    bytes.append(reinterpret_cast<const char*>(slice.begin()), slice.size());
  }
  return message->ParseFromString(bytes);
}

// The unary method "package.Service/Method", or null.
const protobuf::MethodDescriptor* FindUnaryMethod(std::string_view method) {
  const size_t slash = method.find('/');
  if (slash == std::string_view::npos) return nullptr;
  std::string dotted(method);
  dotted[slash] = '.';
  const protobuf::MethodDescriptor* found =
      protobuf::DescriptorPool::generated_pool()->FindMethodByName(dotted);
  if (found == nullptr || found->client_streaming() || found->server_streaming()) return nullptr;
  return found;
}

std::unique_ptr<protobuf::Message> NewMessage(const protobuf::Descriptor* type) {
  return std::unique_ptr<protobuf::Message>(
      protobuf::MessageFactory::generated_factory()->GetPrototype(type)->New());
}

}  // namespace

int HttpStatusOf(grpc::StatusCode code) {
  switch (code) {
    case grpc::StatusCode::OK:
      return 200;
    case grpc::StatusCode::INVALID_ARGUMENT:
    case grpc::StatusCode::OUT_OF_RANGE:
      return 400;
    case grpc::StatusCode::UNAUTHENTICATED:
      return 401;
    case grpc::StatusCode::PERMISSION_DENIED:
      return 403;
    case grpc::StatusCode::NOT_FOUND:
      return 404;
    case grpc::StatusCode::ALREADY_EXISTS:
    case grpc::StatusCode::ABORTED:
      return 409;
    case grpc::StatusCode::FAILED_PRECONDITION:
      return 412;
    case grpc::StatusCode::RESOURCE_EXHAUSTED:
      return 429;
    case grpc::StatusCode::CANCELLED:
      return 499;
    case grpc::StatusCode::UNIMPLEMENTED:
      return 501;
    case grpc::StatusCode::UNAVAILABLE:
      return 503;
    case grpc::StatusCode::DEADLINE_EXCEEDED:
      return 504;
    default:
      return 500;
  }
}

std::string JsonText(const nlohmann::json& json) {
  return json.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
}

HttpReply ErrorReply(const grpc::Status& status) {
  const nlohmann::json body = {{"code", std::string(GrpcCodeName(status.error_code()))},
                               {"message", status.error_message()}};
  return {HttpStatusOf(status.error_code()), "application/json", JsonText(body)};
}

std::string ToJson(const protobuf::Message& message) {
  protobuf::util::JsonPrintOptions options;
  options.preserve_proto_field_names = true;
  options.always_print_primitive_fields = true;
  std::string json;
  const protobuf::util::Status printed =
      protobuf::util::MessageToJsonString(message, &json, options);
  return printed.ok() ? json : std::string("{}");
}

RpcGateway::RpcGateway(std::shared_ptr<grpc::Channel> channel) : channel_(std::move(channel)) {}

grpc::Status RpcGateway::Call(std::string_view method, const protobuf::Message& request,
                              protobuf::Message* response, const std::string& authorization) const {
  // gRPC aborts the process on metadata it cannot send (a tab, a byte beyond ASCII).
  if (!IsPrintableAscii(authorization)) {
    return {grpc::StatusCode::UNAUTHENTICATED,
            "the Authorization header must be printable ASCII ('Bearer <token>')"};
  }
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + kDeadline);
  if (!authorization.empty()) context.AddMetadata("authorization", authorization);
  grpc::GenericStub stub(channel_);
  const grpc::ByteBuffer sent = Serialize(request);
  grpc::ByteBuffer received;
  std::promise<grpc::Status> done;
  std::string path = "/";
  path += method;
  stub.UnaryCall(&context, path, grpc::StubOptions(), &sent, &received,
                 [&done](grpc::Status status) { done.set_value(std::move(status)); });
  grpc::Status status = done.get_future().get();
  if (status.ok() && !Parse(received, response)) {
    std::string message = "the answer of ";
    message += method;
    message += " is malformed";
    return {grpc::StatusCode::INTERNAL, message};
  }
  return status;
}

HttpReply RpcGateway::Call(std::string_view method, std::string_view body,
                           const std::string& authorization) const {
  const protobuf::MethodDescriptor* descriptor = FindUnaryMethod(method);
  if (descriptor == nullptr) {
    std::string message = "'";
    message += method;
    message += "' is not a unary method of the API (package.Service/Method)";
    return ErrorReply({grpc::StatusCode::NOT_FOUND, message});
  }
  std::unique_ptr<protobuf::Message> request = NewMessage(descriptor->input_type());
  std::unique_ptr<protobuf::Message> response = NewMessage(descriptor->output_type());
  if (body.empty()) body = "{}";  // every field at its default
  const protobuf::util::Status parsed = protobuf::util::JsonStringToMessage(
      protobuf::StringPiece(body.data(), body.size()), request.get());
  if (!parsed.ok()) {
    std::string message = "the body is not a ";
    message += descriptor->input_type()->full_name();
    message += " as JSON: ";
    message += std::string(parsed.message());
    return ErrorReply({grpc::StatusCode::INVALID_ARGUMENT, message});
  }
  const grpc::Status status = Call(method, *request, response.get(), authorization);
  if (!status.ok()) return ErrorReply(status);
  return {200, "application/json", ToJson(*response)};
}

}  // namespace recog::server
