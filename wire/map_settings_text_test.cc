#include "wire/map_settings_text.h"

#include <gtest/gtest.h>

namespace recog {
namespace {

using ::recognition::v1::MapSettings;

constexpr std::string_view kNames[] = {"preset", "alpha", "temporal_matches", "geometry",
                                       "keyframe_confirmations"};

TEST(MapSettingsTextTest, OnlyTheGivenFieldsAreReadInTheOrderOfTheNames) {
  MapSettings settings;
  settings.set_geometry(recognition::v1::GEOMETRY_CHECK_DIRECT_INDEX);
  settings.set_alpha(0.1 + 0.2);
  settings.set_temporal_matches(0);  // given, although zero
  const auto text = MapSettingsAsText(settings, kNames);
  ASSERT_EQ(text.size(), 3u);
  EXPECT_EQ(text[0], (std::pair<std::string, std::string>{"alpha", "0.30000000000000004"}));
  EXPECT_EQ(text[1], (std::pair<std::string, std::string>{"temporal_matches", "0"}));
  EXPECT_EQ(text[2], (std::pair<std::string, std::string>{"geometry", "direct_index"}));
  settings.set_geometry(recognition::v1::GEOMETRY_CHECK_UNSPECIFIED);
  EXPECT_EQ(MapSettingsAsText(settings, kNames).size(), 2u) << "UNSPECIFIED is not given";
  settings.set_geometry(static_cast<recognition::v1::GeometryCheck>(99));  // a newer client's
  EXPECT_EQ(MapSettingsAsText(settings, kNames)[2].second, "99");
}

TEST(MapSettingsTextTest, EveryKindReadsBackWhatItWrote) {
  MapSettings settings;
  for (const auto& [name, value] :
       std::vector<std::pair<std::string, std::string>>{{"preset", "keyframes"},
                                                        {"alpha", "0.30000000000000004"},
                                                        {"temporal_matches", "4294967295"},
                                                        {"geometry", "exhaustive"},
                                                        {"keyframe_confirmations", "2"}}) {
    EXPECT_EQ(SetMapSettingFromText(&settings, name, value), "") << name;
  }
  EXPECT_EQ(settings.alpha(), 0.1 + 0.2);
  EXPECT_EQ(settings.geometry(), recognition::v1::GEOMETRY_CHECK_EXHAUSTIVE);
  EXPECT_EQ(settings.temporal_matches(), 4294967295u);
  const auto text = MapSettingsAsText(settings, kNames);
  ASSERT_EQ(text.size(), 5u);
  EXPECT_EQ(text[0].second, "keyframes");
  EXPECT_EQ(text[3].second, "exhaustive");
}

TEST(MapSettingsTextTest, BadTextIsOneLineNamingTheSettingAndChangesNothing) {
  MapSettings settings;
  EXPECT_EQ(SetMapSettingFromText(&settings, "alpha", "abc"), "alpha: 'abc' is not a number");
  EXPECT_NE(SetMapSettingFromText(&settings, "temporal_matches", "-1"), "");
  EXPECT_NE(SetMapSettingFromText(&settings, "temporal_matches", "4294967296"), "");
  EXPECT_NE(SetMapSettingFromText(&settings, "temporal_matches", "2.5"), "");
  EXPECT_EQ(SetMapSettingFromText(&settings, "geometry", "sideways"),
            "geometry: 'sideways' is not one of direct_index, exhaustive, none");
  EXPECT_EQ(SetMapSettingFromText(&settings, "geometry", "unspecified").find("geometry: "), 0u);
  EXPECT_EQ(SetMapSettingFromText(&settings, "alpah", "0.2"), "unknown setting 'alpah'");
  EXPECT_EQ(SetMapSettingFromText(&settings, "rig", "x"), "unknown setting 'rig'");
  EXPECT_EQ(settings.ByteSizeLong(), 0u) << "nothing was set";
}

}  // namespace
}  // namespace recog
