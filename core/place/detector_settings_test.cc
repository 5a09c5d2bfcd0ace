#include "core/place/detector_settings.h"

#include <cmath>
#include <cstdio>
#include <fstream>
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
  // Each value is in its own range, but together they break LoopDetectorParams::Validate.
  LoopDetectorParams p;
  EXPECT_EQ(Apply({{"ransac_confidence", "1"}}, &p).code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(p.epipolar.confidence, LoopDetectorParams{}.epipolar.confidence);
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

TEST(DetectorSettingsTest, TheUserGuideNamesEverySetting) {
  std::ifstream in(std::string(RECOG_SOURCE_DIR) + "/docs/places.md");
  ASSERT_TRUE(in.good());
  std::stringstream guide;
  guide << in.rdbuf();
  for (const DetectorSetting& s : DetectorSettings()) {
    std::string quoted(1, '`');  // (not "`" + name + "`": GCC 12's -Wrestrict misfires on it)
    quoted.append(s.name).push_back('`');
    EXPECT_NE(guide.str().find(quoted), std::string::npos)
        << "docs/places.md does not name the setting " << s.name;
  }
}

}  // namespace
}  // namespace recog
