// The detector settings of a MapSettings message as text, by field name: the proto side of the one
// settings table (core/place/detector_settings.h), whose names are MapSettings' field names. The
// server turns a request's settings into the detector's parameters through it, and the clients
// (`recog maps create`, the load generator) fill a request from the table's flags through it, so
// that adding a setting to the table and to the message is all a new setting needs.
//
// Text is what the table reads and writes: reals with 17 significant digits, whole numbers in
// decimal, strings as they are, and an enum by its value's name without the enum's prefix, in
// lower case (GEOMETRY_CHECK_DIRECT_INDEX is "direct_index"; the zero value, *_UNSPECIFIED, is
// "not given").
#pragma once

#include <span>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "recognition/v1/place.pb.h"

namespace recog {

// The fields named `names` that `settings` gives (has_*), as (name, text) in the order of `names`,
// into *values. Returns an empty string, or what is wrong in one line for a name that is not a
// field of MapSettings this text stands for ("unknown setting 'alpah'"; *values is then empty):
// with the settings table's names, a programming error, which its callers report as such.
[[nodiscard]] std::string MapSettingsAsText(
    const ::recognition::v1::MapSettings& settings, std::span<const std::string_view> names,
    std::vector<std::pair<std::string, std::string>>* values);

// Sets the field `name` of *settings from `text`. Returns an empty string, or what is wrong in one
// line ("alpha: 'abc' is not a number", "unknown setting 'alpah'").
std::string SetMapSettingFromText(::recognition::v1::MapSettings* settings, std::string_view name,
                                  std::string_view text);

}  // namespace recog
