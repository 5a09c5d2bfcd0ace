#include "core/place/detector_settings.h"

#include <charconv>
#include <cmath>
#include <cstdio>
#include <limits>
#include <type_traits>
#include <variant>

namespace recog {
namespace {

constexpr double kMaxCount = std::numeric_limits<uint32_t>::max();

// Where a number, count or flag lives in LoopDetectorParams.
using FieldRef = std::variant<double*, uint32_t*, size_t*, int*, bool*>;

// A setting and how its value is reached: `field` for numbers, counts and flags; the two choice
// functions for kChoice (the preset is handled by ApplyDetectorSettings itself).
struct Row {
  DetectorSetting setting;
  FieldRef (*field)(LoopDetectorParams&) = nullptr;
  Status (*parse_choice)(std::string_view, LoopDetectorParams*) = nullptr;
  std::string_view (*format_choice)(const LoopDetectorParams&) = nullptr;
};

Row Number(std::string_view name, bool kept, const RealRange& range, std::string_view doc,
           FieldRef (*field)(LoopDetectorParams&)) {
  return {{name, SettingKind::kNumber, kept, range, {}, doc}, field};
}
Row Count(std::string_view name, bool kept, double min, double max, std::string_view doc,
          FieldRef (*field)(LoopDetectorParams&)) {
  return {{name, SettingKind::kCount, kept, RealRange::Closed(min, max), {}, doc}, field};
}
Row Flag(std::string_view name, std::string_view doc, FieldRef (*field)(LoopDetectorParams&)) {
  return {{name, SettingKind::kFlag, false, {}, {}, doc}, field};
}

const std::vector<Row>& Rows() {
  using P = LoopDetectorParams;
  static const std::vector<Row> rows = {
      {{"preset",
        SettingKind::kPreset,
        true,
        {},
        "default, thesis, keyframes",
        "the parameter set the other settings apply over"}},
      Number("alpha", true, RealRange::AtLeast(0), "minimum normalised score eta of a candidate",
             [](P& p) -> FieldRef { return &p.alpha; }),
      Count("temporal_matches", true, 0, kMaxCount, "k: consistent previous queries a loop needs",
            [](P& p) -> FieldRef { return &p.temporal_matches; }),
      Count("min_inliers", true, 8, 100000, "RANSAC inliers of the fundamental matrix a loop needs",
            [](P& p) -> FieldRef { return &p.epipolar.min_inliers; }),
      {{"geometry",
        SettingKind::kChoice,
        true,
        {},
        "direct_index, exhaustive, none",
        "how candidates are verified"},
       nullptr,
       [](std::string_view text, P* p) -> Status {
         RECOG_ASSIGN_OR_RETURN(p->geometry, ParseGeometryCheck(text));
         return Status::Ok();
       },
       [](const P& p) { return GeometryCheckName(p.geometry); }},
      Number("recent_seconds", true, RealRange::AtLeast(0),
             "tau_c when frames carry timestamps: newer entries are not candidates",
             [](P& p) -> FieldRef { return &p.recent_seconds; }),
      Count("recent_frames", true, 0, kMaxCount, "tau_c in frames when frames carry no timestamp",
            [](P& p) -> FieldRef { return &p.recent_frames; }),
      Count("keyframe_confirmations", true, 0, LoopDetectorParams::kMaxKeyframeConfirmations,
            "keyframes that must confirm a verified loop before it is accepted",
            [](P& p) -> FieldRef { return &p.keyframe_confirmations; }),
      Count("min_features", false, 0, kMaxCount, "a frame with fewer features is not queried",
            [](P& p) -> FieldRef { return &p.min_features; }),
      {{"normalisation",
        SettingKind::kChoice,
        false,
        {},
        "previous_frame, best_candidate",
        "what scores are normalised by"},
       nullptr,
       [](std::string_view text, P* p) -> Status {
         RECOG_ASSIGN_OR_RETURN(p->normalisation, ParseScoreNormalisation(text));
         return Status::Ok();
       },
       [](const P& p) { return ScoreNormalisationName(p.normalisation); }},
      Number("min_score_with_previous", false, RealRange::AtLeast(0),
             "a frame scoring less with the previous one is not queried (previous_frame)",
             [](P& p) -> FieldRef { return &p.min_score_with_previous; }),
      Count("max_query_results", false, 1, kMaxCount, "database results considered per query",
            [](P& p) -> FieldRef { return &p.max_query_results; }),
      Count("query_full_scan_postings", false, 0, 1e12,
            "postings a query reads in full before it completes only its best candidates (0: all)",
            [](P& p) -> FieldRef { return &p.query_full_scan_postings; }),
      Count("query_rescored_candidates", false, 1, kMaxCount,
            "candidates of a bounded query whose scores are completed",
            [](P& p) -> FieldRef { return &p.query_rescored_candidates; }),
      Count("island_max_gap", false, 0, kMaxCount, "entries at most this far apart join an island",
            [](P& p) -> FieldRef { return &p.island_max_gap; }),
      Count("island_min_size", false, 1, kMaxCount, "smaller islands are dropped",
            [](P& p) -> FieldRef { return &p.island_min_size; }),
      Count("consistency_max_island_gap", false, 0, kMaxCount,
            "ids between consecutive queries' islands that are still consistent",
            [](P& p) -> FieldRef { return &p.consistency_max_island_gap; }),
      Count("consistency_max_query_gap", false, 0, kMaxCount,
            "queries further apart restart the consistency count",
            [](P& p) -> FieldRef { return &p.consistency_max_query_gap; }),
      Number("ratio", false, RealRange::OpenClosed(0, 1),
             "nearest-neighbour distance ratio of a correspondence",
             [](P& p) -> FieldRef { return &p.matching.ratio; }),
      Count("max_distance", false, 0, 256, "Hamming distance of a correspondence at most",
            [](P& p) -> FieldRef { return &p.matching.max_distance; }),
      Flag("mutual", "a correspondence must be each feature's nearest both ways",
           [](P& p) -> FieldRef { return &p.matching.mutual; }),
      Number("ransac_threshold_px", false, RealRange::Above(0), "epipolar distance of an inlier",
             [](P& p) -> FieldRef { return &p.epipolar.threshold_px; }),
      Number("ransac_confidence", false, RealRange::Open(0, 1),
             "RANSAC confidence of the fundamental matrix",
             [](P& p) -> FieldRef { return &p.epipolar.confidence; }),
      Count("ransac_max_iterations", false, 1, std::numeric_limits<int>::max(),
            "RANSAC iterations of the fundamental matrix",
            [](P& p) -> FieldRef { return &p.epipolar.max_iterations; }),
      Flag("strong_acceptance", "accept a loop on strong evidence before k consistent queries",
           [](P& p) -> FieldRef { return &p.strong_acceptance; }),
      Count("strong_temporal_matches", false, 0, kMaxCount,
            "consistent queries a loop accepted on strong evidence needs",
            [](P& p) -> FieldRef { return &p.strong_temporal_matches; }),
      Count("verified_candidates", false, 1, kMaxCount,
            "candidates verified for strong evidence (the most inliers wins)",
            [](P& p) -> FieldRef { return &p.verified_candidates; }),
      Count("strong_min_inliers", false, 8, kMaxCount,
            "inliers of strong evidence (>= min_inliers)",
            [](P& p) -> FieldRef { return &p.strong_min_inliers; }),
      Number("strong_min_spread", false, RealRange::Closed(0, 1),
             "inlier spread of strong evidence",
             [](P& p) -> FieldRef { return &p.strong_min_spread; }),
      Number("strong_max_homography_ratio", false, RealRange::Closed(0, 1),
             "R_H above which a homography explains the inliers as well as F",
             [](P& p) -> FieldRef { return &p.strong_max_homography_ratio; }),
      Number("min_spread", false, RealRange::Closed(0, 1),
             "inlier spread every verified loop needs",
             [](P& p) -> FieldRef { return &p.min_spread; }),
      Count("relocalisation_min_inliers", false, 0, kMaxCount,
            "inliers a one-frame query (relocalisation, across maps) needs",
            [](P& p) -> FieldRef { return &p.relocalisation_min_inliers; }),
      Count("small_frame_pixels", false, 0, kMaxCount,
            "a frame of at most this many pixels is small",
            [](P& p) -> FieldRef { return &p.small_frame_pixels; }),
      Count("small_frame_min_inliers", false, 0, kMaxCount,
            "inliers every verification of a small frame needs",
            [](P& p) -> FieldRef { return &p.small_frame_min_inliers; }),
      Number("max_motion_disagreement_deg", false, RealRange::Closed(0, 180),
             "how far two confirming loops' relative motions may disagree",
             [](P& p) -> FieldRef { return &p.max_motion_disagreement_deg; }),
      Flag("calibrated_check", "calibrated frames' loops must make physical sense",
           [](P& p) -> FieldRef { return &p.calibrated.enabled; }),
      Number("calibrated_min_in_front", false, RealRange::Closed(0, 1),
             "share of inliers in front of both cameras (calibrated check)",
             [](P& p) -> FieldRef { return &p.calibrated.min_in_front; }),
      Number("calibrated_max_rotation_deg", false, RealRange::Closed(0, 180),
             "rotation between the cameras at most (calibrated check)",
             [](P& p) -> FieldRef { return &p.calibrated.max_rotation_deg; }),
      Number("calibrated_min_spread", false, RealRange::Closed(0, 1),
             "inlier spread (calibrated check)",
             [](P& p) -> FieldRef { return &p.calibrated.min_spread; }),
  };
  return rows;
}

const Row* FindRow(std::string_view name) {
  for (const Row& row : Rows()) {
    if (row.setting.name == name) return &row;
  }
  return nullptr;
}

// "a finite number >= 0", "a finite number in (0, 1]", "a whole number in [8, 100000]".
std::string RangeText(const DetectorSetting& s) {
  std::string range = s.range.Describe();  // "in [a, b]", or "finite and >= a"
  const std::string_view finite = "finite and ";
  if (range.rfind(finite, 0) == 0) range.erase(0, finite.size());
  return (s.kind == SettingKind::kCount ? "a whole number " : "a finite number ") + range;
}

Status BadValue(const DetectorSetting& s, std::string_view text, const std::string& expected) {
  return Status::InvalidArgument("setting " + std::string(s.name) + " = '" + std::string(text) +
                                 "': must be " + expected);
}

Status ParseNumber(const DetectorSetting& s, std::string_view text, double* value) {
  const std::string copy(text);
  char* end = nullptr;
  const double number = std::strtod(copy.c_str(), &end);
  if (copy.empty() || *end != '\0' || !s.range.Contains(number)) {
    return BadValue(s, text, RangeText(s));
  }
  *value = number;
  return Status::Ok();
}

Status ParseCount(const DetectorSetting& s, std::string_view text, uint64_t* value) {
  uint64_t number = 0;
  const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), number);
  if (text.empty() || error != std::errc() || end != text.data() + text.size() ||
      !s.range.Contains(double(number))) {
    return BadValue(s, text, RangeText(s));
  }
  *value = number;
  return Status::Ok();
}

Status ParseFlag(const DetectorSetting& s, std::string_view text, bool* value) {
  if (text == "true" || text == "yes" || text == "on") {
    *value = true;
  } else if (text == "false" || text == "no" || text == "off") {
    *value = false;
  } else {
    return BadValue(s, text, "true or false");
  }
  return Status::Ok();
}

Status ParseInto(const Row& row, std::string_view text, LoopDetectorParams* params) {
  const DetectorSetting& s = row.setting;
  if (s.kind == SettingKind::kChoice) {
    const Status parsed = row.parse_choice(text, params);
    return parsed.ok() ? parsed : BadValue(s, text, "one of " + std::string(s.choices));
  }
  const FieldRef field = row.field(*params);
  if (bool* const* flag = std::get_if<bool*>(&field)) return ParseFlag(s, text, *flag);
  if (double* const* real = std::get_if<double*>(&field)) return ParseNumber(s, text, *real);
  uint64_t count = 0;
  RECOG_RETURN_IF_ERROR(ParseCount(s, text, &count));
  std::visit(
      [count](auto* target) { *target = static_cast<std::decay_t<decltype(*target)>>(count); },
      field);
  return Status::Ok();
}

std::string FormatRow(const Row& row, const LoopDetectorParams& params) {
  switch (row.setting.kind) {
    case SettingKind::kPreset:
      return std::string(DetectorPresetName(params.preset));
    case SettingKind::kChoice:
      return std::string(row.format_choice(params));
    default:
      break;
  }
  // The field accessors take a mutable struct; formatting only reads through them.
  const FieldRef field = row.field(const_cast<LoopDetectorParams&>(params));
  if (bool* const* flag = std::get_if<bool*>(&field)) return **flag ? "true" : "false";
  if (double* const* real = std::get_if<double*>(&field)) {
    char text[32];
    std::snprintf(text, sizeof(text), "%.17g", **real);
    return text;
  }
  return std::visit([](auto* value) { return std::to_string(uint64_t(*value)); }, field);
}

}  // namespace

std::span<const DetectorSetting> DetectorSettings() {
  static const std::vector<DetectorSetting> settings = [] {
    std::vector<DetectorSetting> out;
    for (const Row& row : Rows()) out.push_back(row.setting);
    return out;
  }();
  return settings;
}

const DetectorSetting* FindDetectorSetting(std::string_view name) {
  const Row* row = FindRow(name);
  return row == nullptr ? nullptr : &DetectorSettings()[size_t(row - Rows().data())];
}

std::string FormatDetectorSetting(const DetectorSetting& setting,
                                  const LoopDetectorParams& params) {
  const Row* row = FindRow(setting.name);
  return row == nullptr ? std::string() : FormatRow(*row, params);
}

Status ApplyDetectorSettings(std::span<const NamedSetting> values, LoopDetectorParams* params) {
  LoopDetectorParams result = *params;
  const NamedSetting* preset = nullptr;
  for (const NamedSetting& value : values) {
    if (value.first != "preset") continue;
    if (preset != nullptr) return Status::InvalidArgument("setting preset is given twice");
    preset = &value;
  }
  if (preset != nullptr) {
    StatusOr<LoopDetectorParams> base = ParseDetectorPreset(preset->second);
    if (!base.ok()) {
      return BadValue(*FindDetectorSetting("preset"), preset->second,
                      "one of " + std::string(FindDetectorSetting("preset")->choices));
    }
    result = base.value();
  }
  for (const auto& [name, text] : values) {
    if (name == "preset") continue;
    const Row* row = FindRow(name);
    if (row == nullptr) return Status::InvalidArgument("unknown setting '" + name + "'");
    RECOG_RETURN_IF_ERROR(ParseInto(*row, text, &result));
  }
  RECOG_RETURN_IF_ERROR(result.Validate());
  *params = result;
  return Status::Ok();
}

std::vector<NamedSetting> MapDetectorSettings(const LoopDetectorParams& params) {
  std::vector<NamedSetting> out;
  for (const Row& row : Rows()) {
    if (row.setting.kept_by_map) {
      out.emplace_back(std::string(row.setting.name), FormatRow(row, params));
    }
  }
  return out;
}

std::span<const std::string_view> MapDetectorSettingNames() {
  static const std::vector<std::string_view> names = [] {
    std::vector<std::string_view> out;
    for (const Row& row : Rows()) {
      if (row.setting.kept_by_map) out.push_back(row.setting.name);
    }
    return out;
  }();
  return names;
}

}  // namespace recog
