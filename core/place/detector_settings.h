// DetectorSettings: the one table of the loop detector's settings by name. Every place that reads
// or writes LoopDetectorParams as text goes through it: a map's stored settings (map_registry.cc),
// the server's YAML (`place:`), the proto (MapSettings, server/api/place_converters),
// `recog maps create`'s flags, `recog eval place --params` and the load generator's offline check.
// A setting has one name everywhere (the proto field, the YAML key, the store key; the CLI flag is
// the name with dashes), a kind, a range, and a one-line doc; its value in each preset is read from
// the preset (LoopDetectorParams{}, Thesis(), Keyframes()) rather than written again here.
// LoopDetectorParams::Validate checks each setting's range from this table
// (CheckDetectorSettingRanges); DetectorSettingsTable renders it for `recog settings` and
// docs/places.md, and PresetHelp the presets for a --preset flag, so that no value or range is
// typed anywhere else.
//
// `preset` is a setting too, and the first one applied: it replaces every value by its preset's,
// whatever the order the others were given in. A map keeps only the settings marked kept_by_map
// (the others are the detector's defaults for its preset when the server restarts), so only those
// are in MapSettings, the server's YAML and `recog maps create`.
#pragma once

#include <span>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "core/common/option_checks.h"
#include "core/common/status.h"
#include "core/place/loop_detector.h"

namespace recog {

enum class SettingKind {
  kPreset,  // a preset's name: default, thesis or keyframes
  kNumber,  // a finite real number in `range`
  kCount,   // a whole number in `range`
  kFlag,    // true or false
  kChoice,  // one of a few names (choices)
};

struct DetectorSetting {
  std::string_view name;
  SettingKind kind;
  bool kept_by_map;          // stored with a map (MapSettings, YAML, `recog maps create`)
  RealRange range;           // kNumber and kCount: the values LoopDetectorParams::Validate takes
  std::string_view choices;  // kPreset and kChoice: the names, comma-separated
  std::string_view doc;      // one line, for --help and the docs
};

// Every setting, `preset` first.
std::span<const DetectorSetting> DetectorSettings();

// The setting called `name`, or nullptr.
const DetectorSetting* FindDetectorSetting(std::string_view name);

// A preset and what it is for, in one line.
struct DetectorPresetInfo {
  DetectorPreset preset;
  std::string_view doc;
};
// Every preset, `default` first.
std::span<const DetectorPresetInfo> DetectorPresets();

// The value of `setting` in `params` as text that ParseDetectorSetting reads back exactly (reals
// with 17 significant digits, counts in decimal, flags as true/false, choices by name).
std::string FormatDetectorSetting(const DetectorSetting& setting, const LoopDetectorParams& params);
// The same value for people (help texts, tables): reals in their shortest form (0.3, not
// 0.29999999999999999), which may not read back to the same double.
std::string DisplayDetectorSetting(const DetectorSetting& setting,
                                   const LoopDetectorParams& params);

// A setting's value given as text, by its name.
using NamedSetting = std::pair<std::string, std::string>;

// Applies `values` to *params: the preset first (if given), then the others in order, each parsed
// and checked against its kind and range. INVALID_ARGUMENT naming the setting and the value for an
// unknown name, a malformed or out-of-range value, or a preset given twice; *params is unchanged
// then. The result must still pass LoopDetectorParams::Validate (cross-field conditions), checked
// last.
Status ApplyDetectorSettings(std::span<const NamedSetting> values, LoopDetectorParams* params);

// The settings kept_by_map, each with its value in `params`, `preset` first.
std::vector<NamedSetting> MapDetectorSettings(const LoopDetectorParams& params);
// Their names alone (MapSettings' detector fields).
std::span<const std::string_view> MapDetectorSettingNames();

// Checks the value in `params` of every number and count of the table against its range, under
// the setting's name ("LoopDetectorParams.min_inliers = 7: must be in [8, 100000]"):
// LoopDetectorParams::Validate's ranges of its settings.
void CheckDetectorSettingRanges(const LoopDetectorParams& params, OptionChecks* check);

// The presets (each with what it is for) and the settings (each with its value in the default
// preset, its value in another preset where that one differs, its range, whether a map keeps it,
// and its doc), as two tables. kMarkdown is docs/places.md's (a test compares the two); kText
// aligns the columns for a terminal (`recog settings`).
enum class SettingsTableFormat { kText, kMarkdown };
std::string DetectorSettingsTable(SettingsTableFormat format);

// The help of a --preset flag: one line per preset, what it is for and then the settings where it
// differs from `default`, with their values.
std::string PresetHelp();

}  // namespace recog
