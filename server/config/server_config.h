// ServerConfig: everything recogd can be configured with, from a YAML file and command-line flags.
//
// A configuration starts from the defaults documented on each field, then the YAML file named by
// --config (if any) overrides them, then the flags given on the command line override the file:
// `recogd --config recogd.yaml --workers 8` takes everything from the file except the number of
// workers. The YAML keys are the field names, with the nested structs as sections:
//
//   listen: "0.0.0.0:50051"
//   data_dir: /var/lib/recog
//   keepalive: {time_ms: 20000, timeout_ms: 10000}
//   tls: {cert: server.crt, key: server.key, client_ca: robots-ca.crt}
//   store: {sync: every_write}
//   place: {alpha: 0.3, geometry: direct_index}
//
// An unknown key or a value of the wrong type is an error naming the key, so that a typo is never
// silently ignored. Loading does not validate: Validate() checks the combination of values
// (ParseCommandLine calls it). The struct is a plain value, safe to copy and to read from any
// number of threads.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include <CLI/CLI.hpp>

#include "core/common/status.h"
#include "core/place/loop_detector.h"

namespace recog::server {

// When the store fsyncs an acknowledged write (mirrors storage's SyncPolicy; the server converts).
enum class StoreSync {
  kGrouped,     // a background thread fsyncs the write-ahead log every group_sync_interval_ms
  kEveryWrite,  // every write is fsync'ed before it is acknowledged
};
std::string_view StoreSyncName(StoreSync sync);  // "grouped", "every_write"
StatusOr<StoreSync> ParseStoreSync(std::string_view name);

// What start-up does with a write-ahead log damaged anywhere but in its torn last write (mirrors
// storage's DamagedLogPolicy; see storage/rocksdb_index_store.h, "Damage").
enum class StoreRecover {
  kRefuse,       // recogd exits 1 naming the log file and the damage; nothing is rewritten
  kPointInTime,  // keep a copy of the files, recover to the damage, log and count what was lost
};
std::string_view StoreRecoverName(StoreRecover recover);  // "refuse", "point-in-time"
StatusOr<StoreRecover> ParseStoreRecover(std::string_view name);

// HTTP/2 keepalive, tuned for robots on Wi-Fi: dead connections are noticed within
// time_ms + timeout_ms, and clients may ping idle connections.
struct KeepaliveConfig {
  // Default 20000: the server pings a connection that has been idle this long.
  uint32_t time_ms = 20000;
  // Default 10000: a ping not answered within this time closes the connection.
  uint32_t timeout_ms = 10000;
  // Default true: pings are sent (and accepted) on connections without an active call.
  bool permit_without_calls = true;
  // Default 10000: clients pinging more often than this are sent GOAWAY (too_many_pings).
  uint32_t min_ping_interval_ms = 10000;
};

// What the gRPC port lets one client take (docs/server.md, "Security"). Compressed requests
// (grpc-encoding other than identity) are always refused: gRPC 1.51 inflates a message before it
// checks max_message_bytes, so a few hundred kilobytes of gzip could take gigabytes.
struct GrpcLimitsConfig {
  // Default 100: calls one connection may have open at once (HTTP/2 SETTINGS
  // MAX_CONCURRENT_STREAMS); 1 to 10000.
  uint32_t max_concurrent_streams = 100;
  // Default 128: MiB that gRPC's transport (connections, read buffers, calls) may hold in all
  // (gRPC's resource quota; beyond it gRPC refuses new calls and shrinks its buffers); 16 to
  // 65536.
  uint32_t memory_quota_mb = 128;
  // Default 128: MiB of requests taken and not yet answered (waiting for a worker or being
  // worked on), by their serialised size; a call beyond it is refused with RESOURCE_EXHAUSTED and
  // a retry hint. At least max_message_bytes, at most 65536.
  uint32_t pending_requests_mb = 128;
  // Default 256: MiB that the images of one call may take to decode, together (the decoded
  // images, and the decoder's buffers of the one being decoded: a progressive JPEG holds 2 bytes
  // a sample); beyond it the call is refused with INVALID_ARGUMENT naming the image. At most
  // workers x this is spent on images at once. 16 to 65536; below 128 it also lowers the 128 MiB
  // that one image may take.
  uint32_t decode_memory_mb = 256;
  // Default 300000 (5 minutes): a connection without a call for this long is closed (GOAWAY;
  // clients reconnect by themselves); 0 = never. Otherwise at least 1000.
  uint32_t max_connection_idle_ms = 300000;
  // Default 0 = never: a connection older than this is closed (GOAWAY), its calls given
  // max_connection_age_grace_ms to finish; robots streaming a session for hours keep the default.
  // Otherwise at least 1000.
  uint32_t max_connection_age_ms = 0;
  // Default 30000: how long calls of a connection closed for its age may still run.
  uint32_t max_connection_age_grace_ms = 30000;
  // Default 64: descriptors kept free below the process's limit (ulimit -n); a new connection
  // beyond is closed at once, so that running out of descriptors never stops the port (see
  // server/app/grpc_listener.h); 16 to 65536.
  uint32_t reserve_descriptors = 64;
};

// Transport security. All empty (the default): plaintext. cert and key: TLS. client_ca as well:
// mutual TLS, every client must present a certificate signed by that CA.
struct TlsConfig {
  std::string cert;       // default "": PEM file of the server's certificate chain
  std::string key;        // default "": PEM file of the server's private key
  std::string client_ca;  // default "": PEM file of the CA that signs client certificates
};

// The RocksDB store under data_dir (see storage/rocksdb_index_store.h).
struct StoreConfig {
  // Default kGrouped ("grouped"): writes survive a crash of the process; a crash of the machine
  // may lose the last group_sync_interval_ms of them. "every_write": durable, slower.
  StoreSync sync = StoreSync::kGrouped;
  // Default 50: how often the grouped policy fsyncs, 1 to 60000 ms.
  uint32_t group_sync_interval_ms = 50;
  // Default 64: block cache shared by all column families, in MiB; 0 turns it off.
  uint64_t block_cache_mb = 64;
  // Default kRefuse ("refuse"): a damaged write-ahead log stops the start-up. "point-in-time"
  // accepts losing the writes after the damage, once the operator has decided to (--recover).
  StoreRecover recover = StoreRecover::kRefuse;
  // Default 86400 (a day): how often a background check reads every file of the store and checks
  // its checksums (storage's Verify); 0 turns it off. The first check runs one period after
  // start-up.
  uint32_t verify_interval_s = 86400;
  // Default 32: the background check and `recog admin verify` read at most this many MiB a
  // second, 1 to 65536, so that queries keep the disk.
  uint32_t verify_mb_per_s = 32;
};

// Sharding place maps across servers (placement_table.h, docs/scaling.md). Both empty (the
// default): this server owns every map. Both set: it serves only the maps the placement table
// gives to `name`, and refuses the others with FAILED_PRECONDITION naming their owner.
struct ShardConfig {
  std::string name;            // default "": this server's shard ([A-Za-z0-9_], 1..64)
  std::string placement_file;  // default "": the placement table (re-read on SIGHUP)
};

// Replicating the object model repository (docs/scaling.md). `primary` empty (the default): this
// server's repository takes uploads and deletions. Set: this server is a read-only replica of the
// repository of the recogd at `primary`. It follows that repository (its versions, tags and
// deletions, with the same version numbers; see server/replication/repository_follower.h),
// refuses uploads and deletions with FAILED_PRECONDITION naming the primary, and goes on
// serving what it holds while the primary is unreachable.
struct RepositoryConfig {
  std::string primary;     // default "": address of the primary recogd (host:port)
  std::string token_file;  // default "": file of the bearer token sent to the primary; "" = none
  std::string tls_ca;      // default "": PEM CA of the primary's certificate; "" = plaintext
};

// What one of recogd's HTTP ports (the console, the metrics) answers, and how much a client may
// take of it (server/http/guarded_http_server.h): every request is held to these limits before
// anything of it is routed. The defaults are the console's; MetricsConfig's connection caps are
// lower.
struct HttpPortConfig {
  // Default []: host names the port answers to besides IP addresses and "localhost" (the names
  // of its URL, e.g. behind a proxy: ["recog.example.com"]). A request whose Host (or, on the
  // console, Origin) names another host is refused with 403, so that a web page cannot reach
  // the port through a name it rebinds to this machine's address (DNS rebinding).
  std::vector<std::string> hosts;
  // Default 32: connections served at once, a thread each (1..1024). One more takes the place of
  // the connection that has waited longest (over a second) for its request's headers, or is
  // refused with 503 when none has.
  uint32_t max_connections = 32;
  // Default 8: connections one client address may hold at once (1..max_connections); the same
  // rule as max_connections within the address.
  uint32_t max_connections_per_client = 8;
  // Default 30000: milliseconds a client has to send a whole request, and again to take its
  // answer, however slowly it sends (1000..600000).
  uint32_t request_timeout_ms = 30000;
  // Default 10000: milliseconds a client has to send a request's line and headers (1000..600000;
  // at most request_timeout_ms applies); later: 408 and the connection closed.
  uint32_t header_timeout_ms = 10000;
  // Default 1024: after its first second, a request (and its answer) must move at least this
  // many bytes a second on average, or the connection is closed (408 before its headers are
  // whole); 0 = no minimum, at most 1073741824.
  uint32_t min_bytes_per_s = 1024;
  // Default 100: header lines a request may have (1..10000); more: 431 and the connection closed.
  uint32_t max_header_lines = 100;
  // Default 16384: bytes of a request's line and headers together (1024..1048576); more: 431 and
  // the connection closed.
  uint32_t max_header_bytes = 16384;
};

// The web console (server/console/): pages and an HTTP/JSON API over the same services, on its
// own address. `listen` empty (the default): no console, and the gRPC path does nothing for it.
// It uses the server's TLS files (tls.cert/key; with tls.client_ca, browsers must present a
// client certificate too) and its tokens: a read token may look, a write token may change. Its
// port's limits are HttpPortConfig's, as keys of the same section.
struct ConsoleConfig : HttpPortConfig {
  std::string listen;  // default "": host:port of the console ("127.0.0.1:8080"); "" = off
  // Default "": the console's pages; empty means the bundled ones (server/console/web, or the
  // installed copy).
  std::string web_root;
  // Default "/usr/share/javascript": where Debian's libjs-three and libjs-chart.js are (served
  // under /vendor/).
  std::string vendor_dir = "/usr/share/javascript";
  // Default 50: the last loops each map answered, kept in memory for the console (1..1000).
  uint32_t loops_per_map = 50;
  // Default "": a folder of charts (the .json that `recog eval ... --plot` writes beside each
  // PNG) shown on the console's Charts page; empty means none.
  std::string charts_dir;
  // Default 16777216 (16 MiB): the largest body of a call of the JSON gateway (a photo for "Try
  // it" in base64 and the rest of the request), 1024..2147483647; larger: 413 before it is read.
  uint64_t max_body_bytes = 16u << 20;
  // Default 33554432 (32 MiB): the bodies the gateway reads and decodes at once, all calls
  // together (max_body_bytes..17179869184); a call that would go beyond: 503 before its body is
  // read. The memory they take is about 4 times as much (two 16 MiB bodies: +129 MiB).
  uint64_t max_inflight_body_bytes = 32u << 20;
};

// The metrics port (`metrics_listen`): its limits, as HttpPortConfig's with fewer connections.
struct MetricsConfig : HttpPortConfig {
  MetricsConfig() {
    max_connections = 8;             // default 8 (a scraper or two, and a person with curl)
    max_connections_per_client = 4;  // default 4
  }
};

struct ServerConfig {
  // Default "127.0.0.1:50051": the gRPC address (host:port, [v6]:port or unix:path).
  std::string listen = "127.0.0.1:50051";
  // Default "./recog-data": the directory of the store (maps, entries, object models).
  std::string data_dir = "./recog-data";
  // Default "": the vocabulary of new place maps; empty means the bundled place vocabulary.
  std::string place_vocabulary;
  // Default "": the vocabulary of object models; empty means the bundled object vocabulary.
  std::string object_vocabulary;
  // Default 0: threads recognising frames; 0 means one per CPU this process may use: the
  // container's or service's CPU quota when there is one, else the hardware threads (see
  // WorkerCount()).
  uint32_t workers = 0;
  // Default 64: tasks that may wait for a worker; beyond that, calls fail with
  // RESOURCE_EXHAUSTED. At least 1.
  uint32_t queue_capacity = 64;
  // Default 100: the retry delay (ms) suggested to clients with RESOURCE_EXHAUSTED (and with
  // UNAVAILABLE while starting or draining), sent as gRPC's `grpc-retry-pushback-ms` trailer.
  uint32_t retry_after_ms = 100;
  // Default 10000: answers of mutating calls remembered by their request_id (for 10 minutes each,
  // the oldest forgotten first) so that a retried call is not applied twice; at most 1000000;
  // 0 = none (request ids are still checked). Per process: a restart forgets them.
  uint32_t request_log_entries = 10000;
  // Default 32 MiB: the largest request or response, enough for a 1920x1080 PNG or raw BGR
  // frame. 1 MiB to 2 GiB - 1 (gRPC's limit).
  uint32_t max_message_bytes = 32u << 20;
  KeepaliveConfig keepalive;  // YAML section "keepalive"
  GrpcLimitsConfig grpc;      // YAML section "grpc"
  TlsConfig tls;              // YAML section "tls"
  // Default "": the token file (server/auth/token_auth.h); empty means no authentication.
  std::string token_file;
  // Default "127.0.0.1:9464": the Prometheus endpoint (host:port, serves /metrics); empty means
  // none.
  std::string metrics_listen = "127.0.0.1:9464";
  MetricsConfig metrics;        // YAML section "metrics": the limits of that port
  StoreConfig store;            // YAML section "store"
  ShardConfig shard;            // YAML section "shard"
  RepositoryConfig repository;  // YAML section "repository"
  ConsoleConfig console;        // YAML section "console"
  // Default 10000: on SIGTERM/SIGINT, calls in flight get this long to finish before they are
  // cancelled.
  uint32_t shutdown_grace_ms = 10000;
  // Default "info": spdlog level: trace, debug, info, warn (or warning), err (or error),
  // critical or off.
  std::string log_level = "info";
  // Loop detector parameters of new place maps: the `default` preset unless the YAML says
  // otherwise (defaults: `recog settings`, docs/places.md). YAML section "place" with the
  // settings a map keeps (core/place/detector_settings.h, kept_by_map), by their names there:
  // `preset` (the one the other keys start from) and the others; the parameters a map does not
  // keep take the preset's values. "mode" is the deprecated name of "preset".
  LoopDetectorParams place;

  // Defaults overridden by the YAML file at `path`. NOT_FOUND when the file is missing;
  // INVALID_ARGUMENT naming the key for unknown keys and values of the wrong type, with the line
  // for YAML syntax errors. Does not call Validate().
  static StatusOr<ServerConfig> LoadYaml(const std::string& path);

  // INVALID_ARGUMENT naming the first bad field (as its YAML key, e.g. "tls.key").
  Status Validate() const;

  // The number of worker threads: `workers`, or when 0 AvailableCpus(the process's cgroups, the
  // hardware concurrency).
  uint32_t WorkerCount() const;
};

// Where AvailableCpus looks: the cgroup file system and the process's own line(s) in it.
struct CgroupPaths {
  std::string root = "/sys/fs/cgroup";     // the cgroup (v2) or cgroup-v1 mount root
  std::string self = "/proc/self/cgroup";  // "0::/system.slice/recogd.service" for cgroup v2
};

// The CPUs the process may use: ceil(quota / period) of the tightest CPU quota of its cgroup and
// its ancestors up to `paths.root` (cgroup v2: `cpu.max` along the "0::" line of `paths.self`;
// else v1: `cpu.cfs_quota_us` / `cpu.cfs_period_us` under `paths.root`/cpu along the line of the
// cpu controller), at least 1 and at most `hardware_cpus`. `hardware_cpus` (at least 1) when
// there is no quota ("max", -1), no such file, or a malformed one.
uint32_t AvailableCpus(const CgroupPaths& paths, uint32_t hardware_cpus);

// Adds one flag per commonly changed field (--listen, --data-dir, --place-vocabulary,
// --object-vocabulary, --workers, --queue-capacity, --max-message-bytes, --token-file,
// --tls-cert, --tls-key, --tls-client-ca, --metrics-listen, --sync, --recover, --shutdown-grace-ms,
// --log-level, --shard-name, --placement-file, --repository-primary, --repository-token-file,
// --repository-tls-ca), bound to `config`: parsing `app` overwrites exactly
// the fields whose flags were given. The help shows the values `config` holds now as defaults.
// `config` must outlive `app`.
void AddFlags(CLI::App& app, ServerConfig* config);

// The result of ParseCommandLine.
struct CommandLine {
  ServerConfig config;      // defaults, then the --config file, then the flags; validated
  std::string config_file;  // the value of --config; empty when none was given
  // Not empty when --help (-h) was given: the usage text, for the caller to print before it
  // exits successfully. `config` then holds the defaults and nothing else was checked.
  std::string help;
  // True when --version was given: the caller prints its version and exits successfully. `config`
  // then holds the defaults and nothing else was checked.
  bool version = false;
  // True when --verify was given: the caller opens the store of `config`, checks every file of it
  // (as fast as the disk goes), prints what it found and exits: 0 when the store is whole.
  bool verify = false;
};

// Parses recogd's command line: `--config FILE` (-c), --version and the flags of AddFlags. Flags
// override the file wherever they stand relative to --config. Never prints and never exits:
// INVALID_ARGUMENT with CLI11's message for unknown flags and bad values, the errors of LoadYaml
// for the file, and those of Validate() for the result.
StatusOr<CommandLine> ParseCommandLine(int argc, const char* const* argv);

}  // namespace recog::server
