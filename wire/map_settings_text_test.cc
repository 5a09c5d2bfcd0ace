#include "wire/map_settings_text.h"

#include <algorithm>
#include <limits>
#include <set>

#include <google/protobuf/descriptor.h>
#include <gtest/gtest.h>

#include "core/place/detector_settings.h"

namespace recog {
namespace {

namespace gp = ::google::protobuf;
using ::recognition::v1::MapSettings;
using SettingTexts = std::vector<std::pair<std::string, std::string>>;

SettingTexts AsText(const MapSettings& settings, std::span<const std::string_view> names) {
  SettingTexts values;
  EXPECT_EQ(MapSettingsAsText(settings, names, &values), "");
  return values;
}

constexpr std::string_view kNames[] = {"preset", "alpha", "temporal_matches", "geometry",
                                       "keyframe_confirmations"};

TEST(MapSettingsTextTest, OnlyTheGivenFieldsAreReadInTheOrderOfTheNames) {
  MapSettings settings;
  settings.set_geometry(recognition::v1::GEOMETRY_CHECK_DIRECT_INDEX);
  settings.set_alpha(0.1 + 0.2);
  settings.set_temporal_matches(0);  // given, although zero
  const auto text = AsText(settings, kNames);
  ASSERT_EQ(text.size(), 3u);
  EXPECT_EQ(text[0], (std::pair<std::string, std::string>{"alpha", "0.30000000000000004"}));
  EXPECT_EQ(text[1], (std::pair<std::string, std::string>{"temporal_matches", "0"}));
  EXPECT_EQ(text[2], (std::pair<std::string, std::string>{"geometry", "direct_index"}));
  settings.set_geometry(recognition::v1::GEOMETRY_CHECK_UNSPECIFIED);
  EXPECT_EQ(AsText(settings, kNames).size(), 2u) << "UNSPECIFIED is not given";
  settings.set_geometry(static_cast<recognition::v1::GeometryCheck>(99));  // a newer client's
  EXPECT_EQ(AsText(settings, kNames)[2].second, "99");
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
  const auto text = AsText(settings, kNames);
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
  EXPECT_EQ(SetMapSettingFromText(&settings, "keep_thumbnails", "true"),
            "unknown setting 'keep_thumbnails'");
  EXPECT_EQ(settings.ByteSizeLong(), 0u) << "nothing was set";
}

// A name that is no field (a typo in the settings table, a field renamed in the proto) is an
// error, never left out.
TEST(MapSettingsTextTest, AnUnknownNameIsAnErrorNotLeftOut) {
  MapSettings settings;
  settings.set_alpha(0.2);
  settings.set_keep_thumbnails(true);
  SettingTexts values = {{"stale", "value"}};
  constexpr std::string_view kTypo[] = {"alpha", "alpah"};
  EXPECT_EQ(MapSettingsAsText(settings, kTypo, &values), "unknown setting 'alpah'");
  EXPECT_TRUE(values.empty());
  for (const std::string_view name : {"rig", "keep_thumbnails"}) {  // no text stands for them
    const std::string_view names[] = {name};
    EXPECT_EQ(MapSettingsAsText(settings, names, &values),
              "unknown setting '" + std::string(name) + "'");
  }
}

// The settings a map keeps (the settings table) and MapSettings' detector fields are the same,
// both ways, with matching kinds: the names the server and the clients pass through this text.
TEST(MapSettingsTextTest, TheSettingsAMapKeepsAreExactlyMapSettingsDetectorFields) {
  // MapSettings' fields that are not the detector's settings.
  const std::set<std::string> kNotDetectorSettings = {"group", "rig", "keep_thumbnails"};
  const gp::Descriptor& message = *MapSettings::descriptor();
  for (const std::string_view name : MapDetectorSettingNames()) {
    const DetectorSetting& setting = *FindDetectorSetting(name);
    const gp::FieldDescriptor* field = message.FindFieldByName(std::string(name));
    ASSERT_NE(field, nullptr) << "MapSettings has no field " << name;
    EXPECT_FALSE(field->is_repeated()) << name;
    EXPECT_TRUE(field->has_presence()) << name << ": given or not, as optional";
    switch (setting.kind) {
      case SettingKind::kPreset:
        EXPECT_EQ(field->cpp_type(), gp::FieldDescriptor::CPPTYPE_STRING) << name;
        break;
      case SettingKind::kNumber:
        EXPECT_EQ(field->cpp_type(), gp::FieldDescriptor::CPPTYPE_DOUBLE) << name;
        break;
      case SettingKind::kCount:
        EXPECT_EQ(field->cpp_type(), gp::FieldDescriptor::CPPTYPE_UINT32) << name;
        EXPECT_LE(setting.range.max, double(std::numeric_limits<uint32_t>::max())) << name;
        break;
      case SettingKind::kFlag:
        EXPECT_EQ(field->cpp_type(), gp::FieldDescriptor::CPPTYPE_BOOL) << name;
        break;
      case SettingKind::kChoice: {
        // The enum names the table's choices, and nothing else (besides *_UNSPECIFIED).
        ASSERT_EQ(field->cpp_type(), gp::FieldDescriptor::CPPTYPE_ENUM) << name;
        size_t choices = 0;
        std::string_view rest = setting.choices;
        while (!rest.empty()) {
          const size_t comma = std::min(rest.find(", "), rest.size());
          MapSettings settings;
          EXPECT_EQ(SetMapSettingFromText(&settings, name, rest.substr(0, comma)), "") << name;
          rest.remove_prefix(std::min(comma + 2, rest.size()));
          ++choices;
        }
        EXPECT_EQ(int(choices), field->enum_type()->value_count() - 1) << name;
        break;
      }
    }
    // The table's text of each preset's value reads into the field and back unchanged.
    for (const DetectorPresetInfo& info : DetectorPresets()) {
      const std::string text = FormatDetectorSetting(
          setting, ParseDetectorPreset(DetectorPresetName(info.preset)).value());
      MapSettings settings;
      ASSERT_EQ(SetMapSettingFromText(&settings, name, text), "") << name;
      const std::string_view one[] = {name};
      EXPECT_EQ(AsText(settings, one), (SettingTexts{{std::string(name), text}})) << name;
    }
  }
  for (int i = 0; i < message.field_count(); ++i) {
    const std::string& name = message.field(i)->name();
    if (kNotDetectorSettings.contains(name)) {
      EXPECT_EQ(FindDetectorSetting(name), nullptr) << name << " is not a detector setting";
      continue;
    }
    const DetectorSetting* setting = FindDetectorSetting(name);
    ASSERT_NE(setting, nullptr) << "MapSettings." << name << " is not in the settings table";
    EXPECT_TRUE(setting->kept_by_map) << "MapSettings." << name << " is not kept by a map";
  }
  for (const std::string& name : kNotDetectorSettings) {
    EXPECT_NE(message.FindFieldByName(name), nullptr) << "no MapSettings." << name << " any more";
  }
}

}  // namespace
}  // namespace recog
