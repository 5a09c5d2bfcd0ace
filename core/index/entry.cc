#include "core/index/entry.h"

namespace recog {

Status ValidateMapName(const std::string& name) {
  if (name.empty() || name.size() > 128) {
    return Status::InvalidArgument("map name must have 1 to 128 characters");
  }
  for (char c : name) {
    const bool ok = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') ||
                    c == '.' || c == '_' || c == '-';
    if (!ok) {
      return Status::InvalidArgument("map name '" + name +
                                     "' may only use letters, digits, '.', '_' and '-'");
    }
  }
  return Status::Ok();
}

Status MapConfig::Validate() const {
  RECOG_RETURN_IF_ERROR(ValidateMapName(name));
  if (vocabulary_checksum == 0 || vocabulary_words == 0 || vocabulary_nodes < vocabulary_words) {
    return Status::InvalidArgument("map '" + name + "' needs its vocabulary's checksum and size");
  }
  RECOG_RETURN_IF_ERROR(descriptor.Validate());
  if (uint8_t(scoring) > uint8_t(ScoringType::kDotProduct)) {
    return Status::InvalidArgument("unknown scoring " + std::to_string(int(scoring)));
  }
  if (direct_index_levels_up > 255) {
    return Status::InvalidArgument("direct_index_levels_up must be at most 255");
  }
  return Status::Ok();
}

}  // namespace recog
