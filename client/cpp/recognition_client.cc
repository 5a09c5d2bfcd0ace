#include "client/cpp/recognition_client.h"

#include <chrono>
#include <fstream>
#include <sstream>

#include "client/cpp/request_id.h"
#include "client/cpp/service_config.h"
#include "wire/routing.h"

namespace recog::client {
namespace {

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
  // gRPC's retries by the one policy (proto/service_config.json, compiled in). Retries are on by
  // default in Debian 12's gRPC 1.51 too; the switch is set anyway, both ways.
  args.SetServiceConfigJSON(internal::kServiceConfigJson);
  args.SetInt(GRPC_ARG_ENABLE_RETRIES, options.retries ? 1 : 0);
  // gRPC keeps a call's messages for its retries until the first answer, up to this many bytes
  // (default 256 KiB); beyond, the call is committed and not retried. Any message may be retried.
  args.SetInt(GRPC_ARG_PER_RPC_RETRY_BUFFER_SIZE, int(options.max_message_bytes));
  // gRPC reconnects a broken channel at the pace of the retry policy, so that a retry after a
  // server restart finds the channel connected again. (GRPC_ARG_MIN_RECONNECT_BACKOFF_MS is left
  // at its default: gRPC also uses it as the connect timeout, and a short one fails whenever the
  // process is busy when the connection is made.)
  args.SetInt(GRPC_ARG_INITIAL_RECONNECT_BACKOFF_MS, internal::kInitialBackoffMs);
  args.SetInt(GRPC_ARG_MAX_RECONNECT_BACKOFF_MS, internal::kMaxBackoffMs);
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

std::unique_ptr<grpc::ClientContext> RecognitionClient::UnaryContext(const std::string* map) const {
  auto context = std::make_unique<grpc::ClientContext>();
  const Deadline deadline = std::chrono::system_clock::now() + options_.deadline;
  PrepareContext(*context, &deadline);
  if (map != nullptr) context->AddMetadata(kMapHeader, *map);
  return context;
}

bool RecognitionClient::Resumable(const grpc::Status& status) {
  return status.error_code() == grpc::StatusCode::UNAVAILABLE;
}

// --- Place maps ---

Result<pb::MapInfo> RecognitionClient::CreateMap(const std::string& name,
                                                 const pb::MapSettings& settings,
                                                 const std::string& request_id) {
  pb::CreateMapRequest request;
  request.set_name(name);
  *request.mutable_settings() = settings;
  request.set_request_id(internal::RequestIdOr(request_id));
  pb::CreateMapResponse response;
  const grpc::Status status = places_->CreateMap(UnaryContext(&name).get(), request, &response);
  if (!status.ok()) return status;
  return std::move(*response.mutable_map());
}

Result<pb::MapInfo> RecognitionClient::GetMap(const std::string& name) {
  pb::GetMapRequest request;
  request.set_name(name);
  pb::GetMapResponse response;
  const grpc::Status status = places_->GetMap(UnaryContext(&name).get(), request, &response);
  if (!status.ok()) return status;
  return std::move(*response.mutable_map());
}

Result<std::vector<pb::MapInfo>> RecognitionClient::ListMaps() {
  std::vector<pb::MapInfo> maps;
  pb::ListMapsRequest request;
  pb::ListMapsResponse response;
  do {
    response.Clear();
    const grpc::Status status = places_->ListMaps(UnaryContext().get(), request, &response);
    if (!status.ok()) return status;
    for (pb::MapInfo& map : *response.mutable_maps()) maps.push_back(std::move(map));
    request.set_page_token(response.next_page_token());
  } while (!request.page_token().empty());
  return maps;
}

Result<uint64_t> RecognitionClient::DeleteMap(const std::string& name,
                                              const std::string& request_id) {
  pb::DeleteMapRequest request;
  request.set_name(name);
  request.set_request_id(internal::RequestIdOr(request_id));
  pb::DeleteMapResponse response;
  const grpc::Status status = places_->DeleteMap(UnaryContext(&name).get(), request, &response);
  if (!status.ok()) return status;
  return response.frames_deleted();
}

Result<pb::AddFrameResponse> RecognitionClient::AddFrame(const std::string& map,
                                                         const pb::Frame& frame,
                                                         const std::string& request_id) {
  pb::AddFrameRequest request;
  request.set_map(map);
  *request.mutable_frame() = frame;
  request.set_request_id(internal::RequestIdOr(request_id));
  pb::AddFrameResponse response;
  const grpc::Status status = places_->AddFrame(UnaryContext(&map).get(), request, &response);
  if (!status.ok()) return status;
  return response;
}

Result<pb::QueryPlaceResponse> RecognitionClient::QueryPlace(
    const std::string& map, const pb::Frame& frame, QueryMode mode,
    const pb::ResultOptions& result_options, const std::string& request_id,
    const SearchSet& search) {
  pb::QueryPlaceRequest request;
  request.set_map(map);
  for (const std::string& name : search.maps) request.add_search_maps(name);
  request.set_search_group(search.group);
  *request.mutable_frame() = frame;
  request.set_add_frame(mode == QueryMode::kAddFrame);
  *request.mutable_options() = result_options;
  if (mode == QueryMode::kAddFrame) request.set_request_id(internal::RequestIdOr(request_id));
  pb::QueryPlaceResponse response;
  const grpc::Status status = places_->QueryPlace(UnaryContext(&map).get(), request, &response);
  if (!status.ok()) return status;
  return response;
}

Result<pb::RelocalizeResponse> RecognitionClient::Relocalize(
    const std::vector<pb::Frame>& frames, const SearchSet& search,
    const pb::ResultOptions& result_options, uint32_t max_results) {
  pb::RelocalizeRequest request;
  for (const pb::Frame& frame : frames) *request.add_frames() = frame;
  for (const std::string& name : search.maps) request.add_maps(name);
  request.set_group(search.group);
  *request.mutable_options() = result_options;
  request.set_max_results(max_results);
  pb::RelocalizeResponse response;
  // A router sends the call to the shard of its first map, or of its group (`group:NAME` in the
  // placement table).
  const std::string routed_by = !search.maps.empty()   ? search.maps.front()
                                : search.group.empty() ? std::string()
                                                       : "group:" + search.group;
  const grpc::Status status = places_->Relocalize(
      UnaryContext(routed_by.empty() ? nullptr : &routed_by).get(), request, &response);
  if (!status.ok()) return status;
  return response;
}

Result<std::vector<uint64_t>> RecognitionClient::RemoveFrame(const std::string& map,
                                                             uint64_t frame_id,
                                                             const std::string& request_id) {
  pb::RemoveFrameRequest request;
  request.set_map(map);
  request.set_frame_id(frame_id);
  return RemoveFrames(std::move(request), request_id);
}

Result<std::vector<uint64_t>> RecognitionClient::RemoveFramesByClientId(
    const std::string& map, const std::string& client_frame_id, const std::string& request_id) {
  pb::RemoveFrameRequest request;
  request.set_map(map);
  request.set_client_frame_id(client_frame_id);
  return RemoveFrames(std::move(request), request_id);
}

Result<std::vector<uint64_t>> RecognitionClient::RemoveFrames(pb::RemoveFrameRequest request,
                                                              const std::string& request_id) {
  request.set_request_id(internal::RequestIdOr(request_id));
  pb::RemoveFrameResponse response;
  const grpc::Status status =
      places_->RemoveFrame(UnaryContext(&request.map()).get(), request, &response);
  if (!status.ok()) return status;
  return std::vector<uint64_t>(response.removed_frame_ids().begin(),
                               response.removed_frame_ids().end());
}

// --- Objects ---

Result<pb::RecognizeObjectsResponse> RecognitionClient::RecognizeObjects(
    const pb::Frame& frame, const pb::ObjectFilter& filter,
    const pb::DetectionOptions& detection_options, bool explain) {
  pb::RecognizeObjectsRequest request;
  *request.mutable_frame() = frame;
  *request.mutable_filter() = filter;
  *request.mutable_detection_options() = detection_options;
  request.set_explain(explain);
  pb::RecognizeObjectsResponse response;
  const grpc::Status status = objects_->RecognizeObjects(UnaryContext().get(), request, &response);
  if (!status.ok()) return status;
  return response;
}

}  // namespace recog::client
