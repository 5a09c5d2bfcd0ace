// recogd: the recognition server. `recogd --help` lists the flags; server/README.md explains the
// configuration, security and operations.
//
// Exit status: 0 after --help, --version or a clean shutdown (SIGTERM, SIGINT); 2 when the command
// line or the configuration is refused before anything starts (an unknown flag, a bad value, a
// --config file that cannot be read or does not validate: one line "recogd: CODE: message"); 1
// when the server fails to start.
#include <csignal>
#include <cstdio>

#include <spdlog/spdlog.h>

#include "recog_build_info.h"
#include "server/app/recognition_server.h"

namespace {

constexpr int kUsageError = 2;

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
  int signal = 0;
  // SIGHUP re-reads the placement table of a sharded server (a bad file keeps the old one).
  while (sigwait(&signals, &signal) == 0 && signal == SIGHUP) {
    if (const recog::Status reloaded = server.value()->ReloadPlacement(); !reloaded.ok()) {
      spdlog::error("recogd: SIGHUP: {}; the placement table in use is kept", reloaded.ToString());
    }
  }
  spdlog::info("recogd: {} received, shutting down", signal == SIGTERM ? "SIGTERM" : "SIGINT");
  server.value()->Shutdown(std::chrono::milliseconds(config.shutdown_grace_ms));
  return 0;
}
