// GrpcListener: the listening sockets of recogd's gRPC port. Connections are accepted here and
// handed to gRPC (ServerBuilder's external connection acceptor, plaintext or TLS alike) because
// gRPC 1.51's own listener stops for good at the first accept that finds no free descriptor
// (EMFILE): a client that opened connections until the process ran out of descriptors left the
// port deaf until a restart, even after closing them all.
//
//  - Reserve: a connection whose descriptor is among the last `reserve_descriptors` below the
//    process's limit (RLIMIT_NOFILE) is closed at once. Descriptors are allocated lowest first, so
//    that number means every lower one is taken; the reserve stays for the store, the console,
//    the metrics port and the connections already served.
//  - Spare: when accept itself finds no descriptor (the reserve was taken by someone else), a
//    descriptor kept for this is closed, the waiting connection accepted and closed at once (its
//    client sees the connection close, not a hang), and the spare taken again. Accepting goes on.
//  - Refused connections are counted (refused()) and logged at most once every 10 s.
//
// One thread accepts; gRPC serves what it hands over. Not copyable; destroying the listener stops
// accepting and closes the listening sockets (gRPC keeps the connections already handed over).
#pragma once

#include <atomic>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "core/common/status.h"

namespace grpc::experimental {
class ExternalConnectionAcceptor;
}

namespace recog::server {

class GrpcListener {
 public:
  struct Options {
    // "host:port", "[v6]:port" or "unix:path"; port 0 picks a free port. A host name listens on
    // each address it resolves to ("localhost": 127.0.0.1 and ::1).
    std::string address;
    // Descriptors kept free below the process's limit: connections beyond are closed at once.
    size_t reserve_descriptors = 64;
  };

  // Binds and listens. UNAVAILABLE naming the address when it cannot (in use, not this machine's,
  // malformed); INVALID_ARGUMENT when the descriptor limit leaves no room above the reserve.
  static StatusOr<std::unique_ptr<GrpcListener>> Bind(const Options& options);
  ~GrpcListener();
  GrpcListener(const GrpcListener&) = delete;
  GrpcListener& operator=(const GrpcListener&) = delete;

  // The TCP port listened on (the one picked for port 0); 0 for a unix socket.
  int port() const { return port_; }
  // Starts the accepting thread, handing each connection to `acceptor` (which must outlive the
  // listener; gRPC closes connections handed over before its server started or after it stopped).
  void Start(grpc::experimental::ExternalConnectionAcceptor* acceptor);
  // Connections closed at once for want of descriptors since Bind.
  uint64_t refused() const { return refused_.load(); }

 private:
  explicit GrpcListener(const Options& options) : options_(options) {}
  void AcceptLoop(grpc::experimental::ExternalConnectionAcceptor* acceptor);
  // Accepts one connection of `listener` into `acceptor`; false when there was none waiting.
  bool AcceptOne(int listener, grpc::experimental::ExternalConnectionAcceptor* acceptor);
  void Refuse(int fd, const char* why);

  const Options options_;
  std::vector<int> sockets_;  // listening
  std::string unix_path_;     // removed on destruction
  int port_ = 0;
  int wake_ = -1;   // eventfd: the destructor wakes the loop
  int spare_ = -1;  // a descriptor given up when accept finds none
  std::atomic<uint64_t> refused_{0};
  std::chrono::steady_clock::time_point last_warning_{};  // of Refuse's log line
  uint64_t refused_since_warning_ = 0;
  std::atomic<bool> stopping_{false};
  std::thread thread_;
};

}  // namespace recog::server
