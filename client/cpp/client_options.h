// ClientOptions: how a RecognitionClient reaches recogd — address, transport security,
// authentication, deadlines, retries and message size. Every field has a working default for a
// server on this machine with its default configuration (plaintext, no tokens).
//
// The retry rule (RetryPolicy) is the client's whole answer to a busy or unreachable server:
//  - Retried, for every call: RESOURCE_EXHAUSTED that carries the server's `retry-after-ms`
//    trailer. The server sends it only when it refused the call from a full work queue, before
//    running any of it, so even an AddFrame or an upload can be sent again. Other
//    RESOURCE_EXHAUSTED errors (a message over the size limit, a model over 256 MiB) are final.
//  - Retried, for calls that change nothing or can be repeated without harm (GetMap, ListMaps,
//    QueryPlace without add_frame, RecognizeObjects, ListModels, DownloadModel): UNAVAILABLE.
//    UploadModel is one of them: a retry first asks the server what it holds of the file
//    (GetUploadStatus) and sends only the rest, or returns the version stored by an attempt
//    whose answer was lost.
//  - Retried, for calls that change the server (CreateMap, DeleteMap, AddFrame, QueryPlace with
//    add_frame, DeleteModel): UNAVAILABLE only when nothing was sent. Before sending
//    such a call the client waits for the channel to be connected; when it cannot connect, the
//    attempt fails without sending anything and is retried. An UNAVAILABLE after the request left
//    (the connection broke, the server was draining) is returned to the caller: the server may
//    have applied it, and only the caller knows whether doing it twice is harmless.
//  - Never retried: every other code, and the streams (FrameStream, ObjectStream, WatchModels).
// The delay before retry n (1, 2, ...) is min(max_backoff, initial_backoff * multiplier^(n-1)),
// times a random factor in [1 - jitter, 1 + jitter], and at least the server's `retry-after-ms`
// when it sent one. No retry starts after the call's deadline: the deadline covers every attempt.
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

// When and how often failed calls are tried again (the rule is in the header comment).
struct RetryPolicy {
  // Default 5: attempts of one call, the first included; 1 = never retry. 1 to 100.
  int max_attempts = 5;
  // Default 100 ms: the delay before the first retry. At least 1 ms.
  std::chrono::milliseconds initial_backoff{100};
  // Default 2: each further retry waits this many times longer than the previous one. 1 to 10.
  double multiplier = 2.0;
  // Default 5 s: the longest computed delay (a longer `retry-after-ms` from the server wins).
  // At least initial_backoff.
  std::chrono::milliseconds max_backoff{5000};
  // Default 0.2: every delay is multiplied by a random factor in [1 - jitter, 1 + jitter], so
  // that clients refused together do not come back together. 0 to 1.
  double jitter = 0.2;
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
  RetryPolicy retry;
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
