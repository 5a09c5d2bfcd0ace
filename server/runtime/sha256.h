// SHA-256 of a byte string as lowercase hex (OpenSSL), for model uploads and downloads.
#pragma once

#include <string>
#include <string_view>

namespace recog::server {

std::string Sha256Hex(std::string_view bytes);

}  // namespace recog::server
