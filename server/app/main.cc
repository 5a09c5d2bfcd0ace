// recogd: the recognition server. `recogd --help` lists the flags; server/README.md explains the
// configuration, security and operations.
//
// Signals: SIGTERM and SIGINT shut down gracefully; SIGHUP reloads the placement table, the token
// file and the TLS files (RecognitionServer::Reload). Under systemd (Type=notify, NOTIFY_SOCKET
// set) it reports READY=1 once serving, RELOADING=1 then READY=1 around a reload, STOPPING=1 when
// shutting down.
//
// recogd --verify checks every file of the configured store without serving (the server must be
// stopped: the store is opened) and prints one line: what it read, or the first damaged file.
//
// Exit status: 0 after --help, --version, a clean shutdown (SIGTERM, SIGINT) or a --verify that
// found the store whole; 2 when the command line or the configuration is refused before anything
// starts (an unknown flag, a bad value, a --config file that cannot be read or does not validate:
// one line "recogd: CODE: message"); 1 when the server fails to start or --verify fails.
#include <chrono>
#include <csignal>
#include <cstdio>
#include <ctime>
#include <string>

#include <spdlog/spdlog.h>

#include "recog_build_info.h"
#include "server/app/recognition_server.h"
#include "server/app/systemd_notify.h"

namespace {

constexpr int kUsageError = 2;

// Tells systemd `state`; a failure is logged, never fatal.
void Notify(const std::string& state) {
  if (const recog::Status sent = recog::server::NotifySystemd(state); !sent.ok()) {
    spdlog::warn("recogd: {}", sent.ToString());
  }
}

// "RELOADING=1" with the CLOCK_MONOTONIC time systemd (Type=notify-reload) wants beside it.
std::string ReloadingState() {
  timespec now{};
  clock_gettime(CLOCK_MONOTONIC, &now);
  return "RELOADING=1\nMONOTONIC_USEC=" +
         std::to_string(uint64_t(now.tv_sec) * 1000000 + uint64_t(now.tv_nsec) / 1000);
}

// recogd --verify: the exit status.
int VerifyStore(const recog::server::ServerConfig& config) {
  const auto start = std::chrono::steady_clock::now();
  const auto report = recog::server::RecognitionServer::VerifyOffline(config);
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  if (!report.ok()) {
    std::fprintf(stderr, "recogd: %s\n", report.status().ToString().c_str());
    return 1;
  }
  const double mib = double(report->bytes) / (1 << 20);
  std::printf("store %s/store: %zu files, %.1f MiB checked in %.2f s (%.0f MiB/s): no damage\n",
              config.data_dir.c_str(), report->files, mib, seconds, mib / std::max(seconds, 1e-9));
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  using recog::server::RecognitionServer;
  auto command_line = recog::server::ParseCommandLine(argc, argv);
  if (!command_line.ok()) {
    std::fprintf(stderr, "recogd: %s\n", command_line.status().ToString().c_str());
    return kUsageError;
  }
  if (!command_line.value().help.empty()) {
    std::fputs(command_line.value().help.c_str(), stdout);
    return 0;
  }
  if (command_line.value().version) {
    std::puts(recog::build_info::VersionLine("recogd").c_str());
    return 0;
  }
  const recog::server::ServerConfig& config = command_line.value().config;
  spdlog::set_level(spdlog::level::from_str(config.log_level));
  spdlog::set_pattern("%Y-%m-%dT%H:%M:%S.%e%z %^%l%$ %v");
  if (command_line.value().verify) return VerifyStore(config);

  // SIGTERM, SIGINT and SIGHUP are taken by this thread with sigwait; every thread started from
  // here on (gRPC's, the workers) inherits the blocked mask.
  sigset_t signals;
  sigemptyset(&signals);
  sigaddset(&signals, SIGTERM);
  sigaddset(&signals, SIGINT);
  sigaddset(&signals, SIGHUP);
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);

  auto server = RecognitionServer::Start(config);
  if (!server.ok()) {
    spdlog::error("recogd: {}", server.status().ToString());
    return 1;
  }
  Notify("READY=1\nSTATUS=serving on port " + std::to_string(server.value()->port()));
  int signal = 0;
  // SIGHUP reloads; each file that does not load is logged and the one in use kept.
  while (sigwait(&signals, &signal) == 0 && signal == SIGHUP) {
    spdlog::info("recogd: SIGHUP received, reloading");
    Notify(ReloadingState());
    const recog::Status reloaded = server.value()->Reload();
    Notify(std::string("READY=1\nSTATUS=") +
           (reloaded.ok() ? "reloaded" : "reload failed, see the log"));
  }
  spdlog::info("recogd: {} received, shutting down", signal == SIGTERM ? "SIGTERM" : "SIGINT");
  Notify("STOPPING=1");
  server.value()->Shutdown(std::chrono::milliseconds(config.shutdown_grace_ms));
  return 0;
}
