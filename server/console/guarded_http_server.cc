#include "server/console/guarded_http_server.h"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <condition_variable>
#include <deque>
#include <functional>
#include <mutex>
#include <optional>
#include <thread>
#include <type_traits>
#include <unordered_map>
#include <vector>

#include <httplib.h>
#include <openssl/err.h>
#include <openssl/ssl.h>

namespace recog::server {
namespace {

using Clock = std::chrono::steady_clock;

// Set on the thread that serves a connection by CloseConnectionAfterResponse.
thread_local bool close_requested = false;
// Set while the accept thread runs a connection that no worker was free for: it is refused.
thread_local bool over_capacity = false;

constexpr auto kPollSlice = std::chrono::milliseconds(100);  // how often a wait checks for stop()
// A closing connection reads (and drops) at most this much of what the client still sends, so
// that its response is not lost to a reset.
constexpr auto kLingerTime = std::chrono::milliseconds(500);
constexpr size_t kLingerBytes = 1 << 20;
constexpr char kRefusalBody[] =
    R"({"code":"UNAVAILABLE","message":"the console serves too many connections; retry later"})";

std::string RefusalResponse() {
  return std::string("HTTP/1.1 503 Service Unavailable\r\nContent-Type: application/json\r\n") +
         "Retry-After: 1\r\nConnection: close\r\nContent-Length: " +
         std::to_string(sizeof(kRefusalBody) - 1) + "\r\n\r\n" + kRefusalBody;
}

// The numeric address of a socket's peer (or of its own end), and the port.
void SocketAddress(int fd, bool peer, std::string* ip, int* port) {
  sockaddr_storage address{};
  socklen_t length = sizeof(address);
  const int got = peer ? getpeername(fd, reinterpret_cast<sockaddr*>(&address), &length)
                       : getsockname(fd, reinterpret_cast<sockaddr*>(&address), &length);
  ip->clear();
  *port = 0;
  if (got != 0) return;
  char text[INET6_ADDRSTRLEN] = {};
  if (address.ss_family == AF_INET) {
    const auto* v4 = reinterpret_cast<const sockaddr_in*>(&address);
    inet_ntop(AF_INET, &v4->sin_addr, text, sizeof(text));
    *port = ntohs(v4->sin_port);
  } else if (address.ss_family == AF_INET6) {
    const auto* v6 = reinterpret_cast<const sockaddr_in6*>(&address);
    inet_ntop(AF_INET6, &v6->sin6_addr, text, sizeof(text));
    *port = ntohs(v6->sin6_port);
  }
  *ip = text;
}

// A thread per connection, up to a fixed number; a connection that finds every thread busy is
// run at once on the accepting thread, marked over capacity, so that it is refused there instead
// of queueing behind slow clients.
class CappedTaskQueue final : public httplib::TaskQueue {
 public:
  explicit CappedTaskQueue(size_t threads) {
    for (size_t i = 0; i < threads; ++i) threads_.emplace_back([this] { Work(); });
  }

  void enqueue(std::function<void()> task) override {
    {
      std::lock_guard lock(mutex_);
      if (tasks_.size() + busy_ < threads_.size()) {
        tasks_.push_back(std::move(task));
        wake_.notify_one();
        return;
      }
    }
    over_capacity = true;
    task();
    over_capacity = false;
  }

  void shutdown() override {
    {
      std::lock_guard lock(mutex_);
      stopping_ = true;
    }
    wake_.notify_all();
    for (std::thread& thread : threads_) thread.join();
  }

 private:
  void Work() {
    std::unique_lock lock(mutex_);
    while (true) {
      wake_.wait(lock, [this] { return stopping_ || !tasks_.empty(); });
      if (tasks_.empty()) return;  // stopping, and nothing left
      std::function<void()> task = std::move(tasks_.front());
      tasks_.pop_front();
      ++busy_;
      lock.unlock();
      task();
      lock.lock();
      --busy_;
    }
  }

  std::mutex mutex_;
  std::condition_variable wake_;
  std::deque<std::function<void()>> tasks_;
  size_t busy_ = 0;
  bool stopping_ = false;
  std::vector<std::thread> threads_;
};

// How many connections each client address has open.
class ClientCounts {
 public:
  // False (and nothing counted) when `address` already has `max` connections.
  bool Admit(const std::string& address, size_t max) {
    std::lock_guard lock(mutex_);
    size_t& count = open_[address];
    if (count >= max) return false;
    ++count;
    return true;
  }
  void Release(const std::string& address) {
    std::lock_guard lock(mutex_);
    const auto it = open_.find(address);
    if (it != open_.end() && --it->second == 0) open_.erase(it);
  }

 private:
  std::mutex mutex_;
  std::unordered_map<std::string, size_t> open_;
};

// One connection, plain or TLS, as cpp-httplib's Stream: a non-blocking socket whose reads must
// finish before the request's deadline and whose writes before the response's. Reads are
// buffered (cpp-httplib reads request lines a byte at a time).
class ConnectionStream final : public httplib::Stream {
 public:
  ConnectionStream(int fd, SSL* ssl, std::function<bool()> running)
      : fd_(fd), ssl_(ssl), running_(std::move(running)) {
    fcntl(fd_, F_SETFL, fcntl(fd_, F_GETFL, 0) | O_NONBLOCK);
  }

  // A new exchange: its request must be read before `read_deadline`; its response, once begun,
  // must be sent within `write_time`.
  void StartExchange(Clock::time_point read_deadline, Clock::duration write_time) {
    read_deadline_ = read_deadline;
    write_time_ = write_time;
    write_deadline_.reset();
  }

  // The TLS handshake (nothing for a plain connection), before `deadline`.
  bool Handshake(Clock::time_point deadline) {
    if (ssl_ == nullptr) return true;
    while (true) {
      ERR_clear_error();
      const int done = SSL_accept(ssl_);
      if (done == 1) return true;
      const int error = SSL_get_error(ssl_, done);
      if (error == SSL_ERROR_WANT_READ) {
        if (!Wait(POLLIN, deadline)) return false;
      } else if (error == SSL_ERROR_WANT_WRITE) {
        if (!Wait(POLLOUT, deadline)) return false;
      } else {
        return false;
      }
    }
  }

  // Waits up to `idle` for the next request's first byte; false when the connection was closed,
  // stayed idle or the server stops.
  bool WaitForRequest(Clock::duration idle) {
    if (Buffered()) return true;
    return Wait(POLLIN, Clock::now() + idle);
  }

  bool is_readable() const override {
    return Buffered() || const_cast<ConnectionStream*>(this)->Wait(POLLIN, read_deadline_);
  }
  bool is_writable() const override {
    return const_cast<ConnectionStream*>(this)->Wait(POLLOUT, WriteDeadline());
  }

  ssize_t read(char* out, size_t size) override {
    if (begin_ == end_) {
      const ssize_t got = Receive(buffer_, sizeof(buffer_));
      if (got <= 0) return got;
      begin_ = 0;
      end_ = size_t(got);
    }
    const size_t n = std::min(size, end_ - begin_);
    std::copy_n(buffer_ + begin_, n, out);
    begin_ += n;
    return ssize_t(n);
  }

  ssize_t write(const char* data, size_t size) override {
    const Clock::time_point deadline = WriteDeadline();
    while (true) {
      ssize_t sent = 0;
      short want = POLLOUT;
      if (ssl_ != nullptr) {
        ERR_clear_error();
        sent = SSL_write(ssl_, data, int(std::min<size_t>(size, INT32_MAX)));
        if (sent > 0) return sent;
        const int error = SSL_get_error(ssl_, int(sent));
        if (error == SSL_ERROR_WANT_READ) {
          want = POLLIN;
        } else if (error != SSL_ERROR_WANT_WRITE) {
          return -1;
        }
      } else {
        sent = send(fd_, data, size, MSG_NOSIGNAL);
        if (sent >= 0) return sent;
        if (errno == EINTR) continue;
        if (errno != EAGAIN && errno != EWOULDBLOCK) return -1;
      }
      if (!Wait(want, deadline)) return -1;
    }
  }

  void get_remote_ip_and_port(std::string& ip, int& port) const override {
    SocketAddress(fd_, true, &ip, &port);
  }
  void get_local_ip_and_port(std::string& ip, int& port) const override {
    SocketAddress(fd_, false, &ip, &port);
  }
  socket_t socket() const override { return fd_; }

 private:
  bool Buffered() const { return begin_ < end_ || (ssl_ != nullptr && SSL_pending(ssl_) > 0); }

  // The response's deadline, from its first write on.
  Clock::time_point WriteDeadline() const {
    if (!write_deadline_) write_deadline_ = Clock::now() + write_time_;
    return *write_deadline_;
  }

  // Up to `size` bytes before the read deadline: > 0 read, 0 the peer closed, -1 error or late.
  ssize_t Receive(char* out, size_t size) {
    while (true) {
      short want = POLLIN;
      if (ssl_ != nullptr) {
        ERR_clear_error();
        const int got = SSL_read(ssl_, out, int(size));
        if (got > 0) return got;
        const int error = SSL_get_error(ssl_, got);
        if (error == SSL_ERROR_ZERO_RETURN) return 0;
        if (error == SSL_ERROR_WANT_WRITE) {
          want = POLLOUT;
        } else if (error != SSL_ERROR_WANT_READ) {
          return -1;
        }
      } else {
        const ssize_t got = recv(fd_, out, size, 0);
        if (got >= 0) return got;
        if (errno == EINTR) continue;
        if (errno != EAGAIN && errno != EWOULDBLOCK) return -1;
      }
      if (!Wait(want, read_deadline_)) return -1;
    }
  }

  // Waits until the socket is ready for `events` (or reports an error or a hang-up, which the
  // next read or write then sees); false at `deadline` or when the server stops.
  bool Wait(short events, Clock::time_point deadline) {
    while (running_()) {
      const auto left =
          std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now());
      if (left.count() <= 0) return false;
      pollfd entry{fd_, events, 0};
      const int ready = poll(&entry, 1, int(std::min(left, kPollSlice).count()));
      if (ready > 0) return true;
      if (ready < 0 && errno != EINTR) return false;
    }
    return false;
  }

  int fd_;
  SSL* ssl_;
  std::function<bool()> running_;
  Clock::time_point read_deadline_ = Clock::now();
  Clock::duration write_time_{};
  mutable std::optional<Clock::time_point> write_deadline_;
  char buffer_[4096];
  size_t begin_ = 0, end_ = 0;
};

// What both servers share: the limits, the per-client counts and the life of a connection.
class ConnectionGuard {
 public:
  explicit ConnectionGuard(const ConnectionLimits& limits) : limits_(limits) {}

  const ConnectionLimits& limits() const { return limits_; }

  // Serves the accepted socket `fd` until the client is done, a limit ends it or `running` turns
  // false; `process` is the server's own handling of one request. Closes `fd`.
  void Serve(int fd, SSL_CTX* tls, const std::function<bool()>& running,
             const std::function<bool(httplib::Stream&, bool last, bool& closed)>& process) {
    std::string client;
    int port = 0;
    SocketAddress(fd, true, &client, &port);
    // Beyond a cap, the connection is refused at once: it must not hold a thread.
    if (over_capacity || !clients_.Admit(client, limits_.max_connections_per_client)) {
      Refuse(fd, tls != nullptr);
      return;
    }
    bool unread = false;  // whether the client may still be sending when we close
    SSL* ssl = tls != nullptr ? SSL_new(tls) : nullptr;
    if (tls == nullptr || (ssl != nullptr && SSL_set_fd(ssl, fd) == 1)) {
      ConnectionStream stream(fd, ssl, running);
      const Clock::time_point deadline = Clock::now() + limits_.request_timeout;
      stream.StartExchange(deadline, limits_.request_timeout);
      if (stream.Handshake(deadline)) unread = ServeRequests(stream, running, process);
    }
    if (ssl != nullptr) {
      SSL_shutdown(ssl);  // one non-blocking attempt at a clean close
      SSL_free(ssl);
    }
    clients_.Release(client);
    if (unread) Linger(fd);
    Close(fd);
  }

 private:
  // The connection's requests, until it ends; true when it ended in the middle of a request
  // (the client may still be sending).
  bool ServeRequests(
      ConnectionStream& stream, const std::function<bool()>& running,
      const std::function<bool(httplib::Stream&, bool last, bool& closed)>& process) {
    for (size_t left = limits_.max_requests_per_connection; left > 0 && running(); --left) {
      if (!stream.WaitForRequest(limits_.idle_timeout)) return false;
      stream.StartExchange(Clock::now() + limits_.request_timeout, limits_.request_timeout);
      close_requested = false;
      bool closed = false;
      const bool ok = process(stream, left == 1, closed);
      if (!ok || close_requested) return true;
      if (closed) return false;
    }
    return false;
  }

  // Says that nothing more will be sent, then drops what the client still sends for a moment: a
  // socket closed with unread bytes resets the connection, and the client may then lose the
  // response (e.g. the refusal of a body that was not read).
  static void Linger(int fd) {
    shutdown(fd, SHUT_WR);
    const Clock::time_point until = Clock::now() + kLingerTime;
    char sink[16384];
    size_t dropped = 0;
    while (dropped < kLingerBytes) {
      const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(until - Clock::now());
      pollfd entry{fd, POLLIN, 0};
      if (left.count() <= 0 || poll(&entry, 1, int(left.count())) <= 0) return;
      const ssize_t got = recv(fd, sink, sizeof(sink), MSG_DONTWAIT);
      if (got <= 0) return;
      dropped += size_t(got);
    }
  }

  // Answers 503 without waiting (over TLS, nothing: that would take a handshake) and closes.
  static void Refuse(int fd, bool tls) {
    if (!tls) {
      char sink[16384];
      while (recv(fd, sink, sizeof(sink), MSG_DONTWAIT) > 0) {
      }  // what the request sent so far, so that the close does not reset the connection
      const std::string refusal = RefusalResponse();
      [[maybe_unused]] const ssize_t sent =
          send(fd, refusal.data(), refusal.size(), MSG_NOSIGNAL | MSG_DONTWAIT);
      shutdown(fd, SHUT_WR);
    }
    Close(fd);
  }

  static void Close(int fd) {
    shutdown(fd, SHUT_RDWR);
    close(fd);
  }

  ConnectionLimits limits_;
  ClientCounts clients_;
};

// httplib's Server or SSLServer, each connection served by a ConnectionGuard.
template <class Base>
class GuardedServer final : public Base {
 public:
  template <class... Args>
  explicit GuardedServer(const ConnectionLimits& limits, Args&&... args)
      : Base(std::forward<Args>(args)...), guard_(std::make_unique<ConnectionGuard>(limits)) {
    this->new_task_queue = [threads = limits.max_connections] {
      return new CappedTaskQueue(threads);
    };
    // cpp-httplib's default also sets SO_REUSEPORT, which lets a second server bind the same port
    // and take half its connections: only SO_REUSEADDR (a restart need not wait for TIME_WAIT).
    this->set_socket_options([](socket_t socket) {
      const int yes = 1;
      setsockopt(socket, SOL_SOCKET, SO_REUSEADDR, &yes, sizeof(yes));
    });
  }

 private:
  bool process_and_close_socket(socket_t fd) override {
    SSL_CTX* tls = nullptr;
    if constexpr (std::is_base_of_v<httplib::SSLServer, Base>) tls = this->ssl_context();
    guard_->Serve(
        fd, tls, [this] { return this->svr_sock_ != INVALID_SOCKET; },
        [this](httplib::Stream& stream, bool last, bool& closed) {
          return this->process_request(stream, last, closed, nullptr);
        });
    return true;
  }

  std::unique_ptr<ConnectionGuard> guard_;
};

}  // namespace

std::unique_ptr<httplib::Server> MakeGuardedHttpServer(const ConnectionLimits& limits,
                                                       const HttpsFiles* https) {
  if (https == nullptr) return std::make_unique<GuardedServer<httplib::Server>>(limits);
  return std::make_unique<GuardedServer<httplib::SSLServer>>(
      limits, https->cert.c_str(), https->key.c_str(),
      https->client_ca.empty() ? nullptr : https->client_ca.c_str());
}

void CloseConnectionAfterResponse() { close_requested = true; }

}  // namespace recog::server
