#include "core/index/entry.h"

#include "core/common/names.h"

namespace recog {

Status MapConfig::Validate() const {
  RECOG_RETURN_IF_ERROR(ValidateName("map", name));
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
