#include "server/app/grpc_listener.h"

#include <fcntl.h>
#include <netdb.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/eventfd.h>
#include <sys/resource.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

#include <grpcpp/server_builder.h>
#include <spdlog/spdlog.h>

namespace recog::server {
namespace {

constexpr char kUnixPrefix[] = "unix:";
constexpr int kBacklog = 1024;
constexpr auto kWarningInterval = std::chrono::seconds(10);

// The host and port of "host:port" or "[v6]:port"; false when malformed.
bool SplitHostPort(const std::string& address, std::string* host, std::string* port) {
  const size_t colon = address.rfind(':');
  if (colon == std::string::npos || colon + 1 == address.size()) return false;
  *host = address.substr(0, colon);
  *port = address.substr(colon + 1);
  if (host->size() >= 2 && host->front() == '[' && host->back() == ']') {
    *host = host->substr(1, host->size() - 2);
  }
  return !host->empty();
}

// The process's descriptor limit (RLIMIT_NOFILE, soft).
uint64_t DescriptorLimit() {
  rlimit limit{};
  if (getrlimit(RLIMIT_NOFILE, &limit) != 0 || limit.rlim_cur == RLIM_INFINITY) return 1 << 20;
  return limit.rlim_cur;
}

Status Unavailable(const std::string& address, const std::string& why) {
  return Status::Unavailable("cannot listen on " + address + ": " + why);
}

}  // namespace

StatusOr<std::unique_ptr<GrpcListener>> GrpcListener::Bind(const Options& options) {
  const uint64_t limit = DescriptorLimit();
  if (limit <= options.reserve_descriptors + 16) {
    return Status::InvalidArgument(
        "the process may open " + std::to_string(limit) + " descriptors, too few to keep " +
        std::to_string(options.reserve_descriptors) + " in reserve (grpc.reserve_descriptors)");
  }
  std::unique_ptr<GrpcListener> listener(new GrpcListener(options));
  const std::string& address = options.address;
  if (address.rfind(kUnixPrefix, 0) == 0) {
    sockaddr_un name{};
    const std::string path = address.substr(sizeof(kUnixPrefix) - 1);
    if (path.empty() || path.size() >= sizeof(name.sun_path)) {
      return Unavailable(address, "the socket path is empty or too long");
    }
    name.sun_family = AF_UNIX;
    std::memcpy(name.sun_path, path.data(), path.size());
    struct stat existing {};
    if (lstat(path.c_str(), &existing) == 0 && S_ISSOCK(existing.st_mode)) unlink(path.c_str());
    const int fd = socket(AF_UNIX, SOCK_STREAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
    if (fd < 0) return Unavailable(address, std::strerror(errno));
    listener->sockets_.push_back(fd);
    if (bind(fd, reinterpret_cast<const sockaddr*>(&name), sizeof(name)) != 0 ||
        listen(fd, kBacklog) != 0) {
      return Unavailable(address, std::strerror(errno));
    }
    listener->unix_path_ = path;
  } else {
    std::string host, port;
    if (!SplitHostPort(address, &host, &port)) return Unavailable(address, "not host:port");
    addrinfo hints{};
    hints.ai_family = AF_UNSPEC;
    hints.ai_socktype = SOCK_STREAM;
    hints.ai_flags = AI_PASSIVE | AI_NUMERICSERV;
    addrinfo* found = nullptr;
    if (const int error = getaddrinfo(host.c_str(), port.c_str(), &hints, &found); error != 0) {
      return Unavailable(address, gai_strerror(error));
    }
    const std::unique_ptr<addrinfo, decltype(&freeaddrinfo)> addresses(found, freeaddrinfo);
    for (const addrinfo* a = found; a != nullptr; a = a->ai_next) {
      const int fd = socket(a->ai_family, a->ai_socktype | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
      if (fd < 0) return Unavailable(address, std::strerror(errno));
      listener->sockets_.push_back(fd);
      const int on = 1;
      setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &on, sizeof(on));  // not SO_REUSEPORT: one owner
      if (a->ai_family == AF_INET6) setsockopt(fd, IPPROTO_IPV6, IPV6_V6ONLY, &on, sizeof(on));
      // Port 0 on several addresses ("localhost"): the first pick is taken for the others.
      sockaddr_storage bound{};
      std::memcpy(&bound, a->ai_addr, a->ai_addrlen);
      if (listener->port_ != 0) {
        const uint16_t net_port = htons(uint16_t(listener->port_));
        if (a->ai_family == AF_INET) reinterpret_cast<sockaddr_in*>(&bound)->sin_port = net_port;
        if (a->ai_family == AF_INET6) reinterpret_cast<sockaddr_in6*>(&bound)->sin6_port = net_port;
      }
      if (bind(fd, reinterpret_cast<const sockaddr*>(&bound), a->ai_addrlen) != 0 ||
          listen(fd, kBacklog) != 0) {
        return Unavailable(address, std::strerror(errno));
      }
      sockaddr_storage name{};
      socklen_t length = sizeof(name);
      getsockname(fd, reinterpret_cast<sockaddr*>(&name), &length);
      listener->port_ =
          ntohs(name.ss_family == AF_INET6 ? reinterpret_cast<const sockaddr_in6*>(&name)->sin6_port
                                           : reinterpret_cast<const sockaddr_in*>(&name)->sin_port);
    }
    if (listener->sockets_.empty()) return Unavailable(address, "no address to listen on");
  }
  listener->wake_ = eventfd(0, EFD_CLOEXEC | EFD_NONBLOCK);
  listener->spare_ = open("/dev/null", O_RDONLY | O_CLOEXEC);
  if (listener->wake_ < 0 || listener->spare_ < 0) {
    return Unavailable(address, std::string("no descriptor left: ") + std::strerror(errno));
  }
  return listener;
}

GrpcListener::~GrpcListener() {
  if (thread_.joinable()) {
    stopping_ = true;
    const uint64_t one = 1;
    [[maybe_unused]] const ssize_t written = write(wake_, &one, sizeof(one));
    thread_.join();
  }
  for (const int fd : sockets_) close(fd);
  if (!unix_path_.empty()) unlink(unix_path_.c_str());
  if (wake_ >= 0) close(wake_);
  if (spare_ >= 0) close(spare_);
}

void GrpcListener::Start(grpc::experimental::ExternalConnectionAcceptor* acceptor) {
  thread_ = std::thread([this, acceptor] { AcceptLoop(acceptor); });
}

void GrpcListener::AcceptLoop(grpc::experimental::ExternalConnectionAcceptor* acceptor) {
  std::vector<pollfd> watched;
  for (const int fd : sockets_) watched.push_back({fd, POLLIN, 0});
  watched.push_back({wake_, POLLIN, 0});
  while (!stopping_.load()) {
    if (poll(watched.data(), watched.size(), -1) < 0 && errno != EINTR) {
      spdlog::error("gRPC listener: poll failed: {}", std::strerror(errno));
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
      continue;
    }
    for (size_t i = 0; i + 1 < watched.size(); ++i) {
      if ((watched[i].revents & POLLIN) == 0) continue;
      // A bounded batch per wake, so that one busy socket does not starve the others.
      for (int n = 0; n < 64 && !stopping_.load() && AcceptOne(watched[i].fd, acceptor); ++n) {
      }
    }
  }
}

bool GrpcListener::AcceptOne(int listener,
                             grpc::experimental::ExternalConnectionAcceptor* acceptor) {
  int fd = accept4(listener, nullptr, nullptr, SOCK_NONBLOCK | SOCK_CLOEXEC);
  if (fd < 0) {
    if (errno == EMFILE || errno == ENFILE) {
      // Give up the spare to take the waiting connection off the backlog, then close it.
      close(spare_);
      fd = accept4(listener, nullptr, nullptr, SOCK_CLOEXEC);
      if (fd >= 0) Refuse(fd, "no descriptor left");
      spare_ = open("/dev/null", O_RDONLY | O_CLOEXEC);
      if (fd < 0) {  // even the spare did not do: wait for descriptors to come back
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
        return false;
      }
      return true;
    }
    if (errno == EAGAIN || errno == EWOULDBLOCK) return false;  // nothing waiting
    if (errno == ECONNABORTED || errno == EINTR) return true;   // that client is gone: the next
    spdlog::error("gRPC listener: accept failed: {}", std::strerror(errno));
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    return false;
  }
  if (uint64_t(fd) + options_.reserve_descriptors >= DescriptorLimit()) {
    Refuse(fd, "descriptors low");
    return true;
  }
  if (unix_path_.empty()) {
    const int on = 1;
    setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &on, sizeof(on));
  }
  grpc::experimental::ExternalConnectionAcceptor::NewConnectionParameters connection;
  connection.listener_fd = listener;
  connection.fd = fd;
  acceptor->HandleNewConnection(&connection);  // gRPC owns fd from here
  return true;
}

void GrpcListener::Refuse(int fd, const char* why) {
  close(fd);
  refused_.fetch_add(1);
  ++refused_since_warning_;
  const auto now = std::chrono::steady_clock::now();
  if (now - last_warning_ < kWarningInterval) return;
  spdlog::warn(
      "gRPC listener: {} connection(s) closed at once ({}: the process may open {} descriptors, "
      "{} kept in reserve)",
      refused_since_warning_, why, DescriptorLimit(), options_.reserve_descriptors);
  last_warning_ = now;
  refused_since_warning_ = 0;
}

}  // namespace recog::server
