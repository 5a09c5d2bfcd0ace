#include "server/console/rpc_gateway.h"

#include <algorithm>
#include <cctype>
#include <future>

#include <unordered_set>

#include <google/protobuf/descriptor.h>
#include <google/protobuf/util/json_util.h>
#include <google/protobuf/util/type_resolver_util.h>
#include <grpcpp/generic/generic_stub.h>
#include <nlohmann/json.hpp>

#include "core/common/text.h"
#include "wire/grpc_code_names.h"

namespace recog::server {
namespace {

namespace protobuf = google::protobuf;

constexpr char kTypeUrlPrefix[] = "type.googleapis.com";
// Protobuf's JSON parser nests no deeper either; no message of the API has as many fields.
constexpr size_t kMaxJsonDepth = 100;
constexpr size_t kMaxKeysPerObject = 1024;

// `bytes` as a gRPC buffer that owns them (no copy).
grpc::ByteBuffer TakeBytes(std::string bytes) {
  auto* owned = new std::string(std::move(bytes));
  grpc::Slice slice(
      owned->data(), owned->size(), [](void* data) { delete static_cast<std::string*>(data); },
      owned);
  return grpc::ByteBuffer(&slice, 1);
}

grpc::ByteBuffer Serialize(const protobuf::Message& message) {
  return TakeBytes(message.SerializeAsString());
}

// A walk through a JSON text that builds nothing: every event is accepted unless overridden.
class JsonWalk : public nlohmann::json_sax<nlohmann::json> {
 public:
  bool null() override { return true; }
  bool boolean(bool) override { return true; }
  bool number_integer(number_integer_t) override { return true; }
  bool number_unsigned(number_unsigned_t) override { return true; }
  bool number_float(number_float_t, const string_t&) override { return true; }
  bool string(string_t&) override { return true; }
  bool binary(binary_t&) override { return true; }
  bool start_object(std::size_t) override { return true; }
  bool key(string_t&) override { return true; }
  bool end_object() override { return true; }
  bool start_array(std::size_t) override { return true; }
  bool end_array() override { return true; }
  bool parse_error(std::size_t, const std::string&, const nlohmann::detail::exception&) override {
    return false;
  }
};

// Reads a JSON text without building it, to refuse what protobuf's parser would let through or
// pay for: an object that names a key twice (the parser keeps one value silently), nesting deeper
// than kMaxJsonDepth, objects of more than kMaxKeysPerObject keys. The keys of the open objects
// are all it keeps.
class JsonKeyCheck final : public JsonWalk {
 public:
  // The problem of `json`, or "" (for a text that is not JSON too: protobuf's parser says so).
  static std::string Problem(std::string_view json) {
    JsonKeyCheck check;
    nlohmann::json::sax_parse(json.begin(), json.end(), &check);
    return check.problem_;
  }

  bool start_object(std::size_t) override {
    open_.emplace_back();
    return Nest();
  }
  bool key(string_t& name) override {
    std::unordered_set<std::string>& keys = open_.back().keys;
    if (keys.size() >= kMaxKeysPerObject) {
      return Fail("an object of the body has more than " + std::to_string(kMaxKeysPerObject) +
                  " keys");
    }
    if (keys.insert(name).second) return true;
    const bool field_like =
        !name.empty() && name.size() <= 64 && std::all_of(name.begin(), name.end(), [](char c) {
          return std::isalnum(static_cast<unsigned char>(c)) || c == '_';
        });
    return Fail(field_like ? "the body names the key '" + name + "' twice in one object"
                           : "the body names a key twice in one object");
  }
  bool end_object() override {
    open_.pop_back();
    --depth_;
    return true;
  }
  bool start_array(std::size_t) override {
    open_.emplace_back();
    return Nest();
  }
  bool end_array() override {
    open_.pop_back();
    --depth_;
    return true;
  }

 private:
  struct Level {
    std::unordered_set<std::string> keys;  // none for an array
  };

  bool Nest() {
    if (++depth_ <= kMaxJsonDepth) return true;
    return Fail("the body nests deeper than " + std::to_string(kMaxJsonDepth) + " levels");
  }
  bool Fail(std::string problem) {
    problem_ = std::move(problem);
    return false;
  }

  std::vector<Level> open_;
  size_t depth_ = 0;
  std::string problem_;
};

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

// A call's error message with what it quotes of the JSON request cut out: the services name what
// they were asked for (a map, a model), and the console's errors never echo the request. Each
// string of the request (value or key) of 4 bytes or more is looked for by its first 16 bytes,
// and a match is cut as far as it goes on like the string. The message is first shortened to
// 1 KiB (its last 16 bytes dropped, so that no short piece of a string is left at its end), and
// a request of more than 4096 such strings gets no message at all: the work stays bounded.
class EchoCut final : public JsonWalk {
 public:
  static std::string Apply(std::string message, std::string_view json) {
    if (message.size() > kMaxMessage) message = message.substr(0, kMaxMessage - kKey) + "...";
    EchoCut cut(&message);
    nlohmann::json::sax_parse(json.begin(), json.end(), &cut);
    if (cut.strings_ > kMaxStrings) return "the call failed (its message is not shown)";
    return message;
  }

  bool string(string_t& text) override { return Cut(text); }
  bool key(string_t& text) override { return Cut(text); }

 private:
  static constexpr size_t kMaxMessage = 1024, kKey = 16, kMinString = 4, kMaxStrings = 4096;

  explicit EchoCut(std::string* message) : message_(message) {}

  bool Cut(const std::string& text) {
    if (text.size() < kMinString) return true;
    if (++strings_ > kMaxStrings) return false;
    const std::string_view key = std::string_view(text).substr(0, kKey);
    std::string& message = *message_;
    for (size_t at = message.find(key); at != std::string::npos; at = message.find(key, at + 3)) {
      size_t length = key.size();
      while (length < text.size() && at + length < message.size() &&
             message[at + length] == text[length]) {
        ++length;
      }
      message.replace(at, length, "...");
    }
    return true;
  }

  std::string* message_;
  size_t strings_ = 0;
};

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

RpcGateway::RpcGateway(std::shared_ptr<grpc::Channel> channel)
    : channel_(std::move(channel)),
      types_(protobuf::util::NewTypeResolverForDescriptorPool(
          kTypeUrlPrefix, protobuf::DescriptorPool::generated_pool())) {}

RpcGateway::~RpcGateway() = default;

grpc::Status RpcGateway::Call(std::string_view method, const protobuf::Message& request,
                              protobuf::Message* response, const std::string& authorization) const {
  return CallBytes(method, Serialize(request), response, authorization);
}

grpc::Status RpcGateway::CallBytes(std::string_view method, const grpc::ByteBuffer& sent,
                                   protobuf::Message* response,
                                   const std::string& authorization) const {
  // gRPC aborts the process on metadata it cannot send (a tab, a byte beyond ASCII).
  if (!IsPrintableAscii(authorization)) {
    return {grpc::StatusCode::UNAUTHENTICATED,
            "the Authorization header must be printable ASCII ('Bearer <token>')"};
  }
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + kDeadline);
  if (!authorization.empty()) context.AddMetadata("authorization", authorization);
  grpc::GenericStub stub(channel_);
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
    return ErrorReply({grpc::StatusCode::NOT_FOUND,
                       "no unary method of the API has this name (package.Service/Method)"});
  }
  const std::string& type = descriptor->input_type()->full_name();
  if (body.empty()) body = "{}";  // every field at its default
  if (const std::string problem = JsonKeyCheck::Problem(body); !problem.empty()) {
    return ErrorReply({grpc::StatusCode::INVALID_ARGUMENT, problem});
  }
  std::string bytes;
  const protobuf::util::Status parsed =
      protobuf::util::JsonToBinaryString(types_.get(), std::string(kTypeUrlPrefix) + "/" + type,
                                         protobuf::StringPiece(body.data(), body.size()), &bytes);
  if (!parsed.ok()) {
    // Protobuf's message quotes the body: it is not sent back.
    return ErrorReply({grpc::StatusCode::INVALID_ARGUMENT,
                       "the body is not a " + type +
                           " as JSON (malformed JSON, a field the message does not have, or a "
                           "value of the wrong type)"});
  }
  std::unique_ptr<protobuf::Message> response = NewMessage(descriptor->output_type());
  const grpc::Status status =
      CallBytes(method, TakeBytes(std::move(bytes)), response.get(), authorization);
  if (!status.ok()) {
    return ErrorReply({status.error_code(), EchoCut::Apply(status.error_message(), body)});
  }
  return {200, "application/json", ToJson(*response)};
}

}  // namespace recog::server
