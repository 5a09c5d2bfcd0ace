// SHA-256 (OpenSSL) as lowercase hex: the checksum of model files on the wire
// (PutModelHeader.sha256, ModelInfo.sha256), shared by the server and the clients.
#pragma once

#include <memory>
#include <string>
#include <string_view>

struct evp_md_ctx_st;

namespace recog {

// Incremental hashing: Update with the bytes in order, then HexDigest once.
class Sha256 {
 public:
  Sha256();
  ~Sha256();
  Sha256(const Sha256&) = delete;
  Sha256& operator=(const Sha256&) = delete;

  void Update(std::string_view bytes);
  std::string HexDigest();

 private:
  evp_md_ctx_st* context_;
};

// The digest of one byte string.
std::string Sha256Hex(std::string_view bytes);

}  // namespace recog
