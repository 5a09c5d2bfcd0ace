#include "server/app/server_tls.h"

#include <openssl/bio.h>
#include <openssl/err.h>
#include <openssl/evp.h>
#include <openssl/pem.h>
#include <openssl/x509.h>

#include <filesystem>
#include <utility>

#include <grpcpp/security/tls_certificate_provider.h>
#include <grpcpp/security/tls_credentials_options.h>

#include "core/common/file_io.h"

namespace recog::server {
namespace {

namespace fs = std::filesystem;

constexpr char kCurrent[] = "current";  // the symlink to the current copy
constexpr char kCertFile[] = "cert.pem";
constexpr char kKeyFile[] = "key.pem";
constexpr char kClientCaFile[] = "client_ca.pem";

using Bio = std::unique_ptr<BIO, decltype(&BIO_free)>;
using Certificate = std::unique_ptr<X509, decltype(&X509_free)>;
using PrivateKey = std::unique_ptr<EVP_PKEY, decltype(&EVP_PKEY_free)>;

Bio MemoryBio(const std::string& text) {
  return Bio(BIO_new_mem_buf(text.data(), int(text.size())), BIO_free);
}

// Never asks for the passphrase of an encrypted key (OpenSSL would read the terminal).
int NoPassphrase(char*, int, int, void*) { return 0; }

// The first certificate of a PEM chain, after checking that every certificate in it parses.
StatusOr<Certificate> ParseChain(const std::string& pem, const std::string& what) {
  Bio bio = MemoryBio(pem);
  Certificate first(PEM_read_bio_X509(bio.get(), nullptr, NoPassphrase, nullptr), X509_free);
  if (first == nullptr) {
    ERR_clear_error();
    return Status::InvalidArgument(what + " holds no PEM certificate");
  }
  while (Certificate(PEM_read_bio_X509(bio.get(), nullptr, NoPassphrase, nullptr), X509_free)) {
  }
  // The loop ends at the end of the text (no further BEGIN line) or at a broken certificate.
  const unsigned long error = ERR_peek_last_error();
  ERR_clear_error();
  if (ERR_GET_LIB(error) != ERR_LIB_PEM || ERR_GET_REASON(error) != PEM_R_NO_START_LINE) {
    return Status::InvalidArgument(what + " holds a certificate that does not parse");
  }
  return first;
}

struct Files {
  std::string cert, key, client_ca;  // PEM texts; client_ca empty without mutual TLS
};

// Reads the configured files and checks them (see the header comment).
StatusOr<Files> ReadAndCheck(const TlsConfig& tls) {
  Files files;
  const auto what = [](const char* key, const std::string& path) {
    return std::string(key) + " '" + path + "'";
  };
  RECOG_ASSIGN_OR_RETURN(files.cert, ReadWholeFile(tls.cert, what("tls.cert", tls.cert)));
  RECOG_ASSIGN_OR_RETURN(files.key, ReadWholeFile(tls.key, what("tls.key", tls.key)));
  RECOG_ASSIGN_OR_RETURN(Certificate leaf, ParseChain(files.cert, what("tls.cert", tls.cert)));
  Bio key_bio = MemoryBio(files.key);
  PrivateKey key(PEM_read_bio_PrivateKey(key_bio.get(), nullptr, NoPassphrase, nullptr),
                 EVP_PKEY_free);
  const bool matches = key != nullptr && X509_check_private_key(leaf.get(), key.get()) == 1;
  ERR_clear_error();
  if (key == nullptr) {
    return Status::InvalidArgument(what("tls.key", tls.key) +
                                   " holds no unencrypted PEM private key");
  }
  if (!matches) {
    return Status::InvalidArgument(what("tls.key", tls.key) + " is not the key of " +
                                   what("tls.cert", tls.cert));
  }
  if (!tls.client_ca.empty()) {
    const std::string ca = what("tls.client_ca", tls.client_ca);
    RECOG_ASSIGN_OR_RETURN(files.client_ca, ReadWholeFile(tls.client_ca, ca));
    RECOG_RETURN_IF_ERROR(ParseChain(files.client_ca, ca).status());
  }
  return files;
}

// Writes `files` into live_dir/<generation> and points live_dir/current at it.
Status MakeCurrent(const Files& files, const fs::path& live_dir, int generation) {
  const fs::path copy = live_dir / std::to_string(generation);
  std::error_code error;
  fs::remove_all(copy, error);
  fs::create_directories(copy, error);
  if (error) {
    return Status::FailedPrecondition("cannot create '" + copy.string() + "': " + error.message());
  }
  RECOG_RETURN_IF_ERROR(WriteFileAtomically((copy / kCertFile).string(), {files.cert}));
  RECOG_RETURN_IF_ERROR(WriteFileAtomically((copy / kKeyFile).string(), {files.key}));
  if (!files.client_ca.empty()) {
    RECOG_RETURN_IF_ERROR(WriteFileAtomically((copy / kClientCaFile).string(), {files.client_ca}));
  }
  const fs::path link = live_dir / (std::string(kCurrent) + ".new");
  fs::remove(link, error);
  fs::create_directory_symlink(std::to_string(generation), link, error);
  if (!error)
    fs::rename(link, live_dir / kCurrent, error);  // atomic: the provider sees one or the other
  if (error) {
    return Status::FailedPrecondition("cannot switch '" + (live_dir / kCurrent).string() +
                                      "': " + error.message());
  }
  // The copy before the previous one: the provider may still be reading the previous one.
  fs::remove_all(live_dir / std::to_string(generation - 2), error);
  return Status::Ok();
}

}  // namespace

ServerTls::ServerTls(TlsConfig tls, std::string live_dir)
    : tls_(std::move(tls)), live_dir_(std::move(live_dir)) {}

ServerTls::~ServerTls() = default;

StatusOr<std::unique_ptr<ServerTls>> ServerTls::Create(const TlsConfig& tls, std::string live_dir) {
  RECOG_ASSIGN_OR_RETURN(const Files files, ReadAndCheck(tls));
  std::unique_ptr<ServerTls> server_tls(new ServerTls(tls, std::move(live_dir)));
  const fs::path dir(server_tls->live_dir_);
  std::error_code error;
  fs::remove_all(dir, error);  // copies left by an earlier run
  fs::create_directories(dir, error);
  if (!error) fs::permissions(dir, fs::perms::owner_all, error);
  if (error) {
    return Status::FailedPrecondition("cannot create '" + dir.string() + "': " + error.message());
  }
  server_tls->generation_ = 1;
  RECOG_RETURN_IF_ERROR(MakeCurrent(files, dir, server_tls->generation_));

  const fs::path current = dir / kCurrent;
  server_tls->provider_ = std::make_shared<grpc::experimental::FileWatcherCertificateProvider>(
      (current / kKeyFile).string(), (current / kCertFile).string(),
      tls.client_ca.empty() ? std::string() : (current / kClientCaFile).string(), kRefreshSeconds);
  grpc::experimental::TlsServerCredentialsOptions options(server_tls->provider_);
  options.watch_identity_key_cert_pairs();
  if (tls.client_ca.empty()) {
    options.set_cert_request_type(GRPC_SSL_DONT_REQUEST_CLIENT_CERTIFICATE);
  } else {
    options.watch_root_certs();
    options.set_cert_request_type(GRPC_SSL_REQUEST_AND_REQUIRE_CLIENT_CERTIFICATE_AND_VERIFY);
  }
  server_tls->credentials_ = grpc::experimental::TlsServerCredentials(options);
  return server_tls;
}

Status ServerTls::Reload() {
  RECOG_ASSIGN_OR_RETURN(const Files files, ReadAndCheck(tls_));
  RECOG_RETURN_IF_ERROR(MakeCurrent(files, live_dir_, generation_ + 1));
  ++generation_;
  return Status::Ok();
}

}  // namespace recog::server
