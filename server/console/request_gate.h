// RequestGate: what the console checks of every request before routing it or reading its body,
// so that a request that will be refused costs nothing (no body read, nothing decoded) and cannot
// reach a handler through a way around the rules.
//
// In order:
//  1. the Host header, exactly host[:port], names the console: an IP address, "localhost", or a
//     name of console.hosts (HostAllowList); an Origin header, when present, is this very origin
//     (scheme://Host). So a page elsewhere cannot drive the console, not even through a name it
//     rebinds to this machine (403);
//  2. the body: sent with Content-Length, which a POST must have (chunked bodies and POSTs without
//     a length are refused, 411), not compressed (415),
//     at most `max_body_bytes` (413), and only to POST /api/rpc/... (400; other methods 405);
//  3. under /api/: an Authorization header of printable ASCII (401); for the gateway's calls a
//     JSON body (Content-Type application/json, with parameters or none; else 415) and, when tokens
//     are configured, a token that authenticates (401), checked before the body is read. The call
//     itself checks its rights, as any gRPC call does.
// A refusal is {"code", "message"} (ErrorReply); the connection is closed after it, since the
// body was not read. Thread-safe (const).
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "server/auth/token_auth.h"
#include "server/console/rpc_gateway.h"
#include "server/http/host_header.h"

namespace httplib {
struct Request;
}

namespace recog::server {

class RequestGate {
 public:
  // `hosts`: console.hosts; `https`: whether the console speaks TLS (for the Origin);
  // `auth`: the server's tokens (must outlive the gate).
  RequestGate(const std::vector<std::string>& hosts, bool https, size_t max_body_bytes,
              const TokenAuthenticator* auth);

  // The refusal of `request`, or nothing when it may go on.
  std::optional<HttpReply> Check(const httplib::Request& request) const;

 private:
  std::optional<HttpReply> CheckOrigin(const httplib::Request& request) const;
  std::optional<HttpReply> CheckBody(const httplib::Request& request) const;
  std::optional<HttpReply> CheckApi(const httplib::Request& request) const;

  HostAllowList hosts_;
  bool https_;
  size_t max_body_bytes_;
  const TokenAuthenticator* auth_;
};

}  // namespace recog::server
