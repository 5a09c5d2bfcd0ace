// UnixSocketAddress: a gRPC address ("unix:<dir>/<name>.sock") for a server a test starts, or for
// one that never comes up. Unlike a TCP port picked in advance, no other process can take it
// between the test choosing it and the server binding it.
#pragma once

#include <sys/un.h>

#include <filesystem>
#include <stdexcept>
#include <string>

namespace recog::testing {

inline std::string UnixSocketAddress(const std::filesystem::path& dir,
                                     const std::string& name = "grpc") {
  const std::string path = (dir / (name + ".sock")).string();
  if (path.size() >= sizeof(sockaddr_un{}.sun_path)) {
    throw std::length_error("a unix socket path must be shorter than 108 bytes: " + path);
  }
  return "unix:" + path;
}

}  // namespace recog::testing
