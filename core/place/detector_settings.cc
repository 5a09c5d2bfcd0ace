#include "core/place/detector_settings.h"

#include <algorithm>
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

// The presets' names, comma-separated (the preset setting's choices).
std::string_view PresetChoices() {
  static const std::string choices = [] {
    std::string out;
    for (const DetectorPresetInfo& info : DetectorPresets()) {
      out += (out.empty() ? "" : ", ") + std::string(DetectorPresetName(info.preset));
    }
    return out;
  }();
  return choices;
}

const std::vector<Row>& Rows() {
  using P = LoopDetectorParams;
  static const std::vector<Row> rows = {
      {{"preset",
        SettingKind::kPreset,
        true,
        {},
        PresetChoices(),
        "the parameter set the other settings apply over"}},
      Number("alpha", true, RealRange::AtLeast(0),
             "minimum normalised score eta of a candidate (Table 4.4)",
             [](P& p) -> FieldRef { return &p.alpha; }),
      Count("temporal_matches", true, 0, kMaxCount,
            "k: consistent previous queries a loop needs (Table 4.4)",
            [](P& p) -> FieldRef { return &p.temporal_matches; }),
      // RANSAC of the fundamental matrix needs 8 correspondences.
      Count("min_inliers", true, 8, 100000,
            "RANSAC inliers of the fundamental matrix a loop needs (Table 4.4)",
            [](P& p) -> FieldRef { return &p.epipolar.min_inliers; }),
      {{"geometry",
        SettingKind::kChoice,
        true,
        {},
        "direct_index, exhaustive, none",
        "how candidates are verified: through the direct index (Algorithm 2), every pair, or not"},
       nullptr,
       [](std::string_view text, P* p) -> Status {
         RECOG_ASSIGN_OR_RETURN(p->geometry, ParseGeometryCheck(text));
         return Status::Ok();
       },
       [](const P& p) { return GeometryCheckName(p.geometry); }},
      Number("recent_seconds", true, RealRange::AtLeast(0),
             "tau_c in seconds when frames carry timestamps: newer entries are not candidates "
             "(Table 4.4)",
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
             "a frame scoring less with the previous one is not queried (previous_frame; "
             "Table 4.4)",
             [](P& p) -> FieldRef { return &p.min_score_with_previous; }),
      Count("max_query_results", false, 1, kMaxCount, "database results considered per query",
            [](P& p) -> FieldRef { return &p.max_query_results; }),
      Count("query_full_scan_postings", false, 0, 1e12,
            "postings a query reads in full before it completes only its best candidates (0: all; "
            "docs/scaling.md)",
            [](P& p) -> FieldRef { return &p.query_full_scan_postings; }),
      Count("query_rescored_candidates", false, 1, kMaxCount,
            "candidates of a bounded query whose scores are completed",
            [](P& p) -> FieldRef { return &p.query_rescored_candidates; }),
      Count("island_max_gap", false, 0, kMaxCount,
            "entries at most this far apart (ids) join an island (as DLoopDetector)",
            [](P& p) -> FieldRef { return &p.island_max_gap; }),
      Count("island_min_size", false, 1, kMaxCount,
            "smaller islands are dropped (as DLoopDetector)",
            [](P& p) -> FieldRef { return &p.island_min_size; }),
      Count("consistency_max_island_gap", false, 0, kMaxCount,
            "ids between consecutive queries' islands that are still consistent (as "
            "DLoopDetector)",
            [](P& p) -> FieldRef { return &p.consistency_max_island_gap; }),
      Count("consistency_max_query_gap", false, 0, kMaxCount,
            "queries further apart restart the consistency count (as DLoopDetector)",
            [](P& p) -> FieldRef { return &p.consistency_max_query_gap; }),
      Number("ratio", false, RealRange::OpenClosed(0, 1),
             "nearest-neighbour distance ratio of a correspondence (thesis §4.4.6)",
             [](P& p) -> FieldRef { return &p.matching.ratio; }),
      Count("max_distance", false, 0, 256,
            "Hamming distance of a correspondence at most (the usual ORB threshold)",
            [](P& p) -> FieldRef { return &p.matching.max_distance; }),
      Flag("mutual", "a correspondence must be each feature's nearest both ways",
           [](P& p) -> FieldRef { return &p.matching.mutual; }),
      Number("ransac_threshold_px", false, RealRange::Above(0),
             "epipolar distance of an inlier, pixels (Table 4.4)",
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
             "share of the 4 x 4 cells of both images the inliers of strong evidence cover",
             [](P& p) -> FieldRef { return &p.strong_min_spread; }),
      Number("strong_max_homography_ratio", false, RealRange::Closed(0, 1),
             "R_H above which a homography explains the inliers as well as F (ORB-SLAM's model "
             "selection)",
             [](P& p) -> FieldRef { return &p.strong_max_homography_ratio; }),
      Number("min_spread", false, RealRange::Closed(0, 1),
             "share of the 4 x 4 cells of both images every verified loop's inliers cover",
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
             "how far two confirming loops' relative motions may disagree, degrees",
             [](P& p) -> FieldRef { return &p.max_motion_disagreement_deg; }),
      Flag("calibrated_check",
           "calibrated frames' loops must make physical sense (instead of min_spread)",
           [](P& p) -> FieldRef { return &p.calibrated.enabled; }),
      Number("calibrated_min_in_front", false, RealRange::Closed(0, 1),
             "share of inliers in front of both cameras (calibrated check)",
             [](P& p) -> FieldRef { return &p.calibrated.min_in_front; }),
      Number("calibrated_max_rotation_deg", false, RealRange::Closed(0, 180),
             "rotation between the cameras at most, degrees (calibrated check)",
             [](P& p) -> FieldRef { return &p.calibrated.max_rotation_deg; }),
      Number("calibrated_min_spread", false, RealRange::Closed(0, 1),
             "share of the 4 x 4 cells of both images the inliers cover (calibrated check)",
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

Status ParseSettingReal(const DetectorSetting& s, std::string_view text, double* value) {
  const std::string copy(text);
  char* end = nullptr;
  const double number = std::strtod(copy.c_str(), &end);
  if (copy.empty() || *end != '\0' || !s.range.Contains(number)) {
    return BadValue(s, text, RangeText(s));
  }
  *value = number;
  return Status::Ok();
}

Status ParseSettingCount(const DetectorSetting& s, std::string_view text, uint64_t* value) {
  uint64_t number = 0;
  const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), number);
  if (text.empty() || error != std::errc() || end != text.data() + text.size() ||
      !s.range.Contains(double(number))) {
    return BadValue(s, text, RangeText(s));
  }
  *value = number;
  return Status::Ok();
}

Status ParseSettingFlag(const DetectorSetting& s, std::string_view text, bool* value) {
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
  if (bool* const* flag = std::get_if<bool*>(&field)) return ParseSettingFlag(s, text, *flag);
  if (double* const* real = std::get_if<double*>(&field)) return ParseSettingReal(s, text, *real);
  uint64_t count = 0;
  RECOG_RETURN_IF_ERROR(ParseSettingCount(s, text, &count));
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

// The value of a number or count as a real number (the ranges are real ranges).
double NumericValue(const Row& row, const LoopDetectorParams& params) {
  const FieldRef field = row.field(const_cast<LoopDetectorParams&>(params));
  return std::visit([](auto* value) { return double(*value); }, field);
}

// The value of a count (an int, uint32_t or size_t field), a size_t beyond int64_t's range
// clamped to its end (out of every count's range either way).
int64_t CountValue(const Row& row, const LoopDetectorParams& params) {
  const FieldRef field = row.field(const_cast<LoopDetectorParams&>(params));
  if (int* const* signed_count = std::get_if<int*>(&field)) return **signed_count;
  const uint64_t count = std::visit([](auto* value) { return uint64_t(*value); }, field);
  return int64_t(std::min<uint64_t>(count, std::numeric_limits<int64_t>::max()));
}

// A value as a reader wants it: FormatRow's, but reals in the shortest text that reads back to
// them ("0.85", not "0.84999999999999998").
std::string DisplayValue(const Row& row, const LoopDetectorParams& params) {
  return row.setting.kind == SettingKind::kNumber ? RealText(NumericValue(row, params))
                                                  : FormatRow(row, params);
}

// "[8, 100000]", "(0, 1]", ">= 0", "> 0"; the choices; "true, false".
std::string RangeCell(const DetectorSetting& s) {
  if (s.kind == SettingKind::kFlag) return "true, false";
  if (s.kind == SettingKind::kPreset || s.kind == SettingKind::kChoice) {
    return std::string(s.choices);
  }
  const RealRange& r = s.range;
  const bool count = s.kind == SettingKind::kCount;
  const auto end = [count](double value) {
    return count ? std::to_string(uint64_t(value)) : RealText(value);
  };
  // A count's upper end at its field type's limit (which only keeps the value in the field) tells
  // a reader nothing.
  const bool type_limit = r.max == kMaxCount || r.max == std::numeric_limits<int>::max();
  if (std::isinf(r.max) || (count && type_limit)) {
    return (r.min_included ? ">= " : "> ") + end(r.min);
  }
  return (r.min_included ? "[" : "(") + end(r.min) + ", " + end(r.max) +
         (r.max_included ? "]" : ")");
}

LoopDetectorParams ValuesOfPreset(DetectorPreset preset) {
  return ParseDetectorPreset(DetectorPresetName(preset)).value();
}

using Cells = std::vector<std::string>;

// `rows` (the header first) as a markdown table, or as text columns two spaces apart.
std::string RenderTable(const std::vector<Cells>& rows, SettingsTableFormat format) {
  std::string out;
  if (format == SettingsTableFormat::kMarkdown) {
    for (size_t i = 0; i < rows.size(); ++i) {
      for (const std::string& cell : rows[i]) out += "| " + cell + " ";
      out += "|\n";
      if (i == 0) {
        for (size_t column = 0; column < rows[i].size(); ++column) out += "|---";
        out += "|\n";
      }
    }
    return out;
  }
  std::vector<size_t> widths(rows.front().size(), 0);
  for (const Cells& row : rows) {
    for (size_t column = 0; column < row.size(); ++column) {
      widths[column] = std::max(widths[column], row[column].size());
    }
  }
  for (const Cells& row : rows) {
    std::string line;
    for (size_t column = 0; column < row.size(); ++column) {
      line += row[column];
      if (column + 1 < row.size()) line.append(widths[column] + 2 - row[column].size(), ' ');
    }
    line.erase(line.find_last_not_of(' ') + 1);
    out += line + "\n";
  }
  return out;
}

}  // namespace

std::span<const DetectorPresetInfo> DetectorPresets() {
  static constexpr DetectorPresetInfo kPresets[] = {
      {DetectorPreset::kDefault,
       "video, whose consecutive frames overlap: thesis Table 4.4, and loops also accepted on "
       "strong evidence"},
      {DetectorPreset::kThesis,
       "the thesis's detector exactly: every loop needs k consistent queries"},
      {DetectorPreset::kKeyframes,
       "a SLAM's keyframes, metres apart: scores against the best candidate, and a verification "
       "for wide baselines"},
  };
  return kPresets;
}

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

std::string DisplayDetectorSetting(const DetectorSetting& setting,
                                   const LoopDetectorParams& params) {
  const Row* row = FindRow(setting.name);
  return row == nullptr ? std::string() : DisplayValue(*row, params);
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

void CheckDetectorSettingRanges(const LoopDetectorParams& params, OptionChecks* check) {
  for (const Row& row : Rows()) {
    const DetectorSetting& s = row.setting;
    if (s.kind == SettingKind::kNumber) {
      check->InRange(s.name, NumericValue(row, params), s.range);
    } else if (s.kind == SettingKind::kCount) {
      // Whole numbers in the message ("100000", where a real would read "1e+05"); a count's
      // range is closed (Count).
      const int64_t value = CountValue(row, params);
      check->Require(s.range.Contains(double(value)), s.name, value,
                     "in [" + std::to_string(int64_t(s.range.min)) + ", " +
                         std::to_string(int64_t(s.range.max)) + "]");
    }
  }
}

std::string DetectorSettingsTable(SettingsTableFormat format) {
  const bool markdown = format == SettingsTableFormat::kMarkdown;
  const auto code = [markdown](std::string_view name) {
    return markdown ? "`" + std::string(name) + "`" : std::string(name);
  };
  std::vector<Cells> presets = {{"preset", "for"}};
  Cells header = {"setting"};
  std::vector<LoopDetectorParams> values;
  for (const DetectorPresetInfo& info : DetectorPresets()) {
    presets.push_back({code(DetectorPresetName(info.preset)), std::string(info.doc)});
    header.emplace_back(DetectorPresetName(info.preset));
    values.push_back(ValuesOfPreset(info.preset));
  }
  for (const char* column : {"range", "map", "doc"}) header.emplace_back(column);
  std::vector<Cells> settings = {header};
  for (const Row& row : Rows()) {
    const DetectorSetting& s = row.setting;
    if (s.kind == SettingKind::kPreset) continue;  // the presets' own table
    Cells cells = {code(s.name), DisplayValue(row, values.front())};
    for (size_t i = 1; i < values.size(); ++i) {
      const std::string value = DisplayValue(row, values[i]);
      cells.push_back(value == cells[1] ? "" : value);
    }
    cells.push_back(RangeCell(s));
    cells.push_back(s.kept_by_map ? "kept" : "");
    cells.emplace_back(s.doc);
    settings.push_back(std::move(cells));
  }
  return RenderTable(presets, format) + "\n" + RenderTable(settings, format);
}

std::string PresetHelp() {
  const LoopDetectorParams defaults;
  std::string help;
  for (const DetectorPresetInfo& info : DetectorPresets()) {
    const LoopDetectorParams values = ValuesOfPreset(info.preset);
    std::string differences;
    for (const Row& row : Rows()) {
      if (row.setting.kind == SettingKind::kPreset) continue;
      const std::string value = DisplayValue(row, values);
      if (value == DisplayValue(row, defaults)) continue;
      differences +=
          (differences.empty() ? "" : ", ") + std::string(row.setting.name) + " " + value;
    }
    help += (help.empty() ? "" : "\n") + std::string(DetectorPresetName(info.preset)) + ": " +
            std::string(info.doc);
    if (!differences.empty()) help += " (" + differences + ")";
  }
  return help;
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
