#include "client/cpp/sha256.h"

#include <array>
#include <fstream>

#include "wire/sha256.h"

namespace recog::client::internal {

Result<std::string> Sha256HexOfFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return grpc::Status(grpc::StatusCode::NOT_FOUND, "cannot open '" + path + "'");
  Sha256 sha;
  std::array<char, 1 << 16> buffer;
  while (in.read(buffer.data(), buffer.size()) || in.gcount() > 0) {
    sha.Update(std::string_view(buffer.data(), size_t(in.gcount())));
  }
  if (in.bad()) {
    return grpc::Status(grpc::StatusCode::FAILED_PRECONDITION, "cannot read '" + path + "'");
  }
  return sha.HexDigest();
}

}  // namespace recog::client::internal
