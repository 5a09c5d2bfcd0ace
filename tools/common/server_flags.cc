#include "tools/common/server_flags.h"

#include "wire/grpc_code_names.h"

namespace recog::cli {

void ServerFlags::AddTo(CLI::App* command) {
  command->add_option("--server", server, "recogd address host:port")
      ->capture_default_str()
      ->envname(kServerEnv);
  command->add_option("--token-file", token_file, "file holding the bearer token")
      ->envname(kTokenFileEnv);
  command->add_option("--tls-ca", tls_ca, "CA certificate (PEM) to trust; turns TLS on")
      ->envname(kTlsCaEnv);
  command->add_option("--tls-cert", tls_cert, "client certificate (PEM) for mutual TLS")
      ->envname(kTlsCertEnv);
  command->add_option("--tls-key", tls_key, "client key (PEM) for mutual TLS")->envname(kTlsKeyEnv);
  command->add_option("--shard", shard,
                      "behind a router of shards: the shard of calls without a map (maps list, "
                      "admin, recognition, model reads)");
  command->add_flag("--json", json, "print JSON");
}

client::Result<std::unique_ptr<client::RecognitionClient>> ServerFlags::Connect() const {
  client::ClientOptions options;
  options.target = server;
  options.token_file = token_file;
  options.tls.enabled = !tls_ca.empty() || !tls_cert.empty();
  options.tls.ca_file = tls_ca;
  options.tls.cert_file = tls_cert;
  options.tls.key_file = tls_key;
  options.shard = shard;
  if (timeout_ms > 0) options.deadline = std::chrono::milliseconds(timeout_ms);
  return client::RecognitionClient::Connect(options);
}

std::string DescribeStatus(const grpc::Status& status) {
  return std::string(GrpcCodeName(status.error_code())) + ": " + status.error_message();
}

}  // namespace recog::cli
