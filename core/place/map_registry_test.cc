#include "core/place/map_registry.h"

#include <gtest/gtest.h>

#include "core/index/memory_index_store.h"
#include "core/place/detector_settings.h"
#include "core/vocabulary/vocabulary_io.h"

namespace recog {
namespace {

std::shared_ptr<const Vocabulary> PlaceVocabulary() {
  static const std::shared_ptr<const Vocabulary> vocabulary = [] {
    auto loaded = LoadVocabulary(DefaultPlaceVocabularyPath());
    EXPECT_TRUE(loaded.ok()) << loaded.status().ToString();
    return std::make_shared<const Vocabulary>(std::move(loaded).value());
  }();
  return vocabulary;
}

TEST(MapRegistryTest, MapsAndTheirParametersSurviveAReopen) {
  MemoryIndexStore store;
  {
    auto registry = MapRegistry::Open(&store, PlaceVocabulary());
    ASSERT_TRUE(registry.ok()) << registry.status().ToString();
    LoopDetectorParams params;
    params.alpha = 0.42;
    params.temporal_matches = 1;
    params.epipolar.min_inliers = 20;
    params.geometry = GeometryCheck::kExhaustive;
    params.recent_seconds = 7.5;
    params.recent_frames = 9;
    ASSERT_TRUE((*registry)->Create("b", params).ok());
    ASSERT_TRUE((*registry)->Create("a", LoopDetectorParams{}).ok());
    EXPECT_EQ((*registry)->Create("a", {}).status().code(), StatusCode::kAlreadyExists);
    EXPECT_EQ((*registry)->Create("bad name", {}).status().code(), StatusCode::kInvalidArgument);
    LoopDetectorParams bad;
    bad.alpha = -1;
    EXPECT_EQ((*registry)->Create("c", bad).status().code(), StatusCode::kInvalidArgument);
  }
  auto reopened = MapRegistry::Open(&store, PlaceVocabulary());
  ASSERT_TRUE(reopened.ok()) << reopened.status().ToString();
  const auto maps = (*reopened)->List();
  ASSERT_EQ(maps.size(), 2u);
  EXPECT_EQ(maps[0]->name(), "a");
  EXPECT_EQ(maps[1]->name(), "b");
  const LoopDetectorParams& p = maps[1]->params();
  EXPECT_EQ(p.alpha, 0.42);
  EXPECT_EQ(p.temporal_matches, 1u);
  EXPECT_EQ(p.epipolar.min_inliers, 20u);
  EXPECT_EQ(p.geometry, GeometryCheck::kExhaustive);
  EXPECT_EQ(p.recent_seconds, 7.5);
  EXPECT_EQ(p.recent_frames, 9u);
}

TEST(MapRegistryTest, MapGroupsAreKeptAcrossAReopenAndListedByGroup) {
  MemoryIndexStore store;
  {
    auto registry = MapRegistry::Open(&store, PlaceVocabulary());
    ASSERT_TRUE(registry.ok());
    ASSERT_TRUE((*registry)->Create("robot-a", {}, "fleet").ok());
    ASSERT_TRUE((*registry)->Create("robot-b", {}, "fleet").ok());
    ASSERT_TRUE((*registry)->Create("alone", {}).ok());
    const Status bad = (*registry)->Create("c", {}, "a fleet").status();
    EXPECT_EQ(bad.code(), StatusCode::kInvalidArgument);
    EXPECT_NE(bad.message().find("group"), std::string::npos) << bad.ToString();
    EXPECT_EQ((*registry)->Get("c").status().code(), StatusCode::kNotFound) << "nothing created";
  }
  auto reopened = MapRegistry::Open(&store, PlaceVocabulary());
  ASSERT_TRUE(reopened.ok()) << reopened.status().ToString();
  auto fleet = (*reopened)->Group("fleet");
  ASSERT_TRUE(fleet.ok()) << fleet.status().ToString();
  ASSERT_EQ(fleet->size(), 2u);
  EXPECT_EQ((*fleet)[0]->name(), "robot-a");
  EXPECT_EQ((*fleet)[1]->name(), "robot-b");
  EXPECT_EQ((*fleet)[0]->group(), "fleet");
  EXPECT_EQ((*reopened)->Get("alone").value()->group(), "");
  const Status unknown = (*reopened)->Group("nobody").status();
  EXPECT_EQ(unknown.code(), StatusCode::kNotFound);
  EXPECT_NE(unknown.message().find("'nobody'"), std::string::npos) << unknown.ToString();
  EXPECT_EQ((*reopened)->Group("").status().code(), StatusCode::kNotFound);
}

TEST(MapRegistryTest, DeletingAMapMarksItForItsHoldersAndFreesTheName) {
  MemoryIndexStore store;
  auto registry = MapRegistry::Open(&store, PlaceVocabulary());
  ASSERT_TRUE(registry.ok());
  auto map = (*registry)->Create("m", {});
  ASSERT_TRUE(map.ok());
  auto frames = (*registry)->Delete("m");
  ASSERT_TRUE(frames.ok());
  EXPECT_EQ(*frames, 0u);
  EXPECT_TRUE((*map)->deleted());
  EXPECT_EQ((*registry)->Get("m").status().code(), StatusCode::kNotFound);
  EXPECT_EQ((*registry)->Delete("m").status().code(), StatusCode::kNotFound);
  EXPECT_TRUE((*registry)->Create("m", {}).ok());
  EXPECT_EQ(store.ListBlobKeys("place-settings/").value().size(), 1u);
}

TEST(MapRegistryTest, LeftoverSettingsAreDroppedAndDamagedOnesRefused) {
  MemoryIndexStore store;
  // Settings whose map was never created: a creation interrupted by a crash.
  ASSERT_TRUE(store.PutBlob("place-settings/ghost", EncodePlaceSettings({})).ok());
  {
    auto registry = MapRegistry::Open(&store, PlaceVocabulary());
    ASSERT_TRUE(registry.ok()) << registry.status().ToString();
    EXPECT_TRUE((*registry)->List().empty());
    EXPECT_TRUE(store.ListBlobKeys("place-settings/").value().empty());
    ASSERT_TRUE((*registry)->Create("real", {}).ok());
  }
  ASSERT_TRUE(store.PutBlob("place-settings/real", "alpha 0.3\n").ok());  // no version line
  EXPECT_EQ(MapRegistry::Open(&store, PlaceVocabulary()).status().code(), StatusCode::kDataLoss);
  ASSERT_TRUE(store.PutBlob("place-settings/real", "version 1\nalpha banana\n").ok());
  EXPECT_EQ(MapRegistry::Open(&store, PlaceVocabulary()).status().code(), StatusCode::kDataLoss);
  ASSERT_TRUE(store.PutBlob("place-settings/real", "version 1\ngeometry sideways\n").ok());
  EXPECT_EQ(MapRegistry::Open(&store, PlaceVocabulary()).status().code(), StatusCode::kDataLoss);
  ASSERT_TRUE(store.PutBlob("place-settings/real", "version 1\ngroup a/b\n").ok());
  EXPECT_EQ(MapRegistry::Open(&store, PlaceVocabulary()).status().code(), StatusCode::kDataLoss);
  ASSERT_TRUE(store.PutBlob("place-settings/real", "version 9\n").ok());
  EXPECT_EQ(MapRegistry::Open(&store, PlaceVocabulary()).status().code(),
            StatusCode::kFailedPrecondition);
}

TEST(MapRegistryTest, SettingsRoundTripThroughTheirText) {
  LoopDetectorParams p;
  p.alpha = 0.1 + 0.2;  // not exactly representable: the text keeps every bit
  p.geometry = GeometryCheck::kNone;
  auto decoded = DecodePlaceSettings(EncodePlaceSettings(p));
  ASSERT_TRUE(decoded.ok());
  EXPECT_EQ(decoded->alpha, p.alpha);
  EXPECT_EQ(decoded->geometry, GeometryCheck::kNone);
  std::string group = "stale";
  ASSERT_TRUE(DecodePlaceSettings(EncodePlaceSettings(p), &group).ok());
  EXPECT_EQ(group, "") << "no group line: no group";
  ASSERT_TRUE(DecodePlaceSettings(EncodePlaceSettings(p, "fleet-7"), &group).ok());
  EXPECT_EQ(group, "fleet-7");
  // The preset, then only what differs from it.
  EXPECT_EQ(EncodePlaceSettings(p),
            "version 4\npreset default\nalpha 0.30000000000000004\n"
            "geometry none\n");
  p.keyframe_confirmations = 2;
  decoded = DecodePlaceSettings(EncodePlaceSettings(p));
  ASSERT_TRUE(decoded.ok());
  EXPECT_EQ(decoded->keyframe_confirmations, 2u);
}

TEST(MapRegistryTest, ARigRoundTripsThroughTheSettingsTextExactly) {
  RigCamera front;
  front.name = "front";
  front.size = {752, 480};
  front.K = cv::Matx33d(458.654, 0, 367.215, 0, 457.296, 248.375, 0, 0, 1);
  front.distortion = {-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05};
  front.body_t_camera = {0.1 / 3.0, 0, 0.4};
  RigCamera rear = front;
  rear.name = "rear";
  rear.distortion = {0.0034, 0.0007, -0.0029, 0.0003};
  rear.lens = LensModel::kEquidistant;
  rear.body_R_camera = cv::Matx33d(-1, 0, 0, 0, 1, 0, 0, 0, -1);
  const std::string text = EncodePlaceSettings({}, "fleet", {front, rear});
  std::vector<RigCamera> rig;
  std::string group;
  ASSERT_TRUE(DecodePlaceSettings(text, &group, &rig).ok());
  EXPECT_EQ(group, "fleet");
  ASSERT_EQ(rig.size(), 2u);
  EXPECT_EQ(rig[0].name, "front");
  EXPECT_EQ(rig[0].size, front.size);
  EXPECT_EQ(rig[0].K, front.K);
  EXPECT_EQ(rig[0].distortion, front.distortion);
  EXPECT_EQ(rig[0].body_t_camera, front.body_t_camera);
  EXPECT_EQ(rig[1].body_R_camera, rear.body_R_camera);
  EXPECT_EQ(rig[0].lens, LensModel::kRadialTangential);
  EXPECT_EQ(rig[1].distortion, rear.distortion);
  EXPECT_EQ(rig[1].lens, LensModel::kEquidistant);
  // A line of before lenses is a radtan camera; a lens no one knows is damage.
  const std::string before_lenses = text.substr(0, text.find(" lens equidistant")) + "\n";
  ASSERT_TRUE(DecodePlaceSettings(before_lenses, nullptr, &rig).ok());
  EXPECT_EQ(rig[1].lens, LensModel::kRadialTangential);
  std::string unknown = text;
  unknown.replace(unknown.find("equidistant"), 11, "omni");
  EXPECT_EQ(DecodePlaceSettings(unknown, nullptr, &rig).status().code(), StatusCode::kDataLoss);

  // A line cut short, and a camera that is not a rigid transform, are damage.
  const std::string cut = text.substr(0, text.rfind(' '));
  EXPECT_EQ(DecodePlaceSettings(cut, nullptr, &rig).status().code(), StatusCode::kDataLoss);
  std::string scaled = EncodePlaceSettings({}, "", {front});
  scaled.replace(scaled.find(" 1 0 0 0 1 0 0 0 1 "), 19, " 2 0 0 0 1 0 0 0 1 ");
  const Status bad = DecodePlaceSettings(scaled, nullptr, &rig).status();
  EXPECT_EQ(bad.code(), StatusCode::kDataLoss);
  EXPECT_NE(bad.message().find("'front'"), std::string::npos) << bad.ToString();
}

TEST(MapRegistryTest, AMapKeepsItsPresetAcrossAReopenWithItsOwnValuesOverIt) {
  MemoryIndexStore store;
  LoopDetectorParams keyframes = LoopDetectorParams::Keyframes();
  keyframes.recent_frames = 7;
  {
    auto registry = MapRegistry::Open(&store, PlaceVocabulary());
    ASSERT_TRUE(registry.ok());
    ASSERT_TRUE((*registry)->Create("slam", keyframes).ok());
    ASSERT_TRUE((*registry)->Create("thesis", LoopDetectorParams::Thesis()).ok());
  }
  auto reopened = MapRegistry::Open(&store, PlaceVocabulary());
  ASSERT_TRUE(reopened.ok());
  auto slam = (*reopened)->Get("slam");
  ASSERT_TRUE(slam.ok());
  const LoopDetectorParams& p = (*slam)->params();
  EXPECT_EQ(p.preset, DetectorPreset::kKeyframes);
  EXPECT_EQ(p.normalisation, ScoreNormalisation::kBestCandidate) << "from the preset";
  EXPECT_EQ(p.consistency_max_island_gap, 1u) << "from the preset";
  EXPECT_EQ(p.recent_frames, 7u) << "the map's own value over the preset's 3";
  auto thesis = (*reopened)->Get("thesis");
  ASSERT_TRUE(thesis.ok());
  EXPECT_FALSE((*thesis)->params().strong_acceptance) << "a thesis map stays a thesis map";
}

TEST(MapRegistryTest, AnOlderKeyframesMapFollowsThePresetsNewValuesUnlessItChangedThem) {
  const std::string v1 =
      "version 1\npreset keyframes\nalpha 0.3\ntemporal_matches 3\nmin_inliers 12\n"
      "recent_seconds 20\nrecent_frames 4\ngeometry direct_index\nkeyframe_confirmations 0\n";
  auto migrated = DecodePlaceSettings(v1);
  ASSERT_TRUE(migrated.ok()) << migrated.status().ToString();
  const LoopDetectorParams now = LoopDetectorParams::Keyframes();
  EXPECT_EQ(migrated->geometry, now.geometry);
  EXPECT_EQ(migrated->epipolar.min_inliers, now.epipolar.min_inliers);
  EXPECT_EQ(migrated->recent_frames, now.recent_frames);
  EXPECT_TRUE(migrated->matching.mutual);
  // Version 2 had today's correspondences: only its recent window was the preset's of then.
  auto v2 = DecodePlaceSettings("version 2\npreset keyframes\nrecent_frames 4\nmin_inliers 12\n");
  ASSERT_TRUE(v2.ok()) << v2.status().ToString();
  EXPECT_EQ(v2->recent_frames, now.recent_frames);
  EXPECT_EQ(v2->epipolar.min_inliers, 12u) << "a version-2 map chose 12 itself";
  // A value the map changed is kept; a default map keeps its values (not a keyframes map).
  auto changed = DecodePlaceSettings(
      "version 1\npreset keyframes\nmin_inliers 40\ngeometry direct_index\nrecent_frames 6\n");
  ASSERT_TRUE(changed.ok());
  EXPECT_EQ(changed->epipolar.min_inliers, 40u);
  EXPECT_EQ(changed->geometry, GeometryCheck::kExhaustive);
  EXPECT_EQ(changed->recent_frames, 6u);
  auto video = DecodePlaceSettings("version 1\npreset default\nmin_inliers 12\nrecent_frames 4\n");
  ASSERT_TRUE(video.ok());
  EXPECT_EQ(video->geometry, GeometryCheck::kDirectIndex);
  EXPECT_EQ(video->epipolar.min_inliers, 12u);
  EXPECT_EQ(video->recent_frames, 4u);
  // Written now: version 4, read back exactly, the old values included when a map sets them.
  LoopDetectorParams own = now;
  own.geometry = GeometryCheck::kDirectIndex;
  own.epipolar.min_inliers = 12;
  own.strong_min_inliers = 12;
  own.recent_frames = 4;
  const std::string text = EncodePlaceSettings(own);
  EXPECT_EQ(text.rfind("version 4\n", 0), 0u) << text;
  auto kept = DecodePlaceSettings(text);
  ASSERT_TRUE(kept.ok());
  EXPECT_EQ(kept->geometry, GeometryCheck::kDirectIndex);
  EXPECT_EQ(kept->epipolar.min_inliers, 12u);
  EXPECT_EQ(kept->recent_frames, 4u);
}

// Every setting's value in `params`, as text: equal texts, equal parameters.
std::vector<std::string> AllSettings(const LoopDetectorParams& params) {
  std::vector<std::string> out;
  for (const DetectorSetting& s : DetectorSettings()) {
    out.push_back(std::string(s.name) + " " + FormatDetectorSetting(s, params));
  }
  return out;
}

// Settings as versions 1 to 3 wrote them (every kept value, the preset's own included) load to
// the parameters they always did.
TEST(MapRegistryTest, StoredSettingsOfEveryEarlierVersionLoadAsBefore) {
  const std::string common = "alpha 0.29999999999999999\ntemporal_matches 3\n";
  const std::string video =
      "min_inliers 12\ngeometry direct_index\nrecent_seconds 20\nrecent_frames 20\n"
      "keyframe_confirmations 0\n";
  LoopDetectorParams keyframes = LoopDetectorParams::Keyframes();
  LoopDetectorParams own_keyframes = keyframes;
  own_keyframes.recent_frames = 7;
  own_keyframes.keyframe_confirmations = 2;
  const std::vector<std::pair<std::string, LoopDetectorParams>> stored = {
      {"version 3\npreset default\n" + common + video, LoopDetectorParams{}},
      {"version 3\npreset thesis\n" + common + video, LoopDetectorParams::Thesis()},
      {"version 3\npreset keyframes\n" + common +
           "min_inliers 45\ngeometry exhaustive\nrecent_seconds 20\nrecent_frames 3\n"
           "keyframe_confirmations 0\n",
       keyframes},
      {"version 3\npreset keyframes\n" + common +
           "min_inliers 45\ngeometry exhaustive\nrecent_seconds 20\nrecent_frames 7\n"
           "keyframe_confirmations 2\n",
       own_keyframes},
      // Version 2's keyframes preset left out 4 frames; version 1's had the direct index's
      // correspondences with 12 inliers: a map holding them follows the preset of now.
      {"version 2\npreset keyframes\n" + common +
           "min_inliers 45\ngeometry exhaustive\nrecent_seconds 20\nrecent_frames 4\n"
           "keyframe_confirmations 0\n",
       keyframes},
      {"version 1\npreset keyframes\n" + common +
           "min_inliers 12\ngeometry direct_index\nrecent_seconds 20\nrecent_frames 4\n",
       keyframes},
      {"version 2\npreset default\n" + common + video, LoopDetectorParams{}},
      {"version 1\n" + common + video, LoopDetectorParams{}},
  };
  for (const auto& [text, expected] : stored) {
    auto decoded = DecodePlaceSettings(text);
    ASSERT_TRUE(decoded.ok()) << text << decoded.status().ToString();
    EXPECT_EQ(AllSettings(*decoded), AllSettings(expected)) << text;
  }
}

// The version line takes any positive number: one above this build's is a newer writer's
// (refused, nothing guessed), and anything else is damage.
TEST(MapRegistryTest, ANewerVersionIsRefusedAndAMalformedOneIsDataLoss) {
  for (const std::string version : {"5", "10", "99999999999999999999999"}) {
    const Status refused =
        DecodePlaceSettings("version " + version + "\npreset keyframes\n").status();
    EXPECT_EQ(refused.code(), StatusCode::kFailedPrecondition) << version;
    EXPECT_EQ(refused.message(), "place settings of an unknown version " + version);
  }
  for (const char* version : {"0", "x", "-1", "4x", "+4"}) {
    const Status malformed =
        DecodePlaceSettings("version " + std::string(version) + "\npreset keyframes\n").status();
    EXPECT_EQ(malformed.code(), StatusCode::kDataLoss) << version;
    EXPECT_NE(malformed.message().find("malformed version"), std::string::npos)
        << malformed.ToString();
  }
  EXPECT_TRUE(DecodePlaceSettings("version 4\npreset keyframes\n").ok());
  EXPECT_EQ(DecodePlaceSettings("version 4\npreset keyframes\npreset thesis\n").status().code(),
            StatusCode::kDataLoss);
}

TEST(MapRegistryTest, EveryPresetRoundTripsWithAndWithoutChangesStoringOnlyTheChanges) {
  for (const DetectorPresetInfo& info : DetectorPresets()) {
    const std::string name(DetectorPresetName(info.preset));
    const LoopDetectorParams preset = ParseDetectorPreset(name).value();
    const std::string text = EncodePlaceSettings(preset);
    EXPECT_EQ(text, "version 4\npreset " + name + "\n");
    auto decoded = DecodePlaceSettings(text);
    ASSERT_TRUE(decoded.ok()) << decoded.status().ToString();
    EXPECT_EQ(AllSettings(*decoded), AllSettings(preset)) << name;

    LoopDetectorParams changed = preset;
    changed.alpha = 0.1 + 0.2;
    changed.temporal_matches = 5;
    changed.epipolar.min_inliers = 20;
    changed.strong_min_inliers = 50;  // not kept by a map: back to the preset's when read
    changed.geometry = GeometryCheck::kNone;
    changed.recent_seconds = 2.5;
    changed.recent_frames = preset.recent_frames + 1;
    changed.keyframe_confirmations = 1;
    decoded = DecodePlaceSettings(EncodePlaceSettings(changed, "fleet"));
    ASSERT_TRUE(decoded.ok()) << decoded.status().ToString();
    changed.strong_min_inliers = preset.strong_min_inliers;
    EXPECT_EQ(AllSettings(*decoded), AllSettings(changed)) << name;
  }
}

// A preset retuned in a later build reaches every stored map that did not change that setting;
// a map that set it keeps its own value, and the maps of other presets do not move.
TEST(MapRegistryTest, ARetunedPresetReachesTheMapsThatDidNotChangeThatSetting) {
  LoopDetectorParams own = LoopDetectorParams::Keyframes();
  own.recent_frames = 9;
  const std::string follows = EncodePlaceSettings(LoopDetectorParams::Keyframes());
  const std::string sets_it = EncodePlaceSettings(own);
  const std::string video = EncodePlaceSettings(LoopDetectorParams{});
  const PresetValues retuned = [](std::string_view name) -> StatusOr<LoopDetectorParams> {
    RECOG_ASSIGN_OR_RETURN(LoopDetectorParams values, ParseDetectorPreset(name));
    if (values.preset == DetectorPreset::kKeyframes) values.recent_frames = 5;
    return values;
  };
  auto followed = DecodePlaceSettings(follows, retuned);
  ASSERT_TRUE(followed.ok()) << followed.status().ToString();
  EXPECT_EQ(followed->recent_frames, 5u) << "the retuned preset's value";
  EXPECT_EQ(followed->preset, DetectorPreset::kKeyframes);
  auto kept = DecodePlaceSettings(sets_it, retuned);
  ASSERT_TRUE(kept.ok());
  EXPECT_EQ(kept->recent_frames, 9u) << "the map's own value";
  auto other = DecodePlaceSettings(video, retuned);
  ASSERT_TRUE(other.ok());
  EXPECT_EQ(other->recent_frames, LoopDetectorParams{}.recent_frames);
  // An unknown preset from the lookup is damage, named.
  const PresetValues none = [](std::string_view name) -> StatusOr<LoopDetectorParams> {
    return Status::InvalidArgument("no preset " + std::string(name));
  };
  const Status refused = DecodePlaceSettings(follows, none).status();
  EXPECT_EQ(refused.code(), StatusCode::kDataLoss);
  EXPECT_NE(refused.message().find("no preset keyframes"), std::string::npos) << refused.ToString();
}

TEST(MapRegistryTest, SettingsWrittenBeforePresetsOpenWithTheDefaultAndAnUnknownPresetIsDataLoss) {
  auto old = DecodePlaceSettings(
      "version 1\nalpha 0.3\ntemporal_matches 3\nmin_inliers 12\nrecent_seconds 20\n"
      "recent_frames 20\ngeometry direct_index\n");
  ASSERT_TRUE(old.ok()) << old.status().ToString();
  EXPECT_EQ(old->preset, DetectorPreset::kDefault);
  EXPECT_TRUE(old->strong_acceptance);
  EXPECT_EQ(old->keyframe_confirmations, 0u) << "settings older than keyframe confirmations";
  auto unknown = DecodePlaceSettings("version 1\npreset sideways\n");
  EXPECT_EQ(unknown.status().code(), StatusCode::kDataLoss);
  EXPECT_NE(unknown.status().message().find("sideways"), std::string::npos);
}

}  // namespace
}  // namespace recog
