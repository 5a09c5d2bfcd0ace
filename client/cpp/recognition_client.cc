#include "client/cpp/recognition_client.h"

#include <algorithm>
#include <chrono>
#include <fstream>
#include <sstream>
#include <thread>

#include <spdlog/spdlog.h>

#include "client/cpp/retry.h"
#include "wire/routing.h"

namespace recog::client {
namespace {

using internal::CallKind;

// The whole content of a small file (certificates, keys, tokens).
Result<std::string> ReadSmallFile(const std::string& what, const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in)
    return grpc::Status(grpc::StatusCode::NOT_FOUND, "cannot open " + what + " '" + path + "'");
  std::ostringstream content;
  content << in.rdbuf();
  if (in.bad()) {
    return grpc::Status(grpc::StatusCode::NOT_FOUND, "cannot read " + what + " '" + path + "'");
  }
  return std::move(content).str();
}

// The token in a token file: its content without leading and trailing whitespace.
Result<std::string> ReadTokenFile(const std::string& path) {
  Result<std::string> content = ReadSmallFile("token file", path);
  if (!content.ok()) return content.status();
  const std::string& text = *content;
  constexpr char kSpace[] = " \t\r\n\f\v";
  const size_t first = text.find_first_not_of(kSpace);
  if (first == std::string::npos) {
    return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, "token file '" + path + "' is empty");
  }
  std::string token = text.substr(first, text.find_last_not_of(kSpace) - first + 1);
  for (char c : token) {
    if (c <= ' ' || c >= 127) {
      return grpc::Status(
          grpc::StatusCode::INVALID_ARGUMENT,
          "token file '" + path + "' must hold one token of visible ASCII characters");
    }
  }
  return token;
}

Result<std::shared_ptr<grpc::ChannelCredentials>> Credentials(const TlsOptions& tls) {
  if (!tls.enabled) return grpc::InsecureChannelCredentials();
  grpc::SslCredentialsOptions ssl;
  const std::pair<const std::string*, std::string*> files[] = {
      {&tls.ca_file, &ssl.pem_root_certs},
      {&tls.cert_file, &ssl.pem_cert_chain},
      {&tls.key_file, &ssl.pem_private_key}};
  for (const auto& [path, pem] : files) {
    if (path->empty()) continue;
    Result<std::string> content = ReadSmallFile("TLS file", *path);
    if (!content.ok()) return content.status();
    *pem = std::move(content).value();
  }
  return grpc::SslCredentials(ssl);
}

// One attempt of a unary call: clears the response, then calls `method`.
template <class Stub, class Request, class Response>
std::function<grpc::Status(grpc::ClientContext&)> UnaryAttempt(
    Stub* stub, grpc::Status (Stub::*method)(grpc::ClientContext*, const Request&, Response*),
    const Request& request, Response* response) {
  return [stub, method, &request, response](grpc::ClientContext& context) {
    response->Clear();
    return (stub->*method)(&context, request, response);
  };
}

// The attempt of a call about place map `map`: the routing header first (wire/routing.h).
std::function<grpc::Status(grpc::ClientContext&)> ForMap(
    const std::string& map, std::function<grpc::Status(grpc::ClientContext&)> attempt) {
  return [map, attempt = std::move(attempt)](grpc::ClientContext& context) {
    context.AddMetadata(kMapHeader, map);
    return attempt(context);
  };
}

}  // namespace

Result<std::unique_ptr<RecognitionClient>> RecognitionClient::Connect(
    const ClientOptions& options) {
  if (grpc::Status status = options.Validate(); !status.ok()) return status;
  std::string token = options.token;
  if (!options.token_file.empty()) {
    Result<std::string> read = ReadTokenFile(options.token_file);
    if (!read.ok()) return read.status();
    token = std::move(read).value();
  }
  Result<std::shared_ptr<grpc::ChannelCredentials>> credentials = Credentials(options.tls);
  if (!credentials.ok()) return credentials.status();

  grpc::ChannelArguments args;
  args.SetMaxReceiveMessageSize(int(options.max_message_bytes));
  args.SetMaxSendMessageSize(int(options.max_message_bytes));
  // gRPC reconnects a broken channel at the pace of the retry policy, so that a retry after a
  // server restart finds the channel connected again. (GRPC_ARG_MIN_RECONNECT_BACKOFF_MS is left
  // at its default: gRPC also uses it as the connect timeout, and a short one fails whenever the
  // process is busy when the connection is made.)
  args.SetInt(GRPC_ARG_INITIAL_RECONNECT_BACKOFF_MS, int(options.retry.initial_backoff.count()));
  args.SetInt(GRPC_ARG_MAX_RECONNECT_BACKOFF_MS, int(options.retry.max_backoff.count()));
  std::shared_ptr<grpc::Channel> channel =
      grpc::CreateCustomChannel(options.target, *credentials, args);
  channel->GetState(/*try_to_connect=*/true);
  return std::unique_ptr<RecognitionClient>(
      new RecognitionClient(options, std::move(token), std::move(channel)));
}

RecognitionClient::RecognitionClient(const ClientOptions& options, std::string token,
                                     std::shared_ptr<grpc::Channel> channel)
    : options_(options),
      token_(std::move(token)),
      channel_(std::move(channel)),
      places_(pb::PlaceRecognition::NewStub(channel_)),
      objects_(pb::ObjectRecognition::NewStub(channel_)),
      models_(pb::ObjectRepository::NewStub(channel_)),
      admin_(pb::Admin::NewStub(channel_)),
      health_(grpc::health::v1::Health::NewStub(channel_)) {}

RecognitionClient::~RecognitionClient() = default;

void RecognitionClient::PrepareContext(grpc::ClientContext& context,
                                       const Deadline* deadline) const {
  if (deadline != nullptr) context.set_deadline(*deadline);
  if (!token_.empty()) context.AddMetadata("authorization", "Bearer " + token_);
  if (!options_.shard.empty()) context.AddMetadata(kShardHeader, options_.shard);
}

RecognitionClient::Deadline RecognitionClient::UnaryDeadline() const {
  return std::chrono::system_clock::now() + options_.deadline;
}

grpc::Status RecognitionClient::WaitForConnection(Deadline deadline) const {
  grpc_connectivity_state state = channel_->GetState(/*try_to_connect=*/true);
  while (state != GRPC_CHANNEL_READY) {
    if (state == GRPC_CHANNEL_SHUTDOWN) {
      return {grpc::StatusCode::UNAVAILABLE, "cannot connect to " + options_.target};
    }
    if (state == GRPC_CHANNEL_TRANSIENT_FAILURE) {
      // gRPC tries again after its reconnect backoff: give it up to one retry backoff to get
      // out of the failure; if it does not, nothing was sent and the caller may retry.
      const Deadline slice =
          std::min(deadline, std::chrono::system_clock::now() + options_.retry.max_backoff);
      if (!channel_->WaitForStateChange(state, slice)) {
        return {grpc::StatusCode::UNAVAILABLE, "cannot connect to " + options_.target};
      }
      state = channel_->GetState(/*try_to_connect=*/true);
      continue;
    }
    if (!channel_->WaitForStateChange(state, deadline)) {
      return {grpc::StatusCode::DEADLINE_EXCEEDED,
              "no connection to " + options_.target + " before the deadline"};
    }
    state = channel_->GetState(/*try_to_connect=*/true);
  }
  return grpc::Status::OK;
}

bool RecognitionClient::Backoff(int retry, std::optional<std::chrono::milliseconds> retry_after,
                                Deadline deadline) const {
  const std::chrono::milliseconds delay =
      internal::RetryDelay(options_.retry, retry, internal::UnitRandom(), retry_after);
  if (std::chrono::system_clock::now() + delay >= deadline) return false;
  std::this_thread::sleep_for(delay);
  return true;
}

grpc::Status RecognitionClient::Run(CallKind kind, Deadline deadline,
                                    const Attempt& attempt) const {
  for (int number = 1;; ++number) {
    grpc::ClientContext context;
    PrepareContext(context, &deadline);
    // A changing call is sent only over a connected channel, so that a failure to connect is
    // known to have sent nothing.
    grpc::Status status =
        kind == CallKind::kChanging ? WaitForConnection(deadline) : grpc::Status::OK;
    const bool sent = status.ok();
    if (sent) status = attempt(context);
    if (status.ok()) return status;
    const std::optional<std::chrono::milliseconds> retry_after =
        sent ? internal::RetryAfter(context) : std::nullopt;
    if (!internal::ShouldRetry(status, kind, sent, retry_after) ||
        number >= options_.retry.max_attempts || !Backoff(number, retry_after, deadline)) {
      return status;
    }
    spdlog::debug("recog client: attempt {} failed with {} ({}); retrying", number,
                  int(status.error_code()), status.error_message());
  }
}

// --- Place maps ---

Result<pb::MapInfo> RecognitionClient::CreateMap(const std::string& name,
                                                 const pb::MapSettings& settings) {
  pb::CreateMapRequest request;
  request.set_name(name);
  *request.mutable_settings() = settings;
  pb::CreateMapResponse response;
  const grpc::Status status =
      Run(CallKind::kChanging, UnaryDeadline(),
          ForMap(request.name(), UnaryAttempt(places_.get(), &pb::PlaceRecognition::Stub::CreateMap,
                                              request, &response)));
  if (!status.ok()) return status;
  return std::move(*response.mutable_map());
}

Result<pb::MapInfo> RecognitionClient::GetMap(const std::string& name) {
  pb::GetMapRequest request;
  request.set_name(name);
  pb::GetMapResponse response;
  const grpc::Status status = Run(
      CallKind::kRepeatable, UnaryDeadline(),
      ForMap(request.name(),
             UnaryAttempt(places_.get(), &pb::PlaceRecognition::Stub::GetMap, request, &response)));
  if (!status.ok()) return status;
  return std::move(*response.mutable_map());
}

Result<std::vector<pb::MapInfo>> RecognitionClient::ListMaps() {
  std::vector<pb::MapInfo> maps;
  pb::ListMapsRequest request;
  pb::ListMapsResponse response;
  do {
    const grpc::Status status =
        Run(CallKind::kRepeatable, UnaryDeadline(),
            UnaryAttempt(places_.get(), &pb::PlaceRecognition::Stub::ListMaps, request, &response));
    if (!status.ok()) return status;
    for (pb::MapInfo& map : *response.mutable_maps()) maps.push_back(std::move(map));
    request.set_page_token(response.next_page_token());
  } while (!request.page_token().empty());
  return maps;
}

Result<uint64_t> RecognitionClient::DeleteMap(const std::string& name) {
  pb::DeleteMapRequest request;
  request.set_name(name);
  pb::DeleteMapResponse response;
  const grpc::Status status =
      Run(CallKind::kChanging, UnaryDeadline(),
          ForMap(request.name(), UnaryAttempt(places_.get(), &pb::PlaceRecognition::Stub::DeleteMap,
                                              request, &response)));
  if (!status.ok()) return status;
  return response.frames_deleted();
}

Result<pb::AddFrameResponse> RecognitionClient::AddFrame(const std::string& map,
                                                         const pb::Frame& frame) {
  pb::AddFrameRequest request;
  request.set_map(map);
  *request.mutable_frame() = frame;
  pb::AddFrameResponse response;
  const grpc::Status status =
      Run(CallKind::kChanging, UnaryDeadline(),
          ForMap(request.map(), UnaryAttempt(places_.get(), &pb::PlaceRecognition::Stub::AddFrame,
                                             request, &response)));
  if (!status.ok()) return status;
  return response;
}

Result<pb::QueryPlaceResponse> RecognitionClient::QueryPlace(
    const std::string& map, const pb::Frame& frame, QueryMode mode,
    const pb::ResultOptions& result_options) {
  pb::QueryPlaceRequest request;
  request.set_map(map);
  *request.mutable_frame() = frame;
  request.set_add_frame(mode == QueryMode::kAddFrame);
  *request.mutable_options() = result_options;
  pb::QueryPlaceResponse response;
  const grpc::Status status = Run(
      mode == QueryMode::kAddFrame ? CallKind::kChanging : CallKind::kRepeatable, UnaryDeadline(),
      ForMap(request.map(), UnaryAttempt(places_.get(), &pb::PlaceRecognition::Stub::QueryPlace,
                                         request, &response)));
  if (!status.ok()) return status;
  return response;
}

Result<std::vector<uint64_t>> RecognitionClient::RemoveFrame(const std::string& map,
                                                             uint64_t frame_id) {
  pb::RemoveFrameRequest request;
  request.set_map(map);
  request.set_frame_id(frame_id);
  return RemoveFrames(request);
}

Result<std::vector<uint64_t>> RecognitionClient::RemoveFramesByClientId(
    const std::string& map, const std::string& client_frame_id) {
  pb::RemoveFrameRequest request;
  request.set_map(map);
  request.set_client_frame_id(client_frame_id);
  return RemoveFrames(request);
}

Result<std::vector<uint64_t>> RecognitionClient::RemoveFrames(
    const pb::RemoveFrameRequest& request) {
  pb::RemoveFrameResponse response;
  const grpc::Status status = Run(
      CallKind::kChanging, UnaryDeadline(),
      ForMap(request.map(), UnaryAttempt(places_.get(), &pb::PlaceRecognition::Stub::RemoveFrame,
                                         request, &response)));
  if (!status.ok()) return status;
  return std::vector<uint64_t>(response.removed_frame_ids().begin(),
                               response.removed_frame_ids().end());
}

// --- Objects ---

Result<pb::RecognizeObjectsResponse> RecognitionClient::RecognizeObjects(
    const pb::Frame& frame, const pb::ObjectFilter& filter,
    const pb::DetectionOptions& detection_options) {
  pb::RecognizeObjectsRequest request;
  *request.mutable_frame() = frame;
  *request.mutable_filter() = filter;
  *request.mutable_detection_options() = detection_options;
  pb::RecognizeObjectsResponse response;
  const grpc::Status status =
      Run(CallKind::kRepeatable, UnaryDeadline(),
          UnaryAttempt(objects_.get(), &pb::ObjectRecognition::Stub::RecognizeObjects, request,
                       &response));
  if (!status.ok()) return status;
  return response;
}

}  // namespace recog::client
