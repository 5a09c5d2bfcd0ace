#include "core/common/names.h"

#include <string>

namespace recog {

Status ValidateName(std::string_view kind, std::string_view name) {
  constexpr size_t kMaxLength = 128;
  if (name.empty() || name.size() > kMaxLength) {
    return Status::InvalidArgument(std::string(kind) + " name must have 1 to 128 characters");
  }
  for (char c : name) {
    const bool ok = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') ||
                    c == '.' || c == '_' || c == '-';
    if (!ok) {
      return Status::InvalidArgument(std::string(kind) + " name '" + std::string(name) +
                                     "' may only use letters, digits, '.', '_' and '-'");
    }
  }
  return Status::Ok();
}

}  // namespace recog
