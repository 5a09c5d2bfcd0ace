#include "server/http/guarded_http_server.h"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <poll.h>
#include <strings.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cctype>
#include <condition_variable>
#include <deque>
#include <functional>
#include <list>
#include <mutex>
#include <optional>
#include <string_view>
#include <thread>
#include <type_traits>
#include <utility>
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
// How long a connection that finds every thread busy and none to evict waits for one to finish
// before it is refused (the accepting thread waits with it, so it stays short).
constexpr auto kWaitForThread = std::chrono::milliseconds(100);
constexpr size_t kLingerBytes = 1 << 20;
// The time a request or response has before the minimum rate applies.
constexpr auto kGrace = std::chrono::seconds(1);
constexpr size_t kReceiveChunk = 16384;

// One of the guard's own answers: {"code", "message"} JSON, closing the connection.
std::string GuardAnswer(int status, const char* reason, const char* code,
                        const std::string& message, const HeaderList& headers) {
  std::string body = std::string(R"({"code":")") + code + R"(","message":")" + message + "\"}";
  std::string answer = "HTTP/1.1 " + std::to_string(status) + " " + reason +
                       "\r\nContent-Type: application/json\r\nCache-Control: no-store\r\n";
  if (status == 503) answer += "Retry-After: 1\r\n";
  for (const auto& [name, value] : headers) answer += name + ": " + value + "\r\n";
  return answer + "Connection: close\r\nContent-Length: " + std::to_string(body.size()) +
         "\r\n\r\n" + body;
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

// The connections being served, by client address, and which of them wait for a request's
// headers (since when): the candidates for eviction when a new connection finds no place.
class ConnectionTable {
 public:
  struct Entry {
    int fd;
    std::string client;
    Clock::time_point waiting_since;
    bool awaiting_head = true;
    bool evicted = false;
  };
  using Handle = std::list<Entry>::iterator;

  // Registers the connection `fd` of `client`, evicting one of that client's when it already has
  // `max` (not evicted) connections; nullopt when it has and none can be evicted.
  std::optional<Handle> Admit(int fd, const std::string& client, size_t max) {
    std::lock_guard lock(mutex_);
    const size_t open = size_t(std::count_if(entries_.begin(), entries_.end(), [&](const Entry& e) {
      return !e.evicted && e.client == client;
    }));
    if (open >= max && !EvictLongestWaiting(&client)) return std::nullopt;
    entries_.push_front(Entry{fd, client, Clock::now(), true, false});
    return entries_.begin();
  }

  // Evicts the connection (of any client) that has waited longest for its request's headers;
  // false when none waits.
  bool EvictOne() {
    std::lock_guard lock(mutex_);
    return EvictLongestWaiting(nullptr);
  }

  // The connection now waits for a request's headers (from now on), or no longer does. False
  // when it was evicted: it must close.
  bool SetAwaitingHead(Handle entry, bool awaiting) {
    std::lock_guard lock(mutex_);
    entry->awaiting_head = awaiting;
    if (awaiting) entry->waiting_since = Clock::now();
    return !entry->evicted;
  }

  bool Evicted(Handle entry) {
    std::lock_guard lock(mutex_);
    return entry->evicted;
  }

  // Before its socket is closed.
  void Remove(Handle entry) {
    std::lock_guard lock(mutex_);
    entries_.erase(entry);
  }

 private:
  // Under mutex_: marks the candidate evicted and wakes its thread (its socket reads end). A
  // connection with bytes in its socket that its thread has not read yet (on a busy machine, a
  // request that came right after its connection may wait there) waits for the server, not for
  // its client: it is no candidate.
  bool EvictLongestWaiting(const std::string* client) {
    Entry* oldest = nullptr;
    for (Entry& entry : entries_) {
      if (entry.evicted || !entry.awaiting_head) continue;
      if (client != nullptr && entry.client != *client) continue;
      if (int unread = 0; ioctl(entry.fd, FIONREAD, &unread) == 0 && unread > 0) continue;
      if (oldest == nullptr || entry.waiting_since < oldest->waiting_since) oldest = &entry;
    }
    if (oldest == nullptr) return false;
    oldest->evicted = true;
    shutdown(oldest->fd, SHUT_RD);
    return true;
  }

  std::mutex mutex_;
  std::list<Entry> entries_;
};

// A thread per connection, up to a fixed number. A connection that finds every thread busy
// evicts one that waits for its request's headers (`evict`) and queues for its thread, which is
// free a moment later; when none can be evicted it is run at once on the accepting thread, marked
// over capacity, so that it is refused there instead of queueing behind slow clients.
class CappedTaskQueue final : public httplib::TaskQueue {
 public:
  CappedTaskQueue(size_t threads, std::function<bool()> evict) : evict_(std::move(evict)) {
    for (size_t i = 0; i < threads; ++i) threads_.emplace_back([this] { Work(); });
  }

  void enqueue(std::function<void()> task) override {
    {
      std::unique_lock lock(mutex_);
      // An evicted connection's thread is free a moment later: the task waits for it. A thread
      // finishing with a connection (closing, lingering after a refusal) is waited for a little.
      const auto place = [this] { return tasks_.size() + busy_ < threads_.size() || evict_(); };
      if (place() || freed_.wait_for(lock, kWaitForThread, place)) {
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
      freed_.notify_one();
    }
  }

  std::function<bool()> evict_;
  std::mutex mutex_;
  std::condition_variable wake_;
  std::condition_variable freed_;  // a thread finished its task
  std::deque<std::function<void()>> tasks_;
  size_t busy_ = 0;
  bool stopping_ = false;
  std::vector<std::thread> threads_;
};

// Whether `c` may be part of a header name (RFC 9110's token).
bool IsTokenCharacter(unsigned char c) {
  return std::isalnum(c) ||
         std::string_view("!#$%&'*+-.^_`|~").find(char(c)) != std::string_view::npos;
}

bool IsDigits(std::string_view text) {
  return !text.empty() && text.size() <= 18 &&
         std::all_of(text.begin(), text.end(), [](char c) { return c >= '0' && c <= '9'; });
}

// How reading a request's head ended.
enum class Head { kComplete, kClosed, kTimedOut, kTooLarge, kMalformed };

// One connection, plain or TLS, as cpp-httplib's Stream: a non-blocking socket whose reads must
// finish before the request's deadline and whose writes before the response's, each at the
// minimum rate. The request's head is read first (ReadHead), whole, into a buffer that reads
// then serve.
class ConnectionStream final : public httplib::Stream {
 public:
  ConnectionStream(int fd, SSL* ssl, const ConnectionLimits& limits, std::function<bool()> running)
      : fd_(fd), ssl_(ssl), limits_(limits), running_(std::move(running)) {
    fcntl(fd_, F_SETFL, fcntl(fd_, F_GETFL, 0) | O_NONBLOCK);
  }

  // A new exchange: its request must be read before `read_deadline`; its response, once begun,
  // must be sent within the request timeout.
  void StartExchange(Clock::time_point read_deadline) {
    pending_.erase(0, begin_);
    begin_ = 0;
    read_start_ = Clock::now();
    read_deadline_ = read_deadline;
    read_bytes_ = 0;
    write_start_.reset();
    write_bytes_ = 0;
    headers_.clear();
  }

  // The TLS handshake (nothing for a plain connection), before the read deadline.
  bool Handshake() {
    if (ssl_ == nullptr) return true;
    while (true) {
      ERR_clear_error();
      const int done = SSL_accept(ssl_);
      if (done == 1) return true;
      const int error = SSL_get_error(ssl_, done);
      if (error == SSL_ERROR_WANT_READ) {
        if (!Wait(POLLIN, read_deadline_)) return false;
      } else if (error == SSL_ERROR_WANT_WRITE) {
        if (!Wait(POLLOUT, read_deadline_)) return false;
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

  // Reads the request line and headers (into the buffer that read() serves) before `deadline`
  // and at the minimum rate, within the limits; the header lines are then headers().
  Head ReadHead(Clock::time_point deadline) {
    size_t line_start = begin_, scanned = begin_, header_lines = 0;
    bool request_line = true;
    while (true) {
      for (size_t end; (end = pending_.find('\n', scanned)) != std::string::npos;) {
        if (end + 1 - begin_ > limits_.max_header_bytes) return Head::kTooLarge;
        const std::string_view line(pending_.data() + line_start, end - line_start);
        scanned = line_start = end + 1;
        if (line.empty() || line.back() != '\r') return Head::kMalformed;  // a bare LF
        if (std::exchange(request_line, false)) continue;
        if (line.size() == 1) return CheckFraming();  // the blank line that ends the head
        if (++header_lines > limits_.max_header_lines) return Head::kTooLarge;
        if (!AddHeader(line.substr(0, line.size() - 1))) return Head::kMalformed;
      }
      scanned = pending_.size();
      if (pending_.size() - begin_ > limits_.max_header_bytes) return Head::kTooLarge;
      const size_t had = pending_.size();
      pending_.resize(had + kReceiveChunk);
      const ssize_t got = Receive(pending_.data() + had, kReceiveChunk, deadline);
      pending_.resize(had + size_t(std::max<ssize_t>(got, 0)));
      if (got == 0) return Head::kClosed;
      if (got < 0) return had == begin_ ? Head::kClosed : Head::kTimedOut;
    }
  }

  // The header lines of the request ReadHead read, as the client sent them.
  const HeaderList& headers() const { return headers_; }

  bool is_readable() const override {
    auto* self = const_cast<ConnectionStream*>(this);
    return Buffered() || self->Wait(POLLIN, self->ReadDeadline(read_deadline_));
  }
  bool is_writable() const override {
    auto* self = const_cast<ConnectionStream*>(this);
    return self->Wait(POLLOUT, self->WriteDeadline());
  }

  ssize_t read(char* out, size_t size) override {
    if (begin_ < pending_.size()) {
      const size_t n = std::min(size, pending_.size() - begin_);
      std::copy_n(pending_.data() + begin_, n, out);
      begin_ += n;
      return ssize_t(n);
    }
    return Receive(out, size, read_deadline_);
  }

  ssize_t write(const char* data, size_t size) override {
    ssize_t sent = 0;
    while (true) {
      short want = POLLOUT;
      if (ssl_ != nullptr) {
        ERR_clear_error();
        sent = SSL_write(ssl_, data, int(std::min<size_t>(size, INT32_MAX)));
        if (sent > 0) break;
        const int error = SSL_get_error(ssl_, int(sent));
        if (error == SSL_ERROR_WANT_READ) {
          want = POLLIN;
        } else if (error != SSL_ERROR_WANT_WRITE) {
          return -1;
        }
      } else {
        sent = send(fd_, data, size, MSG_NOSIGNAL);
        if (sent >= 0) break;
        if (errno == EINTR) continue;
        if (errno != EAGAIN && errno != EWOULDBLOCK) return -1;
      }
      if (!Wait(want, WriteDeadline())) return -1;
    }
    write_bytes_ += size_t(sent);
    return sent;
  }

  void get_remote_ip_and_port(std::string& ip, int& port) const override {
    SocketAddress(fd_, true, &ip, &port);
  }
  void get_local_ip_and_port(std::string& ip, int& port) const override {
    SocketAddress(fd_, false, &ip, &port);
  }
  socket_t socket() const override { return fd_; }

 private:
  bool Buffered() const {
    return begin_ < pending_.size() || (ssl_ != nullptr && SSL_pending(ssl_) > 0);
  }

  // `deadline`, or earlier when the bytes moved so far (`bytes` since `start`) fall short of the
  // minimum rate.
  Clock::time_point AtRate(Clock::time_point deadline, Clock::time_point start,
                           size_t bytes) const {
    if (limits_.min_bytes_per_second == 0) return deadline;
    const auto earned = std::chrono::milliseconds(bytes * 1000 / limits_.min_bytes_per_second);
    return std::min(deadline, start + kGrace + earned);
  }
  Clock::time_point ReadDeadline(Clock::time_point deadline) const {
    return AtRate(deadline, read_start_, read_bytes_);
  }
  // The response's deadline: the request timeout from its first write on, at the minimum rate.
  Clock::time_point WriteDeadline() {
    if (!write_start_) write_start_ = Clock::now();
    return AtRate(*write_start_ + limits_.request_timeout, *write_start_, write_bytes_);
  }

  // Checks a header line (without its CRLF) and keeps it; false when malformed.
  bool AddHeader(std::string_view line) {
    const size_t colon = line.find(':');
    if (colon == 0 || colon == std::string_view::npos) return false;
    const std::string_view name = line.substr(0, colon);
    if (!std::all_of(name.begin(), name.end(),
                     [](char c) { return IsTokenCharacter(static_cast<unsigned char>(c)); })) {
      return false;  // a space before the colon, a folded line, a control byte
    }
    std::string_view value = line.substr(colon + 1);
    while (!value.empty() && (value.front() == ' ' || value.front() == '\t'))
      value.remove_prefix(1);
    while (!value.empty() && (value.back() == ' ' || value.back() == '\t')) value.remove_suffix(1);
    if (std::any_of(value.begin(), value.end(), [](char c) {
          return (static_cast<unsigned char>(c) < 0x20 && c != '\t') || c == 0x7F;
        })) {
      return false;
    }
    headers_.emplace_back(std::string(name), std::string(value));
    return true;
  }

  // A complete head whose body framing is unambiguous: at most one Content-Length, of digits.
  Head CheckFraming() const {
    size_t lengths = 0;
    for (const auto& [name, value] : headers_) {
      if (strcasecmp(name.c_str(), "Content-Length") != 0) continue;
      if (++lengths > 1 || !IsDigits(value)) return Head::kMalformed;
    }
    return Head::kComplete;
  }

  // Up to `size` bytes before `deadline` (and at the minimum rate): > 0 read, 0 the peer closed,
  // -1 error or late.
  ssize_t Receive(char* out, size_t size, Clock::time_point deadline) {
    while (true) {
      short want = POLLIN;
      ssize_t got = 0;
      if (ssl_ != nullptr) {
        ERR_clear_error();
        const int n = SSL_read(ssl_, out, int(std::min<size_t>(size, INT32_MAX)));
        if (n > 0) {
          got = n;
        } else {
          const int error = SSL_get_error(ssl_, n);
          if (error == SSL_ERROR_ZERO_RETURN) return 0;
          if (error == SSL_ERROR_WANT_WRITE) {
            want = POLLOUT;
          } else if (error != SSL_ERROR_WANT_READ) {
            return -1;
          }
        }
      } else {
        got = recv(fd_, out, size, 0);
        if (got == 0) return 0;
        if (got < 0) {
          if (errno == EINTR) continue;
          if (errno != EAGAIN && errno != EWOULDBLOCK) return -1;
          got = 0;
        }
      }
      if (got > 0) {
        read_bytes_ += size_t(got);
        return got;
      }
      if (!Wait(want, ReadDeadline(deadline))) return -1;
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
  const ConnectionLimits& limits_;
  std::function<bool()> running_;
  Clock::time_point read_start_ = Clock::now();
  Clock::time_point read_deadline_ = Clock::now();
  size_t read_bytes_ = 0;
  std::optional<Clock::time_point> write_start_;
  size_t write_bytes_ = 0;
  std::string pending_;  // received, not yet read from begin_ on
  size_t begin_ = 0;
  HeaderList headers_;
};

// cpp-httplib's handling of one request, with the stream its head was read from.
using ProcessRequest = std::function<bool(ConnectionStream&, bool last, bool& closed)>;

// What both servers share: the limits, the connection table and the life of a connection.
class ConnectionGuard {
 public:
  ConnectionGuard(const ConnectionLimits& limits, HeaderList answer_headers)
      : limits_(limits), answer_headers_(std::move(answer_headers)) {}

  const ConnectionLimits& limits() const { return limits_; }
  bool EvictOne() { return table_.EvictOne(); }

  // Serves the accepted socket `fd` until the client is done, a limit ends it or `running` turns
  // false; `process` is the server's own handling of one request. Closes `fd`.
  void Serve(int fd, SSL_CTX* tls, const std::function<bool()>& running,
             const ProcessRequest& process) {
    std::string client;
    int port = 0;
    SocketAddress(fd, true, &client, &port);
    // Beyond a cap, the connection is refused at once: it must not hold a thread.
    const std::optional<ConnectionTable::Handle> entry =
        over_capacity ? std::nullopt : table_.Admit(fd, client, limits_.max_connections_per_client);
    if (!entry.has_value()) {
      Refuse(fd, tls != nullptr);
      return;
    }
    bool unread = false;  // whether the client may still be sending when we close
    SSL* ssl = tls != nullptr ? SSL_new(tls) : nullptr;
    if (tls == nullptr || (ssl != nullptr && SSL_set_fd(ssl, fd) == 1)) {
      ConnectionStream stream(fd, ssl, limits_, running);
      stream.StartExchange(Clock::now() + limits_.request_timeout);
      if (stream.Handshake()) unread = ServeRequests(stream, *entry, running, process);
    }
    if (ssl != nullptr) {
      SSL_shutdown(ssl);  // one non-blocking attempt at a clean close
      SSL_free(ssl);
    }
    const bool evicted = table_.Evicted(*entry);
    table_.Remove(*entry);
    if (unread && !evicted) Linger(fd);
    Close(fd);
  }

 private:
  // The connection's requests, until it ends; true when it ended in the middle of a request
  // (the client may still be sending).
  bool ServeRequests(ConnectionStream& stream, ConnectionTable::Handle entry,
                     const std::function<bool()>& running, const ProcessRequest& process) {
    for (size_t left = limits_.max_requests_per_connection; left > 0 && running(); --left) {
      if (!table_.SetAwaitingHead(entry, true)) return false;
      if (!stream.WaitForRequest(limits_.idle_timeout)) return false;
      const Clock::time_point start = Clock::now();
      stream.StartExchange(start + limits_.request_timeout);
      const Head head =
          stream.ReadHead(start + std::min(limits_.header_timeout, limits_.request_timeout));
      if (!table_.SetAwaitingHead(entry, false)) return false;  // evicted meanwhile
      if (head != Head::kComplete) return RefuseHead(stream, head);
      close_requested = false;
      bool closed = false;
      const bool ok = process(stream, left == 1, closed);
      if (!ok || close_requested) return true;
      if (closed) return false;
    }
    return false;
  }

  // Answers a head that could not be read whole (nothing when the client closed); true when the
  // client may still be sending.
  bool RefuseHead(ConnectionStream& stream, Head head) const {
    std::string answer;
    switch (head) {
      case Head::kTooLarge:
        answer =
            GuardAnswer(431, "Request Header Fields Too Large", "RESOURCE_EXHAUSTED",
                        "the request's headers exceed " + std::to_string(limits_.max_header_lines) +
                            " lines or " + std::to_string(limits_.max_header_bytes) + " bytes",
                        answer_headers_);
        break;
      case Head::kMalformed:
        answer = GuardAnswer(400, "Bad Request", "INVALID_ARGUMENT",
                             "the request's head is malformed (lines must end in CRLF, header "
                             "names be tokens, a Content-Length one number of digits)",
                             answer_headers_);
        break;
      case Head::kTimedOut:
        answer = GuardAnswer(408, "Request Timeout", "DEADLINE_EXCEEDED",
                             "the request's headers did not arrive in time", answer_headers_);
        break;
      default:
        return false;
    }
    [[maybe_unused]] const ssize_t sent = stream.write(answer.data(), answer.size());
    return true;
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
  void Refuse(int fd, bool tls) const {
    if (!tls) {
      char sink[16384];
      while (recv(fd, sink, sizeof(sink), MSG_DONTWAIT) > 0) {
      }  // what the request sent so far, so that the close does not reset the connection
      const std::string refusal =
          GuardAnswer(503, "Service Unavailable", "UNAVAILABLE",
                      "the server serves too many connections; retry later", answer_headers_);
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
  HeaderList answer_headers_;
  ConnectionTable table_;
};

// Gives `request` the headers its client sent (ReadHead's, not percent-decoded) and the
// addresses cpp-httplib adds, and drops a Range of several ranges or one that was encoded.
void UseHeadersAsSent(const HeaderList& sent, httplib::Request& request) {
  const auto is_added = [](const std::string& name) {
    for (const char* added : {"REMOTE_ADDR", "REMOTE_PORT", "LOCAL_ADDR", "LOCAL_PORT"}) {
      if (strcasecmp(name.c_str(), added) == 0) return true;
    }
    return false;
  };
  httplib::Headers headers;
  for (const auto& [name, value] : sent) {
    if (!is_added(name)) headers.emplace(name, value);
  }
  headers.emplace("REMOTE_ADDR", request.remote_addr);
  headers.emplace("REMOTE_PORT", std::to_string(request.remote_port));
  headers.emplace("LOCAL_ADDR", request.local_addr);
  headers.emplace("LOCAL_PORT", std::to_string(request.local_port));
  request.headers = std::move(headers);
  if (request.ranges.size() > 1 ||
      request.get_header_value("Range").find('%') != std::string::npos) {
    request.ranges.clear();
  }
}

// What HttpPort asks of a guarded server once it is bound.
class Backlog {
 public:
  virtual ~Backlog() = default;
  // Lets the kernel queue SOMAXCONN connections for accept (cpp-httplib asks for 5: a burst of
  // connections would have the next ones' SYNs dropped, and retried only a second later).
  virtual void Widen() = 0;
};

// httplib's Server or SSLServer, each connection served by a ConnectionGuard.
template <class Base>
class GuardedServer final : public Base, public Backlog {
 public:
  template <class... Args>
  GuardedServer(const ConnectionLimits& limits, HeaderList answer_headers, Args&&... args)
      : Base(std::forward<Args>(args)...),
        guard_(std::make_unique<ConnectionGuard>(limits, std::move(answer_headers))) {
    this->new_task_queue = [threads = limits.max_connections, guard = guard_.get()] {
      return new CappedTaskQueue(threads, [guard] { return guard->EvictOne(); });
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
        [this](ConnectionStream& stream, bool last, bool& closed) {
          return this->process_request(stream, last, closed, [&stream](httplib::Request& request) {
            UseHeadersAsSent(stream.headers(), request);
          });
        });
    return true;
  }

  void Widen() override { ::listen(this->svr_sock_, SOMAXCONN); }

  std::unique_ptr<ConnectionGuard> guard_;
};

}  // namespace

std::unique_ptr<httplib::Server> MakeGuardedHttpServer(const ConnectionLimits& limits,
                                                       const HttpsFiles* https,
                                                       HeaderList answer_headers) {
  if (https == nullptr) {
    return std::make_unique<GuardedServer<httplib::Server>>(limits, std::move(answer_headers));
  }
  return std::make_unique<GuardedServer<httplib::SSLServer>>(
      limits, std::move(answer_headers), https->cert.c_str(), https->key.c_str(),
      https->client_ca.empty() ? nullptr : https->client_ca.c_str());
}

ConnectionLimits LimitsOf(const HttpPortConfig& config) {
  return {.max_connections = config.max_connections,
          .max_connections_per_client = config.max_connections_per_client,
          .request_timeout = std::chrono::milliseconds(config.request_timeout_ms),
          .header_timeout = std::chrono::milliseconds(config.header_timeout_ms),
          .min_bytes_per_second = config.min_bytes_per_s,
          .max_header_lines = config.max_header_lines,
          .max_header_bytes = config.max_header_bytes};
}

void CloseConnectionAfterResponse() { close_requested = true; }

bool SplitHostPort(const std::string& address, std::string* host, int* port) {
  const size_t colon = address.rfind(':');
  if (colon == std::string::npos || colon == 0 || colon + 1 == address.size()) return false;
  *host = address.substr(0, colon);
  if (host->front() == '[' && host->back() == ']') *host = host->substr(1, host->size() - 2);
  const std::string digits = address.substr(colon + 1);
  if (!IsDigits(digits) || digits.size() > 5) return false;
  *port = std::stoi(digits);
  return *port <= 65535;
}

struct HttpPort::Thread {
  std::thread thread;
  std::atomic<bool> stopped{false};  // the thread has left listen_after_bind
};

StatusOr<std::unique_ptr<HttpPort>> HttpPort::Listen(std::unique_ptr<httplib::Server> server,
                                                     const std::string& listen,
                                                     const std::string& what) {
  std::unique_ptr<HttpPort> port(new HttpPort());
  int wanted = 0;
  if (!SplitHostPort(listen, &port->host_, &wanted)) {
    return Status::InvalidArgument(what + ": '" + listen + "' is not host:port");
  }
  port->port_ = wanted == 0 ? server->bind_to_any_port(port->host_) : wanted;
  if (port->port_ <= 0 || (wanted != 0 && !server->bind_to_port(port->host_, wanted))) {
    return Status::Unavailable(what + " cannot listen on " + listen +
                               " (address in use, or not an address of this machine)");
  }
  if (auto* backlog = dynamic_cast<Backlog*>(server.get())) backlog->Widen();
  port->server_ = std::move(server);
  port->thread_ = std::make_unique<Thread>();
  port->thread_->thread = std::thread([http = port->server_.get(), thread = port->thread_.get()] {
    http->listen_after_bind();
    thread->stopped = true;
  });
  return port;
}

HttpPort::~HttpPort() {
  if (thread_ == nullptr) return;
  // stop() reaches the listening thread only once it listens: until it has stopped, ask again.
  while (!thread_->stopped) {
    server_->stop();
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  thread_->thread.join();
}

}  // namespace recog::server
