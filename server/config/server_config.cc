#include "server/config/server_config.h"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cctype>
#include <charconv>
#include <climits>
#include <filesystem>
#include <fstream>
#include <functional>
#include <optional>
#include <sstream>
#include <thread>
#include <utility>
#include <vector>

#include <spdlog/common.h>
#include <spdlog/spdlog.h>

#include "core/common/file_io.h"
#include "core/place/detector_settings.h"
#include "server/config/placement_table.h"

namespace recog::server {
namespace {

constexpr uint32_t kMinMessageBytes = 1u << 20;
constexpr uint32_t kMaxWorkers = 1024;
constexpr uint32_t kMaxRequestLogEntries = 1000000;
constexpr uint32_t kMaxGroupSyncIntervalMs = 60000;
constexpr uint64_t kMaxBlockCacheMb = uint64_t{1} << 20;  // 1 TiB

// How a value of type T is described in errors ("key 'workers' must be <description>").
template <typename T>
std::string_view Describe() {
  if constexpr (std::is_same_v<T, bool>) {
    return "true or false";
  } else if constexpr (std::is_unsigned_v<T>) {
    return "a non-negative integer";
  } else if constexpr (std::is_floating_point_v<T>) {
    return "a number";
  } else {
    return "a string";
  }
}

// One YAML mapping of the file (the root or a section). Reads the known keys and then rejects any
// other key, so that typos are errors.
class YamlSection {
 public:
  YamlSection(YAML::Node node, std::string path) : node_(std::move(node)), path_(std::move(path)) {}

  // Reads `key` into *value when present; leaves *value alone when absent.
  template <typename T>
  Status Read(const std::string& key, T* value) {
    known_.push_back(key);
    const YAML::Node child = Child(key);
    if (!child.IsDefined()) return Status::Ok();
    if (!child.IsScalar() || !YAML::convert<T>::decode(child, *value)) {
      return Status::InvalidArgument("key '" + Name(key) + "' must be " +
                                     std::string(Describe<T>()) + ", got " + Quote(child));
    }
    return Status::Ok();
  }

  // Reads a list of strings `key` into *values when present.
  Status ReadList(const std::string& key, std::vector<std::string>* values) {
    known_.push_back(key);
    const YAML::Node child = Child(key);
    if (!child.IsDefined()) return Status::Ok();
    const auto wrong = [&] {
      return Status::InvalidArgument("key '" + Name(key) + "' must be a list of strings, got " +
                                     Quote(child));
    };
    if (!child.IsSequence()) return wrong();
    values->clear();
    for (const YAML::Node& item : child) {
      if (!item.IsScalar()) return wrong();
      values->push_back(item.Scalar());
    }
    return Status::Ok();
  }

  // Reads a string `key` and converts it with `parse` (a function returning StatusOr<T>).
  template <typename T, typename Parse>
  Status ReadParsed(const std::string& key, T* value, Parse parse) {
    if (!Child(key).IsDefined()) {
      known_.push_back(key);
      return Status::Ok();
    }
    std::string text;
    RECOG_RETURN_IF_ERROR(Read(key, &text));
    StatusOr<T> parsed = parse(text);
    if (!parsed.ok()) {
      return parsed.status().WithContext("key '" + Name(key) + "'", StatusCode::kInvalidArgument);
    }
    *value = *parsed;
    return Status::Ok();
  }

  // The nested mapping `key`; an absent or empty (null) section has no keys.
  StatusOr<YamlSection> Section(const std::string& key) {
    known_.push_back(key);
    const YAML::Node child = Child(key);
    if (!child.IsDefined() || child.IsNull()) return YamlSection(YAML::Node(), Name(key));
    if (!child.IsMap()) {
      return Status::InvalidArgument("key '" + Name(key) + "' must be a section (a mapping)");
    }
    return YamlSection(child, Name(key));
  }

  // Whether `key` is given (a Read of it still counts it as known).
  bool Has(const std::string& key) const { return Child(key).IsDefined(); }

  // INVALID_ARGUMENT naming the first key that no Read or Section asked for.
  Status RejectUnknownKeys() const {
    if (!node_.IsMap()) return Status::Ok();
    for (const auto& item : node_) {
      if (!item.first.IsScalar()) {
        return Status::InvalidArgument("section '" + path_ + "' has a key that is not a string");
      }
      const std::string& key = item.first.Scalar();
      if (std::find(known_.begin(), known_.end(), key) == known_.end()) {
        return Status::InvalidArgument("unknown key '" + Name(key) + "'");
      }
    }
    return Status::Ok();
  }

 private:
  // Const lookup: unlike the non-const operator[], it never inserts `key`.
  YAML::Node Child(const std::string& key) const { return node_[key]; }

  std::string Name(const std::string& key) const { return path_.empty() ? key : path_ + "." + key; }

  static std::string Quote(const YAML::Node& node) {
    if (node.IsScalar()) return "'" + node.Scalar() + "'";
    if (node.IsSequence()) return "a list";
    if (node.IsMap()) return "a mapping";
    return "nothing";
  }

  YAML::Node node_;
  std::string path_;  // "" for the root, "keepalive" for a section
  std::vector<std::string> known_;
};

// The section "place": the settings a map keeps, by the settings table's names
// (core/place/detector_settings.h), its preset first whatever the order. "mode" is the deprecated
// name of "preset": still read, with a warning.
Status ReadPlaceSettings(YamlSection& place, LoopDetectorParams* params) {
  std::vector<NamedSetting> values;
  if (place.Has("mode")) {
    if (place.Has("preset")) {
      return Status::InvalidArgument(
          "keys 'place.mode' and 'place.preset' are both given: 'mode' is the old name of "
          "'preset'; keep 'preset'");
    }
    std::string mode;
    RECOG_RETURN_IF_ERROR(place.Read("mode", &mode));
    spdlog::warn("configuration: 'place.mode' is deprecated, write 'place.preset: {}'", mode);
    values.emplace_back("preset", mode);
  }
  for (const std::string_view name : MapDetectorSettingNames()) {
    const std::string key(name);
    std::string text;
    RECOG_RETURN_IF_ERROR(place.Read(key, &text));
    if (place.Has(key)) values.emplace_back(key, text);
  }
  const Status applied = ApplyDetectorSettings(values, params);
  return applied.ok() ? applied : applied.WithContext("section 'place'");
}

// The keys of an HTTP port's limits, in its section.
Status ReadHttpPort(YamlSection& section, HttpPortConfig* port) {
  RECOG_RETURN_IF_ERROR(section.ReadList("hosts", &port->hosts));
  RECOG_RETURN_IF_ERROR(section.Read("max_connections", &port->max_connections));
  RECOG_RETURN_IF_ERROR(
      section.Read("max_connections_per_client", &port->max_connections_per_client));
  RECOG_RETURN_IF_ERROR(section.Read("request_timeout_ms", &port->request_timeout_ms));
  RECOG_RETURN_IF_ERROR(section.Read("header_timeout_ms", &port->header_timeout_ms));
  RECOG_RETURN_IF_ERROR(section.Read("min_bytes_per_s", &port->min_bytes_per_s));
  RECOG_RETURN_IF_ERROR(section.Read("max_header_lines", &port->max_header_lines));
  return section.Read("max_header_bytes", &port->max_header_bytes);
}

// INVALID_ARGUMENT naming the first bad limit of the HTTP port of YAML section `name`.
Status ValidateHttpPort(const std::string& name, const HttpPortConfig& port) {
  const auto in_range = [&](const char* key, uint64_t value, uint64_t min, uint64_t max) -> Status {
    if (value >= min && value <= max) return Status::Ok();
    return Status::InvalidArgument(name + "." + key + " must be " + std::to_string(min) + " to " +
                                   std::to_string(max) + ", not " + std::to_string(value));
  };
  RECOG_RETURN_IF_ERROR(in_range("max_connections", port.max_connections, 1, 1024));
  RECOG_RETURN_IF_ERROR(in_range("max_connections_per_client", port.max_connections_per_client, 1,
                                 port.max_connections));
  RECOG_RETURN_IF_ERROR(in_range("request_timeout_ms", port.request_timeout_ms, 1000, 600000));
  RECOG_RETURN_IF_ERROR(in_range("header_timeout_ms", port.header_timeout_ms, 1000, 600000));
  RECOG_RETURN_IF_ERROR(in_range("min_bytes_per_s", port.min_bytes_per_s, 0, 1u << 30));
  RECOG_RETURN_IF_ERROR(in_range("max_header_lines", port.max_header_lines, 1, 10000));
  RECOG_RETURN_IF_ERROR(in_range("max_header_bytes", port.max_header_bytes, 1024, 1u << 20));
  for (const std::string& host : port.hosts) {
    const bool valid =
        !host.empty() && host.size() <= 253 && std::all_of(host.begin(), host.end(), [](char c) {
          return std::isalnum(static_cast<unsigned char>(c)) || c == '-' || c == '.';
        });
    if (!valid) {
      return Status::InvalidArgument(name + ".hosts: '" + host +
                                     "' is not a host name (letters, digits, '-' and '.')");
    }
  }
  return Status::Ok();
}

Status ReadConfig(const YAML::Node& root, ServerConfig* config) {
  YamlSection top(root, "");
  RECOG_RETURN_IF_ERROR(top.Read("listen", &config->listen));
  RECOG_RETURN_IF_ERROR(top.Read("data_dir", &config->data_dir));
  RECOG_RETURN_IF_ERROR(top.Read("place_vocabulary", &config->place_vocabulary));
  RECOG_RETURN_IF_ERROR(top.Read("object_vocabulary", &config->object_vocabulary));
  RECOG_RETURN_IF_ERROR(top.Read("workers", &config->workers));
  RECOG_RETURN_IF_ERROR(top.Read("queue_capacity", &config->queue_capacity));
  RECOG_RETURN_IF_ERROR(top.Read("retry_after_ms", &config->retry_after_ms));
  RECOG_RETURN_IF_ERROR(top.Read("request_log_entries", &config->request_log_entries));
  RECOG_RETURN_IF_ERROR(top.Read("max_message_bytes", &config->max_message_bytes));
  RECOG_RETURN_IF_ERROR(top.Read("token_file", &config->token_file));
  RECOG_RETURN_IF_ERROR(top.Read("metrics_listen", &config->metrics_listen));
  RECOG_RETURN_IF_ERROR(top.Read("shutdown_grace_ms", &config->shutdown_grace_ms));
  RECOG_RETURN_IF_ERROR(top.Read("log_level", &config->log_level));

  RECOG_ASSIGN_OR_RETURN(YamlSection keepalive, top.Section("keepalive"));
  RECOG_RETURN_IF_ERROR(keepalive.Read("time_ms", &config->keepalive.time_ms));
  RECOG_RETURN_IF_ERROR(keepalive.Read("timeout_ms", &config->keepalive.timeout_ms));
  RECOG_RETURN_IF_ERROR(
      keepalive.Read("permit_without_calls", &config->keepalive.permit_without_calls));
  RECOG_RETURN_IF_ERROR(
      keepalive.Read("min_ping_interval_ms", &config->keepalive.min_ping_interval_ms));
  RECOG_RETURN_IF_ERROR(keepalive.RejectUnknownKeys());

  RECOG_ASSIGN_OR_RETURN(YamlSection grpc, top.Section("grpc"));
  GrpcLimitsConfig& limits = config->grpc;
  RECOG_RETURN_IF_ERROR(grpc.Read("max_concurrent_streams", &limits.max_concurrent_streams));
  RECOG_RETURN_IF_ERROR(grpc.Read("memory_quota_mb", &limits.memory_quota_mb));
  RECOG_RETURN_IF_ERROR(grpc.Read("pending_requests_mb", &limits.pending_requests_mb));
  RECOG_RETURN_IF_ERROR(grpc.Read("decode_memory_mb", &limits.decode_memory_mb));
  RECOG_RETURN_IF_ERROR(grpc.Read("max_connection_idle_ms", &limits.max_connection_idle_ms));
  RECOG_RETURN_IF_ERROR(grpc.Read("max_connection_age_ms", &limits.max_connection_age_ms));
  RECOG_RETURN_IF_ERROR(
      grpc.Read("max_connection_age_grace_ms", &limits.max_connection_age_grace_ms));
  RECOG_RETURN_IF_ERROR(grpc.Read("reserve_descriptors", &limits.reserve_descriptors));
  RECOG_RETURN_IF_ERROR(grpc.RejectUnknownKeys());

  RECOG_ASSIGN_OR_RETURN(YamlSection tls, top.Section("tls"));
  RECOG_RETURN_IF_ERROR(tls.Read("cert", &config->tls.cert));
  RECOG_RETURN_IF_ERROR(tls.Read("key", &config->tls.key));
  RECOG_RETURN_IF_ERROR(tls.Read("client_ca", &config->tls.client_ca));
  RECOG_RETURN_IF_ERROR(tls.RejectUnknownKeys());

  RECOG_ASSIGN_OR_RETURN(YamlSection shard, top.Section("shard"));
  RECOG_RETURN_IF_ERROR(shard.Read("name", &config->shard.name));
  RECOG_RETURN_IF_ERROR(shard.Read("placement_file", &config->shard.placement_file));
  RECOG_RETURN_IF_ERROR(shard.RejectUnknownKeys());

  RECOG_ASSIGN_OR_RETURN(YamlSection repository, top.Section("repository"));
  RECOG_RETURN_IF_ERROR(repository.Read("primary", &config->repository.primary));
  RECOG_RETURN_IF_ERROR(repository.Read("token_file", &config->repository.token_file));
  RECOG_RETURN_IF_ERROR(repository.Read("tls_ca", &config->repository.tls_ca));
  RECOG_RETURN_IF_ERROR(repository.RejectUnknownKeys());
  RECOG_ASSIGN_OR_RETURN(YamlSection console, top.Section("console"));
  RECOG_RETURN_IF_ERROR(console.Read("listen", &config->console.listen));
  RECOG_RETURN_IF_ERROR(console.Read("web_root", &config->console.web_root));
  RECOG_RETURN_IF_ERROR(console.Read("vendor_dir", &config->console.vendor_dir));
  RECOG_RETURN_IF_ERROR(console.Read("loops_per_map", &config->console.loops_per_map));
  RECOG_RETURN_IF_ERROR(console.Read("charts_dir", &config->console.charts_dir));
  RECOG_RETURN_IF_ERROR(console.Read("max_body_bytes", &config->console.max_body_bytes));
  RECOG_RETURN_IF_ERROR(
      console.Read("max_inflight_body_bytes", &config->console.max_inflight_body_bytes));
  RECOG_RETURN_IF_ERROR(ReadHttpPort(console, &config->console));
  RECOG_RETURN_IF_ERROR(console.RejectUnknownKeys());

  RECOG_ASSIGN_OR_RETURN(YamlSection metrics, top.Section("metrics"));
  RECOG_RETURN_IF_ERROR(ReadHttpPort(metrics, &config->metrics));
  RECOG_RETURN_IF_ERROR(metrics.RejectUnknownKeys());

  RECOG_ASSIGN_OR_RETURN(YamlSection store, top.Section("store"));
  RECOG_RETURN_IF_ERROR(store.ReadParsed("sync", &config->store.sync, ParseStoreSync));
  RECOG_RETURN_IF_ERROR(
      store.Read("group_sync_interval_ms", &config->store.group_sync_interval_ms));
  RECOG_RETURN_IF_ERROR(store.Read("block_cache_mb", &config->store.block_cache_mb));
  RECOG_RETURN_IF_ERROR(store.ReadParsed("recover", &config->store.recover, ParseStoreRecover));
  RECOG_RETURN_IF_ERROR(store.Read("verify_interval_s", &config->store.verify_interval_s));
  RECOG_RETURN_IF_ERROR(store.Read("verify_mb_per_s", &config->store.verify_mb_per_s));
  RECOG_RETURN_IF_ERROR(store.RejectUnknownKeys());

  RECOG_ASSIGN_OR_RETURN(YamlSection place, top.Section("place"));
  RECOG_RETURN_IF_ERROR(ReadPlaceSettings(place, &config->place));
  RECOG_RETURN_IF_ERROR(place.RejectUnknownKeys());

  return top.RejectUnknownKeys();
}

bool IsLogLevel(const std::string& name) {
  return name == "off" || spdlog::level::from_str(name) != spdlog::level::off;
}

// Adds --config, --version, --verify and the flags of AddFlags, then parses. *help receives the
// usage text when -h or --help was given; *version and *verify are set when their flags were.
Status ParseWith(int argc, const char* const* argv, std::string* config_file, ServerConfig* config,
                 std::string* help, bool* version, bool* verify) {
  CLI::App app{"recogd: place and object recognition server", "recogd"};
  app.add_option("-c,--config", *config_file,
                 "YAML configuration file; the other flags override its values");
  app.add_flag("--version", *version, "Print the version and build, then exit");
  app.add_flag("--verify", *verify,
               "Check every file of the store (offline), print what was found, then exit");
  AddFlags(app, config);
  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp&) {
    *help = app.help();
  } catch (const CLI::CallForAllHelp&) {
    *help = app.help("", CLI::AppFormatMode::All);
  } catch (const CLI::Error& e) {
    return Status::InvalidArgument(e.what());
  }
  return Status::Ok();
}

// INVALID_ARGUMENT naming the first key of the "grpc" section out of its range.
Status ValidateGrpcLimits(const GrpcLimitsConfig& grpc, uint32_t max_message_bytes) {
  const auto range = [](std::string_view key, uint64_t value, uint64_t low,
                        uint64_t high) -> Status {
    if (value >= low && value <= high) return Status::Ok();
    return Status::InvalidArgument("grpc." + std::string(key) + " must be " + std::to_string(low) +
                                   " to " + std::to_string(high) + ", not " +
                                   std::to_string(value));
  };
  const uint64_t message_mb = (uint64_t(max_message_bytes) + (1 << 20) - 1) >> 20;
  RECOG_RETURN_IF_ERROR(range("max_concurrent_streams", grpc.max_concurrent_streams, 1, 10000));
  RECOG_RETURN_IF_ERROR(range("memory_quota_mb", grpc.memory_quota_mb, 16, 65536));
  RECOG_RETURN_IF_ERROR(range("pending_requests_mb", grpc.pending_requests_mb, message_mb, 65536));
  RECOG_RETURN_IF_ERROR(range("decode_memory_mb", grpc.decode_memory_mb, 16, 65536));
  RECOG_RETURN_IF_ERROR(range("reserve_descriptors", grpc.reserve_descriptors, 16, 65536));
  for (const auto& [key, value] :
       {std::pair{"max_connection_idle_ms", grpc.max_connection_idle_ms},
        std::pair{"max_connection_age_ms", grpc.max_connection_age_ms}}) {
    if (value != 0) RECOG_RETURN_IF_ERROR(range(key, value, 1000, (1u << 31) - 1));
  }
  return range("max_connection_age_grace_ms", grpc.max_connection_age_grace_ms, 0, (1u << 31) - 1);
}

}  // namespace

std::string_view StoreSyncName(StoreSync sync) {
  switch (sync) {
    case StoreSync::kGrouped:
      return "grouped";
    case StoreSync::kEveryWrite:
      return "every_write";
  }
  return "unknown";
}

StatusOr<StoreSync> ParseStoreSync(std::string_view name) {
  for (StoreSync sync : {StoreSync::kGrouped, StoreSync::kEveryWrite}) {
    if (name == StoreSyncName(sync)) return sync;
  }
  return Status::InvalidArgument("unknown store sync policy '" + std::string(name) +
                                 "' (grouped or every_write)");
}

std::string_view StoreRecoverName(StoreRecover recover) {
  switch (recover) {
    case StoreRecover::kRefuse:
      return "refuse";
    case StoreRecover::kPointInTime:
      return "point-in-time";
  }
  return "unknown";
}

StatusOr<StoreRecover> ParseStoreRecover(std::string_view name) {
  for (StoreRecover recover : {StoreRecover::kRefuse, StoreRecover::kPointInTime}) {
    if (name == StoreRecoverName(recover)) return recover;
  }
  return Status::InvalidArgument("unknown store recovery '" + std::string(name) +
                                 "' (refuse or point-in-time)");
}

StatusOr<ServerConfig> ServerConfig::LoadYaml(const std::string& path) {
  const std::string what = "config file '" + path + "'";
  RECOG_ASSIGN_OR_RETURN(const std::string text, ReadWholeFile(path, what));
  ServerConfig config;
  try {
    const YAML::Node root = YAML::Load(text);
    if (!root.IsNull() && !root.IsMap()) {
      return Status::InvalidArgument(what + " must be a mapping of keys to values");
    }
    const Status status = ReadConfig(root, &config);
    if (!status.ok()) return status.WithContext(what, StatusCode::kInvalidArgument);
  } catch (const YAML::Exception& e) {
    return Status::InvalidArgument(what + " is not valid YAML: " + e.what());
  }
  return config;
}

Status ServerConfig::Validate() const {
  if (listen.empty()) return Status::InvalidArgument("listen must not be empty");
  if (data_dir.empty()) return Status::InvalidArgument("data_dir must not be empty");
  if (workers > kMaxWorkers) {
    return Status::InvalidArgument("workers must be at most " + std::to_string(kMaxWorkers) +
                                   " (0 = one per available CPU), got " + std::to_string(workers));
  }
  if (queue_capacity < 1) return Status::InvalidArgument("queue_capacity must be at least 1");
  if (request_log_entries > kMaxRequestLogEntries) {
    return Status::InvalidArgument("request_log_entries must be at most " +
                                   std::to_string(kMaxRequestLogEntries) + ", got " +
                                   std::to_string(request_log_entries));
  }
  if (max_message_bytes < kMinMessageBytes || max_message_bytes > INT_MAX) {
    return Status::InvalidArgument("max_message_bytes must be between 1 MiB (1048576) and " +
                                   std::to_string(INT_MAX) + ", got " +
                                   std::to_string(max_message_bytes));
  }
  if (keepalive.time_ms < 1) return Status::InvalidArgument("keepalive.time_ms must be at least 1");
  if (keepalive.timeout_ms < 1) {
    return Status::InvalidArgument("keepalive.timeout_ms must be at least 1");
  }
  if (!tls.key.empty() && tls.cert.empty()) {
    return Status::InvalidArgument("tls.key is set but tls.cert is not");
  }
  if (!tls.cert.empty() && tls.key.empty()) {
    return Status::InvalidArgument("tls.cert is set but tls.key is not");
  }
  if (!tls.client_ca.empty() && tls.cert.empty()) {
    return Status::InvalidArgument(
        "tls.client_ca (mutual TLS) needs the server's own tls.cert and tls.key");
  }
  if (shard.name.empty() != shard.placement_file.empty()) {
    return Status::InvalidArgument("shard.name and shard.placement_file go together");
  }
  if (!shard.name.empty() && !PlacementTable::IsShardName(shard.name)) {
    return Status::InvalidArgument("shard.name '" + shard.name +
                                   "' must have 1 to 64 characters of [A-Za-z0-9_]");
  }
  if (repository.primary.empty() && !(repository.token_file.empty() && repository.tls_ca.empty())) {
    return Status::InvalidArgument(
        "repository.token_file and repository.tls_ca need repository.primary");
  }
  if (!repository.primary.empty() && repository.primary == listen) {
    return Status::InvalidArgument("repository.primary is this server's own address ('" + listen +
                                   "'); a primary follows nobody");
  }
  // Two ":0" addresses are not a clash: each picks its own free port (tests do this).
  const bool picks_free_port = listen.ends_with(":0");
  if (!metrics_listen.empty() && metrics_listen == listen && !picks_free_port) {
    return Status::InvalidArgument("metrics_listen must differ from listen ('" + listen + "')");
  }
  if (!console.listen.empty() && !console.listen.ends_with(":0") &&
      (console.listen == listen || console.listen == metrics_listen)) {
    return Status::InvalidArgument("console.listen ('" + console.listen +
                                   "') must differ from listen and metrics_listen");
  }
  RECOG_RETURN_IF_ERROR(ValidateGrpcLimits(grpc, max_message_bytes));
  if (console.loops_per_map < 1 || console.loops_per_map > 1000) {
    return Status::InvalidArgument("console.loops_per_map must be 1 to 1000, not " +
                                   std::to_string(console.loops_per_map));
  }
  RECOG_RETURN_IF_ERROR(ValidateHttpPort("console", console));
  if (console.max_body_bytes < 1024 || console.max_body_bytes > INT32_MAX) {
    return Status::InvalidArgument("console.max_body_bytes must be 1024 to 2147483647, not " +
                                   std::to_string(console.max_body_bytes));
  }
  if (console.max_inflight_body_bytes < console.max_body_bytes ||
      console.max_inflight_body_bytes > (uint64_t{16} << 30)) {
    return Status::InvalidArgument(
        "console.max_inflight_body_bytes must be console.max_body_bytes (" +
        std::to_string(console.max_body_bytes) + ") to 17179869184, not " +
        std::to_string(console.max_inflight_body_bytes));
  }
  RECOG_RETURN_IF_ERROR(ValidateHttpPort("metrics", metrics));
  if (store.group_sync_interval_ms < 1 || store.group_sync_interval_ms > kMaxGroupSyncIntervalMs) {
    return Status::InvalidArgument("store.group_sync_interval_ms must be between 1 and " +
                                   std::to_string(kMaxGroupSyncIntervalMs));
  }
  if (store.verify_mb_per_s < 1 || store.verify_mb_per_s > 65536) {
    return Status::InvalidArgument("store.verify_mb_per_s must be between 1 and 65536");
  }
  if (store.block_cache_mb > kMaxBlockCacheMb) {
    return Status::InvalidArgument("store.block_cache_mb must be at most " +
                                   std::to_string(kMaxBlockCacheMb) + " (1 TiB)");
  }
  if (!IsLogLevel(log_level)) {
    return Status::InvalidArgument(
        "log_level must be trace, debug, info, warn, err, critical or off, got '" + log_level +
        "'");
  }
  RECOG_RETURN_IF_ERROR(place.Validate("place"));
  return Status::Ok();
}

uint32_t ServerConfig::WorkerCount() const {
  if (workers > 0) return workers;
  return AvailableCpus(CgroupPaths(), std::thread::hardware_concurrency());
}

namespace {

// The whole of a small file, empty when it cannot be read.
std::string ReadSmallFile(const std::filesystem::path& path) {
  std::ifstream in(path);
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

// ceil(quota / period) for a positive quota and period given as text; nullopt for anything else
// ("max", "-1", garbage).
std::optional<uint64_t> CpusOfQuota(std::string_view quota, std::string_view period) {
  uint64_t q = 0, p = 0;
  const auto [q_end, q_error] = std::from_chars(quota.data(), quota.data() + quota.size(), q);
  const auto [p_end, p_error] = std::from_chars(period.data(), period.data() + period.size(), p);
  if (q_error != std::errc() || p_error != std::errc() || q_end != quota.data() + quota.size() ||
      p_end != period.data() + period.size() || q == 0 || p == 0) {
    return std::nullopt;
  }
  return (q + p - 1) / p;
}

std::string_view Trim(std::string_view text) {
  const size_t first = text.find_first_not_of(" \t\n");
  if (first == std::string_view::npos) return {};
  return text.substr(first, text.find_last_not_of(" \t\n") - first + 1);
}

// `path` normalised and without a trailing separator, so that parent_path() goes up one level.
std::filesystem::path Normalised(const std::filesystem::path& path) {
  std::filesystem::path normal = path.lexically_normal();
  return normal.has_filename() ? normal : normal.parent_path();
}

// The process's cgroup in /proc/self/cgroup's text `self`: the cgroup v2 line ("0::/path") or,
// with `v1_controller`, the line of the v1 hierarchy holding that controller
// ("4:cpu,cpuacct:/path"). "" when there is no such line.
std::string OwnCgroup(const std::string& self, std::string_view v1_controller) {
  std::istringstream lines(self);
  for (std::string line; std::getline(lines, line);) {
    const size_t first = line.find(':'), second = line.find(':', first + 1);
    if (first == std::string::npos || second == std::string::npos) continue;
    const std::string controllers = "," + line.substr(first + 1, second - first - 1) + ",";
    const bool wanted =
        v1_controller.empty()
            ? controllers == ",,"
            : controllers.find("," + std::string(v1_controller) + ",") != std::string::npos;
    if (wanted) return line.substr(second + 1);
  }
  return {};
}

// The tightest quota that `cpus_in` finds in `root`/`relative` and in each of its ancestors up to
// `root`. A container's own cgroup is its root, where the path of /proc/self/cgroup (the host's
// view) does not exist: then only the root is read.
std::optional<uint64_t> TightestUpTo(
    const std::filesystem::path& root, const std::string& relative,
    const std::function<std::optional<uint64_t>(const std::filesystem::path&)>& cpus_in) {
  const std::filesystem::path top = Normalised(root);
  std::filesystem::path dir = Normalised(top / std::filesystem::path(relative).relative_path());
  if (dir.lexically_relative(top).native().starts_with("..")) dir = top;
  std::optional<uint64_t> cpus;
  for (;; dir = dir.parent_path()) {
    const std::optional<uint64_t> here = cpus_in(dir);
    if (here.has_value() && (!cpus.has_value() || *here < *cpus)) cpus = here;
    if (dir == top || dir == dir.parent_path()) break;
  }
  return cpus;
}

// cgroup v2: `cpu.max` is "<quota> <period>" or "max <period>".
std::optional<uint64_t> CgroupV2Cpus(const CgroupPaths& paths, const std::string& self) {
  return TightestUpTo(paths.root, OwnCgroup(self, ""), [](const std::filesystem::path& dir) {
    const std::string text = ReadSmallFile(dir / "cpu.max");
    const std::string_view line = Trim(text);
    const size_t space = line.find(' ');
    if (space == std::string_view::npos) return std::optional<uint64_t>();
    return CpusOfQuota(line.substr(0, space), Trim(line.substr(space)));
  });
}

// cgroup v1: the cpu hierarchy (mounted at <root>/cpu) has cpu.cfs_quota_us (-1: none) and
// cpu.cfs_period_us.
std::optional<uint64_t> CgroupV1Cpus(const CgroupPaths& paths, const std::string& self) {
  return TightestUpTo(std::filesystem::path(paths.root) / "cpu", OwnCgroup(self, "cpu"),
                      [](const std::filesystem::path& dir) {
                        return CpusOfQuota(Trim(ReadSmallFile(dir / "cpu.cfs_quota_us")),
                                           Trim(ReadSmallFile(dir / "cpu.cfs_period_us")));
                      });
}

}  // namespace

uint32_t AvailableCpus(const CgroupPaths& paths, uint32_t hardware_cpus) {
  const uint32_t cpus = std::max(1u, hardware_cpus);
  const std::string self = ReadSmallFile(paths.self);
  std::optional<uint64_t> quota = CgroupV2Cpus(paths, self);
  if (!quota.has_value()) quota = CgroupV1Cpus(paths, self);
  if (!quota.has_value()) return cpus;
  return uint32_t(std::clamp<uint64_t>(*quota, 1, cpus));
}

void AddFlags(CLI::App& app, ServerConfig* config) {
  app.add_option("--listen", config->listen, "gRPC address (host:port, [v6]:port or unix:path)")
      ->capture_default_str();
  app.add_option("--data-dir", config->data_dir, "Directory of the store")->capture_default_str();
  app.add_option("--place-vocabulary", config->place_vocabulary,
                 "Vocabulary of new place maps (default: the bundled one)");
  app.add_option("--object-vocabulary", config->object_vocabulary,
                 "Vocabulary of object models (default: the bundled one)");
  app.add_option("--workers", config->workers,
                 "Worker threads (0 = one per CPU of the cgroup quota, else per hardware thread)")
      ->capture_default_str();
  app.add_option("--queue-capacity", config->queue_capacity,
                 "Tasks that may wait for a worker before calls fail with RESOURCE_EXHAUSTED")
      ->capture_default_str();
  app.add_option("--max-message-bytes", config->max_message_bytes,
                 "Largest request or response in bytes")
      ->capture_default_str();
  app.add_option("--token-file", config->token_file,
                 "YAML file of bearer tokens (default: no authentication)");
  app.add_option("--tls-cert", config->tls.cert, "PEM certificate chain of the server");
  app.add_option("--tls-key", config->tls.key, "PEM private key of the server");
  app.add_option("--tls-client-ca", config->tls.client_ca,
                 "PEM CA of client certificates (requires mutual TLS)");
  app.add_option("--metrics-listen", config->metrics_listen,
                 "Prometheus endpoint host:port (empty: none)")
      ->capture_default_str();
  app.add_option_function<std::string>(
         "--sync",
         // The check below lets only valid names through, so the parse cannot fail here.
         [config](const std::string& name) { config->store.sync = *ParseStoreSync(name); },
         "When the store fsyncs acknowledged writes")
      ->check(CLI::IsMember({std::string(StoreSyncName(StoreSync::kGrouped)),
                             std::string(StoreSyncName(StoreSync::kEveryWrite))}))
      ->default_str(std::string(StoreSyncName(config->store.sync)));
  app.add_option_function<std::string>(
         "--recover",
         [config](const std::string& name) { config->store.recover = *ParseStoreRecover(name); },
         "A damaged write-ahead log: refuse to start, or recover up to the damage (keeping a copy "
         "of the files) and report what was lost")
      ->check(CLI::IsMember({std::string(StoreRecoverName(StoreRecover::kRefuse)),
                             std::string(StoreRecoverName(StoreRecover::kPointInTime))}))
      ->default_str(std::string(StoreRecoverName(config->store.recover)));
  app.add_option("--shutdown-grace-ms", config->shutdown_grace_ms,
                 "Time calls in flight get to finish on SIGTERM/SIGINT")
      ->capture_default_str();
  app.add_option("--log-level", config->log_level, "trace, debug, info, warn, err, critical or off")
      ->capture_default_str();
  app.add_option("--shard-name", config->shard.name,
                 "This server's shard in the placement table (default: owns every map)");
  app.add_option("--placement-file", config->shard.placement_file,
                 "Placement table of sharded maps (map -> shard, nginx map syntax)");
  app.add_option("--repository-primary", config->repository.primary,
                 "Follow the model repository of this recogd (host:port) as a read-only replica");
  app.add_option("--repository-token-file", config->repository.token_file,
                 "File of the bearer token sent to the repository primary");
  app.add_option("--repository-tls-ca", config->repository.tls_ca,
                 "PEM CA of the repository primary's certificate (default: plaintext)");
  app.add_option("--console-listen", config->console.listen,
                 "Serve the web console on this address (host:port; default: no console)");
  app.add_option("--console-web-root", config->console.web_root,
                 "The console's pages (default: the bundled ones)");
  app.add_option("--console-charts-dir", config->console.charts_dir,
                 "Folder of the charts (.json beside `recog eval --plot` PNGs) the console shows");
}

StatusOr<CommandLine> ParseCommandLine(int argc, const char* const* argv) {
  CommandLine result;
  // First pass: find --config, catch --help and bad flags. The flags land in a scratch copy.
  ServerConfig scratch;
  RECOG_RETURN_IF_ERROR(ParseWith(argc, argv, &result.config_file, &scratch, &result.help,
                                  &result.version, &result.verify));
  if (!result.help.empty() || result.version) return result;
  if (!result.config_file.empty()) {
    RECOG_ASSIGN_OR_RETURN(result.config, ServerConfig::LoadYaml(result.config_file));
  }
  // Second pass: the flags given override what the file set.
  std::string unused_help;
  bool unused_version = false;
  RECOG_RETURN_IF_ERROR(ParseWith(argc, argv, &result.config_file, &result.config, &unused_help,
                                  &unused_version, &result.verify));
  RECOG_RETURN_IF_ERROR(result.config.Validate());
  return result;
}

}  // namespace recog::server
