// SHA-256 (OpenSSL) as lowercase hex, the form the model repository uses in ModelInfo.sha256 and
// PutModelHeader.sha256. Internal to the client library.
#pragma once

#include <string>
#include <string_view>

#include "client/cpp/result.h"

namespace recog::client::internal {

// Of a whole file, read in pieces. NOT_FOUND when it cannot be opened, FAILED_PRECONDITION when
// reading fails.
Result<std::string> Sha256HexOfFile(const std::string& path);

}  // namespace recog::client::internal
