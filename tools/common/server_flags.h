// The flags every recog subcommand that talks to recogd takes, and the connection they describe.
//
//   --server HOST:PORT   the server (default 127.0.0.1:50051)            env RECOG_SERVER
//   --token-file FILE    a file holding the bearer token (default: none)  env RECOG_TOKEN_FILE
//   --tls-ca FILE        trust this CA and use TLS (default: plaintext)   env RECOG_TLS_CA
//   --tls-cert/--tls-key client certificate and key for mutual TLS       env RECOG_TLS_CERT,
//                        (default: none)                                     RECOG_TLS_KEY
//   --shard NAME         behind a router of shards: the shard of calls without a map (maps list)
//   --json               print machine-readable JSON instead of text
// A flag given on the command line wins over its environment variable (the names are the Python
// client's too). Connect() turns them into a RecognitionClient; a failure is one line for the
// caller to print.
#pragma once

#include <memory>
#include <string>

#include <CLI/CLI.hpp>

#include "client/cpp/recognition_client.h"

namespace recog::cli {

inline constexpr const char* kServerEnv = "RECOG_SERVER";
inline constexpr const char* kTokenFileEnv = "RECOG_TOKEN_FILE";
inline constexpr const char* kTlsCaEnv = "RECOG_TLS_CA";
inline constexpr const char* kTlsCertEnv = "RECOG_TLS_CERT";
inline constexpr const char* kTlsKeyEnv = "RECOG_TLS_KEY";

struct ServerFlags {
  std::string server = "127.0.0.1:50051";
  std::string token_file;
  std::string tls_ca, tls_cert, tls_key;
  std::string shard;
  bool json = false;
  // Default 0: the client's deadline of unary calls (ClientOptions::deadline). Not a flag of
  // every command (recog admin health adds --timeout-ms).
  uint32_t timeout_ms = 0;

  // Adds the flags above to `command`, bound to this object (which must outlive it).
  void AddTo(CLI::App* command);
  // Connects with these flags (and the client's default deadlines and retries).
  client::Result<std::unique_ptr<client::RecognitionClient>> Connect() const;
};

// "CODE: message" of a failed call, for the one-line errors of the subcommands.
std::string DescribeStatus(const grpc::Status& status);

}  // namespace recog::cli
