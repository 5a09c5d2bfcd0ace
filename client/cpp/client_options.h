// ClientOptions: how a RecognitionClient reaches recogd — address, transport security,
// authentication, deadlines, retries and message size. Every field has a working default for a
// server on this machine with its default configuration (plaintext, no tokens).
//
// Retries are gRPC's own (gRFC A6), by the one policy of proto/service_config.json, compiled into
// the client (as shipped: up to 5 attempts of a call, randomised backoff from 0.1 s doubling up to
// 5 s, for UNAVAILABLE and RESOURCE_EXHAUSTED). A busy server's RESOURCE_EXHAUSTED carries
// `grpc-retry-pushback-ms`, and gRPC waits that long before the next attempt; a refusal that a
// retry cannot cure (a model over 256 MiB, a full disk) carries a pushback of -1 and is not
// retried. The deadline covers every attempt. Calls that change the server are retried too: each
// carries a request_id (a fresh UUID v4 unless the caller gives one), and the server answers a
// repeat of a recent id with the first attempt's result instead of applying it twice (for 10
// minutes, per server process). Streams are retried by gRPC only before their first answer; model
// uploads and downloads and checkpoints resume or restart a transfer that broke later
// (recognition_client.h).
#pragma once

#include <chrono>
#include <cstdint>
#include <string>

#include <grpcpp/support/status.h>

namespace recog::client {

// Transport security. Off by default (the server's default is plaintext on localhost).
struct TlsOptions {
  // Default false: plaintext. true: TLS; the server's certificate must be signed by a CA of
  // ca_file (or of the system's trust store when ca_file is empty) and name the target's host.
  bool enabled = false;
  // Default "": PEM file of the CA certificate(s) to trust; "" = the system's trust store.
  std::string ca_file;
  // Default "": PEM certificate chain of this client, for servers that require mutual TLS.
  // Given together with key_file, or not at all.
  std::string cert_file;
  // Default "": PEM private key of cert_file.
  std::string key_file;
};

struct ClientOptions {
  // Default "127.0.0.1:50051": the server's address, as gRPC takes it (host:port,
  // dns:///host:port, ipv4:addr:port, unix:path).
  std::string target = "127.0.0.1:50051";
  TlsOptions tls;
  // Default "": the bearer token sent with every call (`authorization: Bearer <token>`); "" =
  // none, for servers without a token file. Visible ASCII characters only. Not with token_file.
  std::string token;
  // Default "": a file whose content is the token: the whole file, with leading and trailing
  // whitespace (spaces, tabs, line breaks) removed. Read once, by Connect. Not with token.
  std::string token_file;
  // Default 10 s: the deadline of a unary call (map management, frames, queries, recognition,
  // listings), every retry included.
  std::chrono::milliseconds deadline{10000};
  // Default 10 min: the deadline of a model upload or download, every retry and resumption
  // included.
  std::chrono::milliseconds transfer_deadline{600000};
  // Default true: gRPC retries calls by the policy above (grpc.enable_retries); false: every call
  // is one attempt (tests, probes). Transfers that break mid-file resume either way.
  bool retries = true;
  // Default 32 MiB (the server's default): the largest message sent or received. 1 MiB to
  // 2 GiB - 1 (gRPC's limit).
  uint32_t max_message_bytes = 32u << 20;
  // Default 32: frames a FrameStream or ObjectStream may have sent and not yet had answered; a
  // further Send is answered at once with RESOURCE_EXHAUSTED (the frame is not sent), so that a
  // camera faster than the server drops frames instead of queueing them. 1 to 1024.
  uint32_t max_frames_in_flight = 32;
  // Default "": behind a router of sharded servers (deploy/nginx/), the shard that calls without
  // a place map go to (ListMaps, Admin calls; recognition and model reads, else any server that
  // holds the models); sent as the `x-recog-shard` header. Calls about a map are
  // routed by their map (`x-recog-map`, always sent). 1 to 64 characters of [A-Za-z0-9_].
  std::string shard;

  // INVALID_ARGUMENT naming the first bad field. Does not read any file.
  grpc::Status Validate() const;
};

}  // namespace recog::client
