#include "core/place/detector_settings.h"

#include <cmath>
#include <cstdio>
#include <limits>
#include <set>
#include <sstream>

#include <gtest/gtest.h>

namespace recog {
namespace {

Status Apply(std::vector<NamedSetting> values, LoopDetectorParams* params) {
  return ApplyDetectorSettings(values, params);
}

TEST(DetectorSettingsTest, EveryNameIsUniqueAndPresetComesFirst) {
  std::set<std::string_view> names;
  for (const DetectorSetting& s : DetectorSettings()) {
    EXPECT_TRUE(names.insert(s.name).second) << s.name;
    EXPECT_FALSE(s.doc.empty()) << s.name;
    EXPECT_EQ(FindDetectorSetting(s.name), &s);
  }
  EXPECT_EQ(DetectorSettings().front().name, "preset");
  EXPECT_EQ(FindDetectorSetting("mode"), nullptr);
}

TEST(DetectorSettingsTest, EachPresetsValuesReadBackExactly) {
  LoopDetectorParams odd = LoopDetectorParams::Keyframes();
  odd.alpha = 0.1 + 0.2;  // not exactly representable: the text keeps every bit
  odd.epipolar.min_inliers = 17;
  odd.strong_acceptance = false;
  for (const LoopDetectorParams& params :
       {LoopDetectorParams{}, LoopDetectorParams::Thesis(), LoopDetectorParams::Keyframes(), odd}) {
    std::vector<NamedSetting> all;
    for (const DetectorSetting& s : DetectorSettings()) {
      all.emplace_back(std::string(s.name), FormatDetectorSetting(s, params));
    }
    LoopDetectorParams read;
    ASSERT_TRUE(Apply(all, &read).ok());
    for (const DetectorSetting& s : DetectorSettings()) {
      EXPECT_EQ(FormatDetectorSetting(s, read), FormatDetectorSetting(s, params)) << s.name;
    }
  }
  EXPECT_EQ(FormatDetectorSetting(*FindDetectorSetting("alpha"), odd), "0.30000000000000004");
  EXPECT_EQ(FormatDetectorSetting(*FindDetectorSetting("geometry"), odd), "exhaustive");
  EXPECT_EQ(FormatDetectorSetting(*FindDetectorSetting("mutual"), odd), "true");
  EXPECT_EQ(FormatDetectorSetting(*FindDetectorSetting("strong_acceptance"), odd), "false");
}

TEST(DetectorSettingsTest, ThePresetAppliesFirstWhateverTheOrder) {
  LoopDetectorParams p;
  ASSERT_TRUE(Apply({{"recent_frames", "7"}, {"preset", "keyframes"}}, &p).ok());
  EXPECT_EQ(p.preset, DetectorPreset::kKeyframes);
  EXPECT_EQ(p.normalisation, ScoreNormalisation::kBestCandidate) << "from the preset";
  EXPECT_EQ(p.recent_frames, 7u) << "given after the preset's 3, whatever the order";
  EXPECT_EQ(Apply({{"preset", "thesis"}, {"preset", "default"}}, &p).code(),
            StatusCode::kInvalidArgument);
}

TEST(DetectorSettingsTest, BadValuesNameTheSettingAndChangeNothing) {
  const LoopDetectorParams before = LoopDetectorParams::Keyframes();
  const std::vector<NamedSetting> bad = {{"alpha", "nan"},
                                         {"alpha", "inf"},
                                         {"alpha", "-0.1"},
                                         {"alpha", "0.3x"},
                                         {"alpha", ""},
                                         {"temporal_matches", "-1"},
                                         {"temporal_matches", "2.5"},
                                         {"temporal_matches", "99999999999"},
                                         {"min_inliers", "7"},
                                         {"min_inliers", "100001"},
                                         {"ratio", "1.5"},
                                         {"geometry", "sideways"},
                                         {"preset", "sideways"},
                                         {"strong_acceptance", "maybe"},
                                         {"mutual", "maybe"},
                                         {"mutual", ""},
                                         {"verified_candidates", "0"},
                                         {"verified_candidates", "-3"},
                                         {"verified_candidates", "1e99"},
                                         {"keyframe_confirmations", "101"},
                                         {"calibrated_max_rotation_deg", "181"},
                                         {"ransac_max_iterations", "0"}};
  for (const NamedSetting& value : bad) {
    LoopDetectorParams p = before;
    const Status status = Apply({{"recent_frames", "9"}, value}, &p);
    EXPECT_EQ(status.code(), StatusCode::kInvalidArgument) << value.first << "=" << value.second;
    EXPECT_NE(status.message().find(value.first), std::string::npos) << status.ToString();
    EXPECT_EQ(p.recent_frames, before.recent_frames) << "nothing applied: " << value.first;
    EXPECT_EQ(p.alpha, before.alpha);
  }
  LoopDetectorParams p;
  const Status unknown = Apply({{"alpah", "0.2"}}, &p);
  EXPECT_EQ(unknown.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(unknown.message().find("'alpah'"), std::string::npos);
}

// The table's range of each number is what LoopDetectorParams::Validate takes: its ends (or just
// inside an open end) are accepted, just outside them refused.
TEST(DetectorSettingsTest, EachRangeIsWhatValidateTakes) {
  const auto text = [](double value) {
    char buffer[32];
    std::snprintf(buffer, sizeof(buffer), "%.17g", value);
    return std::string(buffer);
  };
  for (const DetectorSetting& s : DetectorSettings()) {
    if (s.kind != SettingKind::kNumber && s.kind != SettingKind::kCount) continue;
    const RealRange& r = s.range;
    const double step = s.kind == SettingKind::kCount ? 1 : 1e-9;
    const double low = r.min_included ? r.min : r.min + step;
    std::vector<double> inside = {low};
    std::vector<double> outside = {r.min_included ? r.min - step : r.min};
    if (std::isfinite(r.max)) {
      inside.push_back(r.max_included ? r.max : r.max - step);
      outside.push_back(r.max_included ? r.max + step : r.max);
    }
    for (const double value : inside) {
      // strong_min_inliers must stay >= min_inliers, strong_temporal_matches <= k: give room.
      LoopDetectorParams p;
      p.temporal_matches = std::numeric_limits<uint32_t>::max();
      p.strong_min_inliers = 200000;
      if (s.name == "strong_min_inliers") p.epipolar.min_inliers = 8;
      EXPECT_TRUE(Apply({{std::string(s.name), text(value)}}, &p).ok())
          << s.name << " = " << text(value);
    }
    for (const double value : outside) {
      if (s.kind == SettingKind::kCount && value < 0) continue;  // not a whole number at all
      LoopDetectorParams p;
      EXPECT_FALSE(Apply({{std::string(s.name), text(value)}}, &p).ok())
          << s.name << " = " << text(value);
    }
  }
}

TEST(DetectorSettingsTest, CrossFieldConditionsAreStillChecked) {
  // Each value is in its own range, but together they break LoopDetectorParams::Validate; the
  // same values the other way round pass.
  const std::vector<std::pair<NamedSetting, NamedSetting>> pairs = {
      {{"min_inliers", "40"}, {"strong_min_inliers", "30"}},
      {{"temporal_matches", "2"}, {"strong_temporal_matches", "3"}},
  };
  for (const auto& [first, second] : pairs) {
    for (const NamedSetting& value : {first, second}) {
      EXPECT_TRUE(FindDetectorSetting(value.first)->range.Contains(std::stod(value.second)))
          << value.first;
    }
    LoopDetectorParams p;
    const Status refused = Apply({first, second}, &p);
    EXPECT_EQ(refused.code(), StatusCode::kInvalidArgument) << first.first;
    EXPECT_NE(refused.message().find(second.first + " = " + second.second + ": must be "),
              std::string::npos)
        << refused.ToString();
    EXPECT_EQ(FormatDetectorSetting(*FindDetectorSetting(first.first), p),
              FormatDetectorSetting(*FindDetectorSetting(first.first), LoopDetectorParams{}))
        << "nothing applied";
    EXPECT_TRUE(Apply({{first.first, second.second}, {second.first, first.second}}, &p).ok())
        << first.first;
  }
}

// Validate takes each setting's range from the table and names the setting: ends that no check
// of Validate's own stated before the table did (min_inliers' upper end, max_distance's).
TEST(DetectorSettingsTest, ValidateChecksEverySettingsRangeUnderItsName) {
  LoopDetectorParams p;
  p.epipolar.min_inliers = 100001;
  p.strong_min_inliers = 200000;
  EXPECT_EQ(p.Validate().message(),
            "LoopDetectorParams.min_inliers = 100001: must be in "
            "[8, 100000]");
  LoopDetectorParams distance;
  distance.matching.max_distance = 257;
  EXPECT_EQ(distance.Validate("RigLoopParams.detector").message(),
            "RigLoopParams.detector.max_distance = 257: must be in [0, 256]");
  for (const LoopDetectorParams& preset :
       {LoopDetectorParams{}, LoopDetectorParams::Thesis(), LoopDetectorParams::Keyframes()}) {
    EXPECT_TRUE(preset.Validate().ok()) << DetectorPresetName(preset.preset);
  }
}

// The markdown row of `name`, from its values in the presets and its range: "| `name` | ...".
std::string MarkdownRow(std::string_view name, const std::string& range, bool kept) {
  const DetectorSetting& s = *FindDetectorSetting(name);
  const std::string in_default = FormatDetectorSetting(s, LoopDetectorParams{});
  std::string row = "| `" + std::string(name) + "` | " + in_default + " ";
  for (const LoopDetectorParams& other :
       {LoopDetectorParams::Thesis(), LoopDetectorParams::Keyframes()}) {
    const std::string value = FormatDetectorSetting(s, other);
    row += "| " + (value == in_default ? "" : value) + " ";
  }
  return row + "| " + range + " | " + (kept ? "kept" : "") + " | " + std::string(s.doc) + " |\n";
}

TEST(DetectorSettingsTest, TheTableGivesEachPresetsValueWhereItDiffersRangeAndDoc) {
  const std::string markdown = DetectorSettingsTable(SettingsTableFormat::kMarkdown);
  EXPECT_EQ(markdown.rfind("| preset | for |\n|---|---|\n| `default` | ", 0), 0u) << markdown;
  EXPECT_NE(markdown.find("| setting | default | thesis | keyframes | range | map | doc |\n"),
            std::string::npos);
  EXPECT_NE(markdown.find(MarkdownRow("recent_frames", ">= 0", true)), std::string::npos)
      << markdown;
  EXPECT_NE(markdown.find(MarkdownRow("min_inliers", "[8, 100000]", true)), std::string::npos);
  EXPECT_NE(markdown.find(MarkdownRow("strong_acceptance", "true, false", false)),
            std::string::npos);
  EXPECT_NE(markdown.find(MarkdownRow("geometry", "direct_index, exhaustive, none", true)),
            std::string::npos);
  // Reals as a reader writes them, and each setting on one row.
  EXPECT_NE(markdown.find("| `ratio` | 0.6 |  | 0.85 | (0, 1] |  | "), std::string::npos);
  for (const DetectorSetting& s : DetectorSettings()) {
    if (s.kind == SettingKind::kPreset) continue;
    const std::string cell = "| `" + std::string(s.name) + "` |";
    const size_t at = markdown.find(cell);
    EXPECT_NE(at, std::string::npos) << s.name;
    EXPECT_EQ(markdown.find(cell, at + 1), std::string::npos) << s.name;
  }
  // The text form: the same cells in columns, the names without backticks.
  const std::string text = DetectorSettingsTable(SettingsTableFormat::kText);
  EXPECT_EQ(text.find('|'), std::string::npos);
  EXPECT_EQ(text.find('`'), std::string::npos);
  EXPECT_NE(text.find("\nrecent_frames "), std::string::npos) << text;
}

TEST(DetectorSettingsTest, PresetHelpGivesWhereEachPresetDiffersFromDefault) {
  std::vector<std::string> lines;
  std::istringstream help(PresetHelp());
  for (std::string line; std::getline(help, line);) lines.push_back(line);
  ASSERT_EQ(lines.size(), DetectorPresets().size());
  EXPECT_EQ(lines[0].rfind("default: ", 0), 0u);
  EXPECT_EQ(lines[0].find('('), std::string::npos) << "default differs from nothing";
  EXPECT_EQ(lines[1].rfind("thesis: ", 0), 0u);
  EXPECT_EQ(lines[1].substr(lines[1].find('(')), "(strong_acceptance false)");
  EXPECT_EQ(lines[2].rfind("keyframes: ", 0), 0u);
  const std::string recent =
      "recent_frames " + std::to_string(LoopDetectorParams::Keyframes().recent_frames);
  EXPECT_NE(lines[2].find(recent), std::string::npos) << lines[2];
  EXPECT_NE(lines[2].find("ratio 0.85"), std::string::npos) << lines[2];
  EXPECT_EQ(lines[2].find("alpha"), std::string::npos) << "the same in both";
}

TEST(DetectorSettingsTest, AMapKeepsItsEightSettingsPresetFirst) {
  const std::vector<NamedSetting> kept = MapDetectorSettings(LoopDetectorParams::Thesis());
  std::vector<std::string> names;
  for (const auto& [name, value] : kept) names.push_back(name);
  EXPECT_EQ(names, (std::vector<std::string>{"preset", "alpha", "temporal_matches", "min_inliers",
                                             "geometry", "recent_seconds", "recent_frames",
                                             "keyframe_confirmations"}));
  EXPECT_EQ(kept.front().second, "thesis");
}

}  // namespace
}  // namespace recog
