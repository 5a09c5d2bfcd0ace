#include "server/app/grpc_guards.h"

#include <atomic>
#include <chrono>
#include <mutex>
#include <string>
#include <string_view>
#include <unordered_map>

#include <google/protobuf/stubs/logging.h>
#include <grpc/support/log.h>
#include <spdlog/spdlog.h>

#include "core/common/text.h"

namespace recog::server {
namespace {

using grpc::experimental::InterceptionHookPoints;

constexpr std::string_view kReflectionPrefix = "/grpc.reflection.";
constexpr auto kLibraryLogInterval = std::chrono::seconds(10);

// Cancels a reflection call whose `authorization` does not authenticate.
class ReflectionGuard final : public grpc::experimental::Interceptor {
 public:
  ReflectionGuard(const TokenAuthenticator* auth, grpc::experimental::ServerRpcInfo* info)
      : auth_(auth), info_(info) {}

  void Intercept(grpc::experimental::InterceptorBatchMethods* methods) override {
    if (methods->QueryInterceptionHookPoint(InterceptionHookPoints::POST_RECV_INITIAL_METADATA)) {
      const std::multimap<grpc::string_ref, grpc::string_ref>* metadata =
          methods->GetRecvInitialMetadata();
      std::string_view header;
      if (const auto it = metadata->find("authorization"); it != metadata->end()) {
        header = {it->second.data(), it->second.size()};
      }
      if (!auth_->Authenticate(header).ok()) {
        spdlog::info("server reflection refused: no valid token");
        info_->server_context()->TryCancel();
      }
    }
    methods->Proceed();
  }

 private:
  const TokenAuthenticator* const auth_;
  grpc::experimental::ServerRpcInfo* const info_;
};

class ReflectionGuardFactory final : public grpc::experimental::ServerInterceptorFactoryInterface {
 public:
  explicit ReflectionGuardFactory(const TokenAuthenticator* auth) : auth_(auth) {}

  grpc::experimental::Interceptor* CreateServerInterceptor(
      grpc::experimental::ServerRpcInfo* info) override {
    const bool reflection = info->method() != nullptr &&
                            std::string_view(info->method()).starts_with(kReflectionPrefix);
    // gRPC skips a null interceptor: every other call goes on untouched.
    return reflection && !auth_->allows_all() ? new ReflectionGuard(auth_, info) : nullptr;
  }

 private:
  const TokenAuthenticator* const auth_;
};

// One line per place in the libraries' code (file:line) at most every kLibraryLogInterval; the
// places are finitely many, so the table stays small.
class LibraryLogThrottle {
 public:
  // Whether the line from `file`:`line` is written now; `suppressed` says how many from there were
  // not since the last one written.
  bool Admit(const char* file, int line, uint64_t* suppressed) {
    std::lock_guard lock(mutex_);
    Site& site = sites_[std::string(file != nullptr ? file : "?") + ':' + std::to_string(line)];
    const auto now = std::chrono::steady_clock::now();
    if (site.written && now - site.last < kLibraryLogInterval) {
      ++site.suppressed;
      return false;
    }
    *suppressed = site.suppressed;
    site = {true, now, 0};
    return true;
  }

 private:
  struct Site {
    bool written = false;
    std::chrono::steady_clock::time_point last{};
    uint64_t suppressed = 0;
  };
  std::mutex mutex_;
  std::unordered_map<std::string, Site> sites_;
};

LibraryLogThrottle& Throttle() {
  static LibraryLogThrottle throttle;
  return throttle;
}

void WriteLibraryLine(spdlog::level::level_enum level, const char* library, const char* file,
                      int line, std::string_view message) {
  uint64_t suppressed = 0;
  if (!Throttle().Admit(file, line, &suppressed)) return;
  spdlog::log(level, "{} {}:{}: {} ({} lines from there in the last {} s not shown)", library,
              file != nullptr ? file : "?", line, EscapeForLog(message, 512), suppressed,
              kLibraryLogInterval.count());
}

void LogProtobufLine(google::protobuf::LogLevel level, const char* file, int line,
                     const std::string& message) {
  if (level == google::protobuf::LOGLEVEL_FATAL) {  // libprotobuf aborts after it: say why
    spdlog::critical("libprotobuf {}:{}: {}", file, line, EscapeForLog(message, 1024));
    return;
  }
  WriteLibraryLine(
      level == google::protobuf::LOGLEVEL_INFO ? spdlog::level::info : spdlog::level::warn,
      "libprotobuf", file, line, message);
}

void LogGrpcLine(gpr_log_func_args* args) {
  const spdlog::level::level_enum level =
      args->severity == GPR_LOG_SEVERITY_ERROR  ? spdlog::level::err
      : args->severity == GPR_LOG_SEVERITY_INFO ? spdlog::level::info
                                                : spdlog::level::debug;
  WriteLibraryLine(level, "grpc", args->file, args->line,
                   args->message != nullptr ? args->message : "");
}

}  // namespace

std::unique_ptr<grpc::experimental::ServerInterceptorFactoryInterface> MakeReflectionGuardFactory(
    const TokenAuthenticator* auth) {
  return std::make_unique<ReflectionGuardFactory>(auth);
}

void ThrottleLibraryLogs() {
  google::protobuf::SetLogHandler(&LogProtobufLine);
  gpr_set_log_function(&LogGrpcLine);
}

}  // namespace recog::server
