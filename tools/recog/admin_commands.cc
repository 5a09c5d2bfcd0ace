// recog admin health | checkpoint | verify | status | restore: operating recogd. health,
// checkpoint, verify and status call the server over the C++ client library (with the
// ServerFlags); restore works offline on a data directory. A failure prints one line
// "recog admin <cmd>: ..." and exits 1.
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>

#include <nlohmann/json.hpp>

#include "client/cpp/recognition_client.h"
#include "storage/rocksdb_index_store.h"
#include "tools/common/cli_support.h"
#include "tools/common/remote_support.h"
#include "tools/common/server_flags.h"
#include "tools/recog/commands.h"

namespace recog::cli {
namespace {

namespace fs = std::filesystem;
using client::RecognitionClient;
using Json = nlohmann::ordered_json;

int RunHealth(const ServerFlags& flags, RecognitionClient& client) {
  auto status = client.CheckHealth();
  if (!status.ok()) return Fail("admin health", status.status());
  const std::string name = grpc::health::v1::HealthCheckResponse::ServingStatus_Name(*status);
  if (flags.json) {
    std::printf("%s\n", Json({{"status", name}}).dump().c_str());
  } else {
    std::printf("%s\n", name.c_str());
  }
  return *status == grpc::health::v1::HealthCheckResponse::SERVING ? 0 : 1;
}

struct CheckpointArgs {
  ServerFlags server;
  std::string to;
  bool quiet = false;
};

int RunCheckpoint(const CheckpointArgs& args, RecognitionClient& client) {
  ProgressBar progress(!args.quiet);
  auto manifest = client.DownloadCheckpoint(
      args.to, [&](uint64_t done, uint64_t total) { progress.Update("bytes", done, total); });
  progress.Finish();
  if (!manifest.ok()) return Fail("admin checkpoint", manifest.status());
  // The copy is read back here, every block against its checksum, before it counts as a backup.
  auto checked = VerifyRocksDbCheckpoint(args.to);
  if (!checked.ok()) {
    return Fail("admin checkpoint", checked.status().WithContext(
                                        "the checkpoint in '" + args.to +
                                        "' is damaged (kept for inspection; do not restore it)"));
  }
  if (args.server.json) {
    std::printf("%s\n", Json({{"directory", args.to},
                              {"files", manifest->files_size()},
                              {"bytes", manifest->total_bytes()},
                              {"maps", manifest->maps()},
                              {"models", manifest->models()},
                              {"created", UtcTime(manifest->created_unix_ms())},
                              {"verified_table_files", checked->files}})
                            .dump()
                            .c_str());
  } else {
    std::printf(
        "checkpoint of %u maps and %u models: %d files, %llu bytes in %s; "
        "%zu table files read back, no damage\n",
        manifest->maps(), manifest->models(), manifest->files_size(),
        static_cast<unsigned long long>(manifest->total_bytes()), args.to.c_str(), checked->files);
  }
  return 0;
}

struct VerifyArgs {
  ServerFlags server;
  uint32_t mib_per_second = 0;
};

int RunVerify(const VerifyArgs& args, RecognitionClient& client) {
  auto report = client.VerifyStore(args.mib_per_second);
  if (!report.ok()) return Fail("admin verify", report.status());
  const double mib = double(report->bytes()) / (1 << 20);
  const double rate = mib / std::max(report->seconds(), 1e-9);
  if (args.server.json) {
    std::printf("%s\n", Json({{"files", report->files()},
                              {"bytes", report->bytes()},
                              {"seconds", report->seconds()},
                              {"mib_per_second", rate}})
                            .dump()
                            .c_str());
  } else {
    std::printf("store verified: %llu files, %.1f MiB in %.2f s (%.1f MiB/s), no damage\n",
                static_cast<unsigned long long>(report->files()), mib, report->seconds(), rate);
  }
  return 0;
}

// The server's recovery report as the store library describes recoveries (the lines recogd logs).
StoreRecovery RecoveryOf(const client::pb::StoreRecoveryReport& report) {
  StoreRecovery recovery;
  recovery.damage.assign(report.damage().begin(), report.damage().end());
  recovery.damaged_copy = report.damaged_copy();
  for (const client::pb::MapLoss& map : report.maps()) {
    StoreRecovery::MapLoss loss;
    loss.name = map.name();
    loss.entries_before = map.frames_before();
    loss.entries_after = map.frames_after();
    loss.missing.assign(map.missing_frame_ids().begin(), map.missing_frame_ids().end());
    loss.map_lost = map.map_lost();
    recovery.maps.push_back(std::move(loss));
  }
  recovery.blobs_lost.assign(report.blobs_lost().begin(), report.blobs_lost().end());
  return recovery;
}

// Exit 1 when the last check found damage.
int RunStatus(const ServerFlags& flags, RecognitionClient& client) {
  auto status = client.GetStoreStatus();
  if (!status.ok()) return Fail("admin status", status.status());
  const StoreRecovery recovery = RecoveryOf(status->recovery());
  const client::pb::StoreCheck& check = status->last_check();
  const bool checked = status->has_last_check();
  if (flags.json) {
    Json maps = Json::array();
    for (const StoreRecovery::MapLoss& loss : recovery.maps) {
      maps.push_back({{"name", loss.name},
                      {"frames_before", loss.entries_before},
                      {"frames_after", loss.entries_after},
                      {"missing_frame_ids", loss.missing},
                      {"map_lost", loss.map_lost}});
    }
    Json out = {{"recovered", recovery.recovered()}};
    if (recovery.recovered()) {
      out["recovery"] = {{"damage", recovery.damage},
                         {"damaged_copy", recovery.damaged_copy},
                         {"maps", maps},
                         {"blobs_lost", recovery.blobs_lost}};
    }
    if (checked) {
      out["last_check"] = {{"finished", UtcTime(check.finished_unix_ms())},
                           {"error", check.error()},
                           {"files", check.files()},
                           {"bytes", check.bytes()},
                           {"seconds", check.seconds()}};
    }
    std::printf("%s\n", out.dump().c_str());
  } else {
    if (!recovery.recovered()) {
      std::printf("store opened whole at start-up (no recovery)\n");
    } else {
      std::printf("store recovered point-in-time at start-up:\n");
      for (const std::string& line : recovery.Describe()) std::printf("  %s\n", line.c_str());
    }
    if (!checked) {
      std::printf("store files not checked yet since start-up\n");
    } else if (check.error().empty()) {
      std::printf("last check %s: %llu files, %.1f MiB in %.2f s, no damage\n",
                  UtcTime(check.finished_unix_ms()).c_str(),
                  static_cast<unsigned long long>(check.files()), double(check.bytes()) / (1 << 20),
                  check.seconds());
    } else {
      std::printf("last check %s: %s\n", UtcTime(check.finished_unix_ms()).c_str(),
                  check.error().c_str());
    }
  }
  return checked && !check.error().empty() ? 1 : 0;
}

struct RestoreArgs {
  std::string from, data_dir;
};

int RunRestore(const RestoreArgs& args) {
  std::error_code ec;
  fs::create_directories(args.data_dir, ec);
  if (ec) {
    return Fail("admin restore",
                Status::InvalidArgument("cannot create '" + args.data_dir + "': " + ec.message()));
  }
  const std::string store = (fs::path(args.data_dir) / "store").string();
  if (Status s = RestoreRocksDbCheckpoint(args.from, store); !s.ok()) {
    return Fail("admin restore", s);
  }
  // Every block of the restored copy is read back and checked before the store is left in place.
  RocksDbStoreOptions options;
  options.create_if_missing = false;
  StatusOr<IndexStore::VerifyReport> report = Status::Unavailable("not checked");
  {
    auto opened = OpenRocksDbIndexStore(store, options);
    report =
        opened.ok() ? (*opened)->Verify(0) : StatusOr<IndexStore::VerifyReport>(opened.status());
  }
  if (!report.ok()) {
    fs::remove_all(store, ec);
    return Fail("admin restore", report.status().WithContext("the checkpoint '" + args.from +
                                                             "' is damaged; nothing restored"));
  }
  std::printf("restored %s into %s: %zu files, %.1f MiB checked\n", args.from.c_str(),
              store.c_str(), report->files, double(report->bytes) / (1 << 20));
  return 0;
}

}  // namespace

void AddAdminCommands(CLI::App& app, int* exit_code) {
  CLI::App* admin = app.add_subcommand("admin", "Operate recogd: health, backups, checks");
  admin->require_subcommand(1);
  auto health_flags = std::make_shared<ServerFlags>();
  CLI::App* health = admin->add_subcommand(
      "health", "Ask the server's gRPC health service; exit 0 when SERVING, 1 otherwise");
  health->add_option("--timeout-ms", health_flags->timeout_ms, "How long to wait for the answer")
      ->capture_default_str();
  ConnectCommand(health, health_flags.get(), exit_code, [health_flags](RecognitionClient& client) {
    return RunHealth(*health_flags, client);
  });

  auto checkpoint_args = std::make_shared<CheckpointArgs>();
  CLI::App* checkpoint = admin->add_subcommand(
      "checkpoint",
      "Copy the server's whole store (maps, frames, models) to a new folder here, "
      "online, and check every block of the copy; `recog admin restore` puts it in place for a "
      "new server");
  checkpoint->add_option("--to", checkpoint_args->to, "The new folder")->required();
  checkpoint->add_flag("-q,--quiet", checkpoint_args->quiet, "No progress output");
  ConnectCommand(checkpoint, &checkpoint_args->server, exit_code,
                 [checkpoint_args](RecognitionClient& client) {
                   return RunCheckpoint(*checkpoint_args, client);
                 });

  auto verify_args = std::make_shared<VerifyArgs>();
  CLI::App* verify = admin->add_subcommand(
      "verify",
      "Have the server read every file of its store and check every checksum now, online; "
      "exit 1 on damage (DATA_LOSS)");
  verify
      ->add_option("--mib-per-second", verify_args->mib_per_second,
                   "Read rate (0: the server's store.verify_mb_per_s)")
      ->capture_default_str();
  ConnectCommand(verify, &verify_args->server, exit_code, [verify_args](RecognitionClient& client) {
    return RunVerify(*verify_args, client);
  });

  auto status_flags = std::make_shared<ServerFlags>();
  CLI::App* status = admin->add_subcommand(
      "status",
      "What the server's store went through: the loss of a point-in-time recovery at start-up "
      "(recogd --recover point-in-time) and the last check of its files; exit 1 when that check "
      "found damage");
  ConnectCommand(status, status_flags.get(), exit_code, [status_flags](RecognitionClient& client) {
    return RunStatus(*status_flags, client);
  });

  auto restore_args = std::make_shared<RestoreArgs>();
  CLI::App* restore =
      admin->add_subcommand("restore",
                            "Offline: make a checkpoint the store of a data directory for recogd "
                            "(<data-dir>/store must not exist; the server must not run on it)");
  restore->add_option("--from", restore_args->from, "A folder written by `recog admin checkpoint`")
      ->required();
  restore->add_option("--data-dir", restore_args->data_dir, "recogd's --data-dir")->required();
  restore->callback([exit_code, restore_args] { *exit_code = RunRestore(*restore_args); });
}

}  // namespace recog::cli
