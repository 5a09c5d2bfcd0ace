// ServerTls: recogd's TLS server credentials, whose certificate, key and client CA can be replaced
// while the server runs (recogd: SIGHUP), without a restart.
//
// The credentials are gRPC's own rotating ones (TlsServerCredentials fed by a
// FileWatcherCertificateProvider), but the provider does not watch the configured files: it would
// hand a half-written or mismatched pair to the handshakes. Create and Reload first check the
// configured files (each PEM parses, the key belongs to the certificate, the client CA holds a
// certificate), and only then copy them into `live_dir` (mode 0700, emptied by Create), as a new
// directory made current by renaming a symlink, the atomic update gRPC's provider asks for. The
// provider re-reads the current copies every kRefreshSeconds, so connections made after a Reload
// use the new certificate within that time; connections already open keep theirs. A Reload whose
// files do not pass leaves the copies, and so the certificates in use, as they are.
//
// With tls.client_ca set, clients must present a certificate signed by it (mutual TLS).
// Not thread-safe: one thread (the one handling signals) calls Reload.
#pragma once

#include <memory>
#include <string>

#include <grpcpp/security/server_credentials.h>

#include "core/common/status.h"
#include "server/config/server_config.h"

namespace grpc::experimental {
class CertificateProviderInterface;
}

namespace recog::server {

class ServerTls {
 public:
  static constexpr unsigned kRefreshSeconds = 1;

  // `tls` must have cert and key. NOT_FOUND for a file that cannot be read, INVALID_ARGUMENT
  // naming the file (as its key, e.g. "tls.key") for one that does not parse or a key that does not
  // match the certificate; FAILED_PRECONDITION (or WriteFileAtomically's error) when `live_dir`
  // cannot be written.
  static StatusOr<std::unique_ptr<ServerTls>> Create(const TlsConfig& tls, std::string live_dir);
  ~ServerTls();
  ServerTls(const ServerTls&) = delete;
  ServerTls& operator=(const ServerTls&) = delete;

  // For grpc::ServerBuilder::AddListeningPort.
  std::shared_ptr<grpc::ServerCredentials> credentials() const { return credentials_; }

  // Checks the configured files again and makes them current (see the header comment). Errors as
  // Create's; on error the certificates in use are kept.
  Status Reload();

 private:
  ServerTls(TlsConfig tls, std::string live_dir);

  const TlsConfig tls_;
  const std::string live_dir_;
  int generation_ = 0;  // the number of the current copy, live_dir/<generation>
  std::shared_ptr<grpc::experimental::CertificateProviderInterface> provider_;
  std::shared_ptr<grpc::ServerCredentials> credentials_;
};

}  // namespace recog::server
