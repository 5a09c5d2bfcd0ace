// MakeGuardedHttpServer: cpp-httplib's HTTP (or HTTPS) server with the connection handling that a
// port open to anyone needs and that cpp-httplib 0.11 lacks. The console and the metrics port
// serve through it; HttpPort runs one on its address.
//
//  - Deadlines per request, not per read: a request's line and headers must arrive within
//    `header_timeout`, the whole request within `request_timeout`, and its response be taken
//    within `request_timeout` too, however slowly the bytes trickle. (cpp-httplib's own timeout is
//    per read, so a client sending a byte every few seconds held one of its threads for ever:
//    slowloris.) Besides, after its first second a request (and a response) must move at least
//    `min_bytes_per_second` on average. A TLS handshake has the request's deadline, and a
//    connection idle between requests is closed after `idle_timeout`. A request cut before its
//    headers were whole is answered 408.
//  - The request's head is read here, before cpp-httplib sees it: at most `max_header_lines`
//    header lines and `max_header_bytes` bytes (request line included), or 431 and the connection
//    closed; lines must end in CRLF and header names be tokens, a Content-Length must be one
//    number of plain digits, or 400. cpp-httplib percent-decodes header values (so that
//    `Content-Length: %32` would read as 2); handlers see the values as they were sent instead.
//    A Range of several byte ranges is ignored (the whole answer, 200): cpp-httplib would build a
//    copy of the answer per range.
//  - A connection cap: `max_connections` are served at once, one thread each, and at most
//    `max_connections_per_client` from one address. A connection beyond either cap takes the place
//    of the connection (of any client, or of its own address) that has waited longest for its
//    request's headers (a new connection, one idle between requests, a slow client): that one is
//    closed. When every place is busy with a request, it is answered 503 and closed at once (over
//    TLS, closed) instead of waiting in a queue. So slow clients cannot hold every place, even
//    from the address of the proxy that all clients share; a client whose request follows its
//    connection at once (as browsers' and scrapers' do) is not evicted before it is read (a
//    connection whose socket holds bytes not yet read is no candidate).
//  - A handler may close its connection after its response (CloseConnectionAfterResponse), as it
//    must when it refused a request without reading the body the client sent.
// The guard's own answers (503, 431, 408, 400) are {"code", "message"} JSON carrying the
// `answer_headers` given (e.g. the console's security headers) and `Connection: close`.
//
// Everything else (routes, handlers, error handlers, default headers, payload limit) is the
// returned httplib::Server's, configured as usual. Its thread pool is set here: do not replace
// `new_task_queue`.
#pragma once

#include <chrono>
#include <cstddef>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "core/common/status.h"
#include "server/config/server_config.h"

namespace httplib {
class Server;
}

namespace recog::server {

struct ConnectionLimits {
  size_t max_connections = 32;                       // served at once (a thread each)
  size_t max_connections_per_client = 8;             // from one client address
  std::chrono::milliseconds request_timeout{30000};  // to receive a request, and to send its reply
  std::chrono::milliseconds header_timeout{10000};   // to receive its line and headers
  std::chrono::milliseconds idle_timeout{5000};      // between two requests of a connection
  size_t min_bytes_per_second = 1024;                // after a request's first second; 0: none
  size_t max_header_lines = 100;                     // header lines of a request
  size_t max_header_bytes = 16384;                   // request line and headers together
  size_t max_requests_per_connection = 100;
};

// The limits of a port as configured (the console's, the metrics').
ConnectionLimits LimitsOf(const HttpPortConfig& config);

// The TLS files of an HTTPS server (PEM paths; client_ca empty: no client certificates asked).
struct HttpsFiles {
  std::string cert, key, client_ca;
};

using HeaderList = std::vector<std::pair<std::string, std::string>>;

// A plain HTTP server when `https` is null. The server's is_valid() says whether the TLS files
// could be used. `answer_headers` go with the answers the guard itself gives.
std::unique_ptr<httplib::Server> MakeGuardedHttpServer(const ConnectionLimits& limits,
                                                       const HttpsFiles* https = nullptr,
                                                       HeaderList answer_headers = {});

// From a handler of a guarded server: closes the connection that carried the request once its
// response is sent (no further request is read from it). The response should also say
// `Connection: close`.
void CloseConnectionAfterResponse();

// "host:port" (or "[v6]:port") into its parts; false when malformed.
bool SplitHostPort(const std::string& address, std::string* host, int* port);

// A configured server listening on an address, served from a background thread until destroyed.
class HttpPort {
 public:
  // Binds `server` (with its routes set) to `listen` ("host:port", "[v6]:port"; port 0 picks a
  // free one) and serves it. INVALID_ARGUMENT for a malformed address, UNAVAILABLE when it cannot
  // be bound; `what` names the port in the message ("the console").
  static StatusOr<std::unique_ptr<HttpPort>> Listen(std::unique_ptr<httplib::Server> server,
                                                    const std::string& listen,
                                                    const std::string& what);
  ~HttpPort();  // stops serving: requests in flight finish first
  HttpPort(const HttpPort&) = delete;
  HttpPort& operator=(const HttpPort&) = delete;

  const std::string& host() const { return host_; }
  int port() const { return port_; }

 private:
  HttpPort() = default;

  std::unique_ptr<httplib::Server> server_;
  std::string host_;
  int port_ = 0;
  struct Thread;
  std::unique_ptr<Thread> thread_;
};

}  // namespace recog::server
