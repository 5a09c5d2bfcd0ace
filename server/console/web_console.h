// WebConsole: recogd's web console (ConsoleConfig, `console.listen`) — pages to browse the place
// maps and the model repository, try recognition on an image, and watch the server live.
//
// It serves, on its own HTTP (or, with the server's tls.cert, HTTPS) address:
//   /static/...            the pages (server/console/web: plain ES modules, no build step)
//   /vendor/three/...      Debian's libjs-three, /vendor/chart.js/... Debian's libjs-chart.js
//   /api/rpc/<Service>/<Method>   every unary RPC as JSON (RpcGateway: the same services)
//   /api/maps, /api/maps/<name>/loops, /api/maps/<name>/frames/<id>/thumbnail,
//   /api/models/<name>, /api/models/<name>/points, /api/models/<name>/views/<i>/image,
//   /api/live, /api/whoami   the views the gRPC API has no call for (docs/server.md, "Console")
// Every request passes the RequestGate first (its Host and Origin, its body's size and framing,
// the Authorization header, and for the gateway's calls the token, all before a body is read);
// a gateway call's body is read only once it fits in the bytes the gateway decodes at once
// (console.max_inflight_body_bytes; 503 otherwise). Files are served by exact name
// (StaticFiles), a Range of one byte range answered 206; connections have deadlines, limits on
// their headers and a cap (MakeGuardedHttpServer, server/http/). Every /api/ view authenticates
// with the server's tokens and needs the read right (and the map's, for a map's views); the
// gateway's calls check their own right as any gRPC call does, so a read-only token cannot change
// anything. Answers that fail are
// {"code", "message"} with the HTTP status of the gRPC code; a handler that throws answers 500.
// Every answer carries a Content-Security-Policy (no framing, scripts of the console only),
// X-Content-Type-Options: nosniff and X-Frame-Options: DENY.
#pragma once

#include <memory>
#include <optional>
#include <string>

#include <grpcpp/grpcpp.h>

#include "core/common/status.h"
#include "server/console/live_sampler.h"
#include "server/console/request_gate.h"
#include "server/console/rpc_gateway.h"
#include "server/console/static_files.h"
#include "server/http/guarded_http_server.h"
#include "server/runtime/byte_budget.h"
#include "server/services/server_state.h"

namespace recog::server {

class WebConsole {
 public:
  // Listens on state->config.console.listen and serves from a background thread until destroyed.
  // `channel` is an in-process channel to the server's services. UNAVAILABLE when the address
  // cannot be bound, NOT_FOUND when the pages are missing, INVALID_ARGUMENT for a malformed
  // address, FAILED_PRECONDITION when the TLS files cannot be used.
  static StatusOr<std::unique_ptr<WebConsole>> Start(ServerState* state,
                                                     std::shared_ptr<grpc::Channel> channel);
  ~WebConsole() = default;  // stops serving: requests in flight finish first
  WebConsole(const WebConsole&) = delete;
  WebConsole& operator=(const WebConsole&) = delete;

  int port() const { return port_->port(); }
  // Where a browser opens it: "http://HOST:PORT/" ("https://" with the server's TLS files).
  const std::string& url() const { return url_; }

 private:
  WebConsole(ServerState* state, std::shared_ptr<grpc::Channel> channel);
  void AddRoutes(httplib::Server& http);

  ServerState* state_;
  RpcGateway gateway_;
  LiveSampler live_;
  std::optional<RequestGate> gate_;  // set by Start
  StaticFiles files_;
  ByteBudget body_budget_;  // of the gateway's calls
  std::unique_ptr<HttpPort> port_;
  std::string url_;
};

// Where the bundled pages are: the source tree's server/console/web, else the installed copy.
std::string DefaultConsoleWebRoot();

}  // namespace recog::server
