// The one rule for the names users give things (place maps, object models): 1 to 128 characters
// of [A-Za-z0-9._-]. Names become store keys, file names and metric labels, so they never hold a
// separator, a space or anything that would need quoting.
#pragma once

#include <string_view>

#include "core/common/status.h"

namespace recog {

// OK when `name` follows the rule; INVALID_ARGUMENT otherwise, naming `kind` ("map", "object"),
// e.g. "map name 'a b' may only use letters, digits, '.', '_' and '-'".
Status ValidateName(std::string_view kind, std::string_view name);

}  // namespace recog
