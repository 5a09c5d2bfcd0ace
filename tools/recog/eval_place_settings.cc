// recog eval place's settings (eval_place.h): --preset and --params in, the report's
// "parameters" out. A report lists every setting, so given back as --params it sets them all and
// the run gives the same result.
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <string_view>
#include <type_traits>
#include <utility>
#include <variant>
#include <vector>

#include <yaml-cpp/yaml.h>

#include "core/bow/scoring.h"
#include "core/place/detector_settings.h"
#include "tools/recog/eval_place.h"

namespace recog::cli {
namespace {

// A setting of the rig detector beyond its loop detector's (RigLoopParams), by the name --params
// and the report give it.
struct RigSetting {
  std::string_view name;
  std::variant<uint32_t RigLoopParams::*, double RigLoopParams::*> field;
};

const RigSetting kRigSettings[] = {
    {"max_verified_frames", &RigLoopParams::max_verified_frames},
    {"max_rotation_disagreement_deg", &RigLoopParams::max_rotation_disagreement_deg},
    {"min_consistent_ratio", &RigLoopParams::min_consistent_ratio},
};

const RigSetting* FindRigSetting(std::string_view name) {
  for (const RigSetting& setting : kRigSettings) {
    if (setting.name == name) return &setting;
  }
  return nullptr;
}

// A setting's value in `params` as typed JSON: FormatDetectorSetting's text (reals with 17
// significant digits, so the double is exact) as a number, a boolean or a name.
nlohmann::json SettingJson(const DetectorSetting& setting, const LoopDetectorParams& params) {
  const std::string text = FormatDetectorSetting(setting, params);
  switch (setting.kind) {
    case SettingKind::kNumber:
      return std::strtod(text.c_str(), nullptr);
    case SettingKind::kCount:
      return std::stoull(text);
    case SettingKind::kFlag:
      return text == "true";
    case SettingKind::kPreset:
    case SettingKind::kChoice:
      break;
  }
  return text;
}

// Reads --params: a YAML map of the settings table's names (core/place/detector_settings.h; a
// `preset` among them applies first), the evaluation's own `features`, `direct_index_levels_up`
// and `scoring`, and with --rig (`rig`) the rig's own settings; or a report of recog eval place
// --json (JSON is YAML), whose "parameters" are such a map with the report's `vocabulary` besides,
// which is skipped: the vocabulary is --vocab's. Unknown keys are an error (typos must not pass
// silently).
Status ReadParams(const std::string& path, bool rig, EvalPlaceSettings* settings) {
  YAML::Node root;
  try {
    root = YAML::LoadFile(path);
  } catch (const YAML::BadFile&) {
    return Status::NotFound("parameter file '" + path + "' cannot be read");
  } catch (const YAML::Exception& e) {
    return Status::InvalidArgument("parameter file '" + path + "': " + e.what());
  }
  if (!root.IsMap()) return Status::InvalidArgument("parameter file '" + path + "' is not a map");
  const std::string context = "parameter file '" + path + "'";
  const bool report = bool(std::as_const(root)["parameters"]);
  const YAML::Node values = report ? std::as_const(root)["parameters"] : root;
  if (!values.IsMap()) return Status::InvalidArgument(context + ": 'parameters' is not a map");
  PlaceEvaluationOptions& options = settings->options;
  std::vector<NamedSetting> detector_settings;
  try {
    for (const auto& item : values) {
      const std::string key = item.first.as<std::string>();
      const YAML::Node& value = item.second;
      if (!value.IsScalar()) {
        return Status::InvalidArgument(context + ": '" + key + "' is not a single value");
      }
      if (report && key == "vocabulary") continue;
      if (key == "direct_index_levels_up") {
        options.direct_index_levels_up = value.as<uint32_t>();
      } else if (key == "features") {
        settings->features = value.as<int>();
      } else if (key == "scoring") {
        RECOG_ASSIGN_OR_RETURN(options.scoring, ParseScoring(value.Scalar()));
      } else if (const RigSetting* rig_setting = FindRigSetting(key)) {
        if (!rig) return Status::InvalidArgument(context + ": '" + key + "' is a setting of --rig");
        std::visit(
            [&](auto field) {
              using Value = std::remove_reference_t<decltype(settings->rig.*field)>;
              settings->rig.*field = value.as<Value>();
            },
            rig_setting->field);
      } else {
        detector_settings.emplace_back(key, value.Scalar());
      }
    }
  } catch (const YAML::Exception& e) {
    return Status::InvalidArgument(context + ": " + e.what());
  }
  Status applied = ApplyDetectorSettings(detector_settings, &options.detector);
  if (applied.ok() && rig) {
    RigLoopParams checked = settings->rig;
    checked.detector = options.detector;
    applied = checked.Validate();
  }
  return applied.ok() ? applied : applied.WithContext(context);
}

}  // namespace

const std::string& PresetFlag(const EvalPlaceArgs& args) {
  return args.deprecated_mode.empty() ? args.preset : args.deprecated_mode;
}

StatusOr<EvalPlaceSettings> ReadEvalPlaceSettings(const EvalPlaceArgs& args) {
  if (!args.deprecated_mode.empty()) {
    std::fprintf(stderr, "recog eval place: --mode is deprecated, use --preset %s\n",
                 args.deprecated_mode.c_str());
  }
  EvalPlaceSettings settings;
  const std::vector<NamedSetting> preset = {{"preset", PresetFlag(args)}};
  RECOG_RETURN_IF_ERROR(ApplyDetectorSettings(preset, &settings.options.detector));
  settings.features = args.features;
  if (!args.params_file.empty()) {
    RECOG_RETURN_IF_ERROR(ReadParams(args.params_file, !args.rig.empty(), &settings));
  }
  return settings;
}

nlohmann::json ParametersJson(const EvalPlaceSettings& settings, const std::string& vocabulary_path,
                              bool rig) {
  const PlaceEvaluationOptions& options = settings.options;
  nlohmann::json out = {{"features", settings.features},
                        {"direct_index_levels_up", options.direct_index_levels_up},
                        {"scoring", std::string(ScoringName(options.scoring))},
                        {"vocabulary", vocabulary_path}};
  for (const DetectorSetting& setting : DetectorSettings()) {
    out[std::string(setting.name)] = SettingJson(setting, options.detector);
  }
  if (rig) {
    for (const RigSetting& setting : kRigSettings) {
      std::visit([&](auto field) { out[std::string(setting.name)] = settings.rig.*field; },
                 setting.field);
    }
  }
  return out;
}

std::string ChangedSettingsLine(const LoopDetectorParams& params) {
  const std::string_view preset = DetectorPresetName(params.preset);
  const LoopDetectorParams base = ParseDetectorPreset(preset).value();
  std::string line = "settings: preset " + std::string(preset);
  for (const DetectorSetting& setting : DetectorSettings()) {
    if (FormatDetectorSetting(setting, params) == FormatDetectorSetting(setting, base)) continue;
    // The JSON text: the shortest that reads back as the same double (0.7, not 0.69999...).
    const nlohmann::json value = SettingJson(setting, params);
    line += ", " + std::string(setting.name) + " " +
            (value.is_string() ? value.get<std::string>() : value.dump());
  }
  return line;
}

}  // namespace recog::cli
