// TcpProxy: a loopback TCP proxy for tests of broken connections. It forwards every connection
// it accepts to 127.0.0.1:<upstream port>, counts the bytes each connection sent upstream, and can
// cut the first connection once it has sent a given number of bytes upstream: it stalls (nothing
// more is forwarded upstream) for kStallBeforeCut, then shuts both sockets down, as when a network
// link fails. The stall lets the server take in what it received before the connection dies, so
// that tests do not race with its reading. Later connections are forwarded untouched.
// CutAtNextAnswer() loses an answer instead: the server's bytes are forwarded an HTTP/2 frame at a
// time, and the next HEADERS frame of a stream (the start of a call's answer, sent once the server
// has done the call's work) is not forwarded: that connection is cut there.
#pragma once

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

namespace recog::testing {

class TcpProxy {
 public:
  static constexpr std::chrono::milliseconds kStallBeforeCut{300};

  // `cut_first_after`: upstream bytes after which the first connection is cut; 0 = never.
  explicit TcpProxy(int upstream_port, uint64_t cut_first_after = 0)
      : upstream_port_(upstream_port), cut_first_after_(cut_first_after) {
    listener_ = socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in address = Loopback(0);
    bind(listener_, reinterpret_cast<sockaddr*>(&address), sizeof(address));
    listen(listener_, 16);
    socklen_t size = sizeof(address);
    getsockname(listener_, reinterpret_cast<sockaddr*>(&address), &size);
    port_ = ntohs(address.sin_port);
    acceptor_ = std::thread([this] { Accept(); });
  }
  ~TcpProxy() {
    shutdown(listener_, SHUT_RDWR);
    close(listener_);
    acceptor_.join();
    std::lock_guard lock(mutex_);
    for (const auto& c : connections_) {
      shutdown(c->client, SHUT_RDWR);
      shutdown(c->server, SHUT_RDWR);
    }
    for (const auto& c : connections_) {
      c->upstream.join();
      c->downstream.join();
      close(c->client);
      close(c->server);
    }
  }
  TcpProxy(const TcpProxy&) = delete;
  TcpProxy& operator=(const TcpProxy&) = delete;

  int port() const { return port_; }
  // Arms the cut of the connection that carries the next answer (see the header comment).
  void CutAtNextAnswer() { cut_at_answer_ = true; }
  // Answers lost by CutAtNextAnswer so far.
  int answers_cut() const { return answers_cut_; }
  // Bytes sent upstream by each connection so far, in the order they were accepted.
  std::vector<uint64_t> upstream_bytes() const {
    std::lock_guard lock(mutex_);
    std::vector<uint64_t> bytes;
    for (const auto& c : connections_) bytes.push_back(c->sent_upstream.load());
    return bytes;
  }

 private:
  struct Connection {
    int client = -1, server = -1;
    uint64_t cut_after = 0;  // 0 = never
    std::atomic<uint64_t> sent_upstream{0};
    std::thread upstream, downstream;
  };

  static sockaddr_in Loopback(int port) {
    sockaddr_in address{};
    address.sin_family = AF_INET;
    address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    address.sin_port = htons(uint16_t(port));
    return address;
  }

  void Accept() {
    for (;;) {
      const int client = accept(listener_, nullptr, nullptr);
      if (client < 0) return;  // the listener was shut down
      const int server = socket(AF_INET, SOCK_STREAM, 0);
      sockaddr_in address = Loopback(upstream_port_);
      if (connect(server, reinterpret_cast<sockaddr*>(&address), sizeof(address)) != 0) {
        close(client);
        close(server);
        continue;
      }
      std::lock_guard lock(mutex_);
      auto c = std::make_unique<Connection>();
      c->client = client;
      c->server = server;
      c->cut_after = connections_.empty() ? cut_first_after_ : 0;
      Connection* raw = c.get();
      c->upstream = std::thread([raw] { PumpRequests(raw); });
      c->downstream = std::thread([this, raw] { PumpAnswers(raw); });
      connections_.push_back(std::move(c));
    }
  }

  // A write that fails with EPIPE instead of raising SIGPIPE when the peer (or the other pump of
  // the same connection) has already shut the socket down.
  static ssize_t Send(int socket, const char* bytes, size_t size) {
    return send(socket, bytes, size, MSG_NOSIGNAL);
  }

  // Copies from the client to the server until either side closes (or the connection is cut).
  static void PumpRequests(Connection* c) {
    const int from = c->client, to = c->server;
    char buffer[16384];
    for (;;) {
      ssize_t n = read(from, buffer, sizeof(buffer));
      if (n <= 0) break;
      if (c->cut_after > 0) {
        const uint64_t room = c->cut_after - c->sent_upstream.load();
        if (uint64_t(n) >= room) {
          if (room > 0) (void)!Send(to, buffer, size_t(room));
          c->sent_upstream += room;
          std::this_thread::sleep_for(kStallBeforeCut);
          break;
        }
      }
      for (ssize_t at = 0; at < n;) {
        const ssize_t w = Send(to, buffer + at, size_t(n - at));
        if (w <= 0) goto done;
        at += w;
      }
      c->sent_upstream += uint64_t(n);
    }
  done:
    shutdown(c->client, SHUT_RDWR);
    shutdown(c->server, SHUT_RDWR);
  }

  // Copies from the server to the client an HTTP/2 frame at a time (9-byte header: 24-bit length,
  // type, flags, 31-bit stream id), cutting the connection at an answer when armed.
  void PumpAnswers(Connection* c) {
    constexpr unsigned char kHeaders = 0x1;
    std::string pending;
    char buffer[16384];
    for (;;) {
      const ssize_t n = read(c->server, buffer, sizeof(buffer));
      if (n <= 0) break;
      pending.append(buffer, size_t(n));
      size_t at = 0;
      while (pending.size() - at >= 9) {
        const auto* frame = reinterpret_cast<const unsigned char*>(pending.data() + at);
        const size_t length = size_t(frame[0]) << 16 | size_t(frame[1]) << 8 | frame[2];
        if (pending.size() - at < 9 + length) break;
        const bool on_stream = ((frame[5] & 0x7f) | frame[6] | frame[7] | frame[8]) != 0;
        if (frame[3] == kHeaders && on_stream && cut_at_answer_.exchange(false)) {
          ++answers_cut_;
          goto done;
        }
        for (size_t w = 0; w < 9 + length;) {
          const ssize_t written = Send(c->client, pending.data() + at + w, 9 + length - w);
          if (written <= 0) goto done;
          w += size_t(written);
        }
        at += 9 + length;
      }
      pending.erase(0, at);
    }
  done:
    shutdown(c->client, SHUT_RDWR);
    shutdown(c->server, SHUT_RDWR);
  }

  const int upstream_port_;
  const uint64_t cut_first_after_;
  std::atomic<bool> cut_at_answer_{false};
  std::atomic<int> answers_cut_{0};
  int listener_ = -1;
  int port_ = 0;
  std::thread acceptor_;
  mutable std::mutex mutex_;
  std::vector<std::unique_ptr<Connection>> connections_;
};

}  // namespace recog::testing
