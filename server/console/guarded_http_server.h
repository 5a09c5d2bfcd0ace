// MakeGuardedHttpServer: cpp-httplib's HTTP (or HTTPS) server with the connection handling that a
// port open to anyone needs and that cpp-httplib 0.11 lacks. The console serves through it.
//
//  - Deadlines per request, not per read: a request (its line, headers and body) must arrive
//    within `request_timeout` and its response be taken within `request_timeout` too, however
//    slowly the bytes trickle. (cpp-httplib's own timeout is per read, so a client sending a byte
//    every few seconds held one of its threads for ever: slowloris.) A TLS handshake has the same
//    deadline, and a connection idle between requests is closed after `idle_timeout`.
//  - A connection cap: `max_connections` are served at once, one thread each, and at most
//    `max_connections_per_client` from one address. A connection beyond the cap is answered 503 and
//    closed at once (over TLS, closed) instead of waiting in a queue behind slow clients.
//  - A handler may close its connection after its response (CloseConnectionAfterResponse), as it
//    must when it refused a request without reading the body the client sent.
//
// Everything else (routes, handlers, error handlers, default headers, payload limit) is the
// returned httplib::Server's, configured as usual. Its thread pool is set here: do not replace
// `new_task_queue`.
#pragma once

#include <chrono>
#include <cstddef>
#include <memory>
#include <string>

namespace httplib {
class Server;
}

namespace recog::server {

struct ConnectionLimits {
  size_t max_connections = 32;                       // served at once (a thread each)
  size_t max_connections_per_client = 8;             // from one client address
  std::chrono::milliseconds request_timeout{30000};  // to receive a request, and to send its reply
  std::chrono::milliseconds idle_timeout{5000};      // between two requests of a connection
  size_t max_requests_per_connection = 100;
};

// The TLS files of an HTTPS server (PEM paths; client_ca empty: no client certificates asked).
struct HttpsFiles {
  std::string cert, key, client_ca;
};

// A plain HTTP server when `https` is null. The server's is_valid() says whether the TLS files
// could be used.
std::unique_ptr<httplib::Server> MakeGuardedHttpServer(const ConnectionLimits& limits,
                                                       const HttpsFiles* https = nullptr);

// From a handler of a guarded server: closes the connection that carried the request once its
// response is sent (no further request is read from it). The response should also say
// `Connection: close`.
void CloseConnectionAfterResponse();

}  // namespace recog::server
