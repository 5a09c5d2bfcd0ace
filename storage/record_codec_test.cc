// The record codec on its own: exact round trips, key order, and decoders that turn every kind
// of damaged value into DATA_LOSS without reading out of bounds (run it under ASan to see that).
#include "storage/record_codec.h"

#include <random>
#include <string>

#include <gtest/gtest.h>

#include "storage/store_test_util.h"

namespace recog::storage {
namespace {

using recog::testing::EntryDifference;
using recog::testing::MakeTestEntry;

const RecordContext kContext{3, 17};

// Every encoded part of an entry, with a decoder that fills the matching part of a record.
struct Part {
  const char* name;
  uint32_t flag;
  std::string bytes;
  Status (*decode)(std::string_view, EntryRecord*);
};

std::vector<Part> EncodeParts(const EntryRecord& e) {
  return {
      {"metadata", kEntryMetadata, EncodeMetadata(e.metadata),
       [](std::string_view b, EntryRecord* r) {
         return DecodeMetadata(b, kContext, &r->metadata);
       }},
      {"bow", kEntryBow, EncodeBow(e.bow),
       [](std::string_view b, EntryRecord* r) { return DecodeBow(b, kContext, &r->bow); }},
      {"direct", kEntryDirect, EncodeDirect(e.direct),
       [](std::string_view b, EntryRecord* r) { return DecodeDirect(b, kContext, &r->direct); }},
      {"features", kEntryFeatures, *EncodeFeatures(e.keypoints, e.descriptors, e.points, e.camera),
       [](std::string_view b, EntryRecord* r) {
         return DecodeFeatures(b, kContext, &r->keypoints, &r->descriptors, &r->points, &r->camera);
       }},
  };
}

TEST(RecordCodecTest, EntryKeysSortInNumericOrder) {
  const std::vector<std::pair<MapId, EntryId>> ordered = {{1, 0},
                                                          {1, 1},
                                                          {1, 2},
                                                          {1, 255},
                                                          {1, 256},
                                                          {1, 65536},
                                                          {1, 0xfffffffe},
                                                          {1, 0xffffffff},
                                                          {2, 0},
                                                          {256, 1},
                                                          {0xffffffff, 0xffffffff}};
  for (size_t i = 1; i < ordered.size(); ++i) {
    EXPECT_LT(EntryKey(ordered[i - 1].first, ordered[i - 1].second),
              EntryKey(ordered[i].first, ordered[i].second));
  }
  for (const auto& [map, id] : ordered) {
    const std::string key = EntryKey(map, id);
    EXPECT_EQ(key.size(), kEntryKeySize);
    MapId m = 0;
    EntryId e = 0;
    ASSERT_TRUE(DecodeEntryKey(key, &m, &e));
    EXPECT_EQ(m, map);
    EXPECT_EQ(e, id);
    EXPECT_LE(MapEntriesBegin(map), key);
    EXPECT_LT(key, MapEntriesEnd(map));
    if (map != 0xffffffff) {
      EXPECT_LT(MapEntriesEnd(map), MapEntriesBegin(map + 1));
    }
  }
  MapId m = 0;
  EntryId e = 0;
  EXPECT_FALSE(DecodeEntryKey("short", &m, &e));
  ASSERT_TRUE(DecodeNextEntryIdKey(NextEntryIdKey(0x01020304), &m));
  EXPECT_EQ(m, 0x01020304u);
  EXPECT_FALSE(DecodeNextEntryIdKey(MapInfoKey("abcd"), &m));
}

TEST(RecordCodecTest, EntryPartsRoundTripBitExactly) {
  for (const DescriptorFormat format : {DescriptorFormat::Orb(), DescriptorFormat::Sift()}) {
    for (EntryId id = 0; id < 20; ++id) {
      const EntryRecord entry = MakeTestEntry(id, 5, format, 400);
      EntryRecord decoded;
      decoded.id = id;
      for (const Part& part : EncodeParts(entry)) {
        const Status s = part.decode(part.bytes, &decoded);
        ASSERT_TRUE(s.ok()) << part.name << ": " << s.ToString();
      }
      EXPECT_EQ(EntryDifference(decoded, entry), "");
    }
  }
}

// Metadata records as versions before optional timestamps wrote them, byte by byte, still read:
// without a client id (format 1) and with one (format 2); their timestamp 0 meant "none".
TEST(RecordCodecTest, OldMetadataRecordsReadWithTheirClientIdAndZeroAsNoTimestamp) {
  std::string old_bytes(1, char(kRecordFormat));
  old_bytes.append("\x00\x00\x00\x00\x00\x00\x29\x40", 8);  // 12.5, little-endian
  old_bytes.append("\x07\x00\x00\x00\x03\x00\x00\x00", 8);
  old_bytes += "cam";
  EntryMetadata decoded;
  decoded.client_id = "stale";
  ASSERT_TRUE(DecodeMetadata(old_bytes, kContext, &decoded).ok());
  EXPECT_EQ(decoded.timestamp, 12.5);
  EXPECT_EQ(decoded.num_features, 7u);
  EXPECT_EQ(decoded.user_data, "cam");
  EXPECT_EQ(decoded.client_id, "");

  std::string with_id(1, char(kMetadataWithClientIdFormat));
  with_id.append(8, '\0');  // timestamp 0: none
  with_id.append("\x07\x00\x00\x00\x03\x00\x00\x00", 8);
  with_id += "cam";
  with_id.append("\x02\x00\x00\x00", 4);
  with_id += "kf";
  ASSERT_TRUE(DecodeMetadata(with_id, kContext, &decoded).ok());
  EXPECT_EQ(decoded.timestamp, std::nullopt);
  EXPECT_EQ(decoded.client_id, "kf");
}

// Now a timestamp is optional and 0.0 is a time: none, 0.0 and others round-trip as themselves,
// and the flags byte is checked.
TEST(RecordCodecTest, MetadataKeepsNoTimestampApartFromTimeZero) {
  for (const std::optional<double> timestamp :
       {std::optional<double>(), std::optional<double>(0.0), std::optional<double>(-2.5)}) {
    EntryMetadata metadata;
    metadata.timestamp = timestamp;
    metadata.num_features = 3;
    metadata.client_id = std::string("kf\0-42", 6);
    const std::string encoded = EncodeMetadata(metadata);
    EXPECT_EQ(uint8_t(encoded[0]), kMetadataFormat);
    EntryMetadata decoded;
    ASSERT_TRUE(DecodeMetadata(encoded, kContext, &decoded).ok());
    EXPECT_EQ(decoded, metadata);
  }
  EntryMetadata metadata;
  std::string encoded = EncodeMetadata(metadata);
  encoded[1] = char(0x80);  // an unknown flag
  EXPECT_EQ(DecodeMetadata(encoded, kContext, &metadata).code(), StatusCode::kDataLoss);
}

TEST(RecordCodecTest, NonContinuousDescriptorsAreStoredRowByRow) {
  cv::Mat big(10, 64, CV_8U);
  cv::randu(big, 0, 256);
  const cv::Mat view = big.colRange(16, 48);  // 32 columns, not continuous
  ASSERT_FALSE(view.isContinuous());
  auto bytes = EncodeFeatures({}, view, {});
  ASSERT_TRUE(bytes.ok());
  std::vector<cv::KeyPoint> keypoints;
  cv::Mat decoded;
  std::vector<cv::Point3f> points;
  cv::Matx33d camera;
  ASSERT_TRUE(DecodeFeatures(*bytes, kContext, &keypoints, &decoded, &points, &camera).ok());
  EXPECT_TRUE(recog::testing::SameMatrix(decoded, view));
}

// Features records keep the layouts older versions wrote when the entry has no camera matrix, so
// a store written by this version reads back in an older one as long as no frame came with one.
TEST(RecordCodecTest, FeaturesWithoutACameraKeepTheirOlderLayouts) {
  EntryRecord entry = MakeTestEntry(1, 0, DescriptorFormat::Orb(), 20);  // 3D points
  ASSERT_FALSE(entry.points.empty());
  EXPECT_EQ(EncodeFeatures(entry.keypoints, entry.descriptors, entry.points)->front(),
            char(kFeaturesWithPointsFormat));
  EXPECT_EQ(EncodeFeatures(entry.keypoints, entry.descriptors, {})->front(), char(kRecordFormat));
  const cv::Matx33d K(500, 0, 320, 0, 500, 240, 0, 0, 1);
  const std::string with_camera = *EncodeFeatures(entry.keypoints, entry.descriptors, {}, K);
  EXPECT_EQ(with_camera.front(), char(kFeaturesWithCameraFormat));
  std::vector<cv::KeyPoint> keypoints;
  cv::Mat descriptors;
  std::vector<cv::Point3f> points = {{1, 2, 3}};
  cv::Matx33d camera;
  ASSERT_TRUE(
      DecodeFeatures(with_camera, kContext, &keypoints, &descriptors, &points, &camera).ok());
  EXPECT_EQ(camera, K);
  EXPECT_TRUE(points.empty());
  EXPECT_EQ(keypoints.size(), entry.keypoints.size());
  // A camera matrix without a positive focal length is damage.
  std::string damaged = with_camera;
  const size_t fx_offset = with_camera.size() - 4 - 72;
  const double negative = -500;
  damaged.replace(fx_offset, 8, reinterpret_cast<const char*>(&negative), 8);
  const Status s = DecodeFeatures(damaged, kContext, &keypoints, &descriptors, &points, &camera);
  EXPECT_EQ(s.code(), StatusCode::kDataLoss);
  EXPECT_NE(s.message().find("camera matrix"), std::string::npos) << s.message();
}

TEST(RecordCodecTest, CatalogRecordsRoundTrip) {
  MapInfo info;
  info.id = 42;
  info.created_unix_ms = 1700000000123;
  info.config = recog::testing::TestMapConfig("office-3", DescriptorFormat::Sift());
  info.config.scoring = ScoringType::kBhattacharyya;
  MapInfo decoded;
  ASSERT_TRUE(DecodeMapInfo("office-3", EncodeMapInfo(info), &decoded).ok());
  EXPECT_EQ(decoded, info);

  StoreRecord store{77};
  StoreRecord store_decoded;
  ASSERT_TRUE(DecodeStoreRecord(EncodeStoreRecord(store), &store_decoded).ok());
  EXPECT_EQ(store_decoded.next_map_id, 77u);

  EntryId next = 0;
  ASSERT_TRUE(DecodeNextEntryId(EncodeNextEntryId(123456), kContext, &next).ok());
  EXPECT_EQ(next, 123456u);
}

TEST(RecordCodecTest, EveryTruncationIsDataLossNamingTheRecord) {
  // Entries 1 (3D points), 3 (points and a camera) and 6 (a camera only): every features layout.
  std::vector<Part> parts;
  for (const EntryId id : {1, 3, 6}) {
    for (Part& part : EncodeParts(MakeTestEntry(id, 2, DescriptorFormat::Orb(), 20))) {
      parts.push_back(std::move(part));
    }
  }
  for (const Part& part : parts) {
    for (size_t n = 0; n < part.bytes.size(); ++n) {
      EntryRecord decoded;
      const Status s = part.decode(std::string_view(part.bytes).substr(0, n), &decoded);
      ASSERT_EQ(s.code(), StatusCode::kDataLoss) << part.name << " cut at " << n;
      EXPECT_NE(s.message().find("map 3 entry 17"), std::string::npos) << s.message();
    }
    // One byte too many is damage as well.
    EntryRecord decoded;
    EXPECT_EQ(part.decode(part.bytes + "x", &decoded).code(), StatusCode::kDataLoss) << part.name;
  }
  MapInfo info;
  info.id = 1;
  info.config = recog::testing::TestMapConfig("m");
  const std::string map_bytes = EncodeMapInfo(info);
  for (size_t n = 0; n < map_bytes.size(); ++n) {
    MapInfo decoded;
    EXPECT_EQ(DecodeMapInfo("m", map_bytes.substr(0, n), &decoded).code(), StatusCode::kDataLoss);
  }
}

TEST(RecordCodecTest, UnknownFormatByteIsDataLoss) {
  const EntryRecord entry = MakeTestEntry(1);
  for (Part& part : EncodeParts(entry)) {
    part.bytes[0] = char(0x7f);
    EntryRecord decoded;
    EXPECT_EQ(part.decode(part.bytes, &decoded).code(), StatusCode::kDataLoss) << part.name;
  }
  std::string store = EncodeStoreRecord({5});
  store[0] = char(kRecordFormat + 1);
  StoreRecord decoded;
  EXPECT_EQ(DecodeStoreRecord(store, &decoded).code(), StatusCode::kFailedPrecondition);
}

TEST(RecordCodecTest, HugeCountsAreRejectedBeforeAllocating) {
  std::string bow(1, char(kRecordFormat));
  bow += std::string("\xff\xff\xff\xff", 4);  // 4 billion words in 5 bytes
  BowVector v;
  EXPECT_EQ(DecodeBow(bow, kContext, &v).code(), StatusCode::kDataLoss);

  std::string direct(1, char(kRecordFormat));
  direct += std::string("\xff\xff\xff\xff\xff\xff\xff\xff", 8);
  FeatureVector f;
  EXPECT_EQ(DecodeDirect(direct, kContext, &f).code(), StatusCode::kDataLoss);

  // 0x7fffffff x 0x7fffffff CV_64FC4 descriptors: the byte count would overflow 64 bits.
  std::string features(1, char(kRecordFormat));
  features += std::string(4, '\0');  // no keypoints
  features += std::string("\xff\xff\xff\x7f\xff\xff\xff\x7f", 8);
  const int32_t type = CV_64FC4;
  features.append(reinterpret_cast<const char*>(&type), 4);
  std::vector<cv::KeyPoint> k;
  cv::Mat d;
  std::vector<cv::Point3f> p;
  cv::Matx33d camera;
  EXPECT_EQ(DecodeFeatures(features, kContext, &k, &d, &p, &camera).code(), StatusCode::kDataLoss);
}

TEST(RecordCodecTest, BrokenInvariantsAreDataLoss) {
  // Bow words out of order.
  BowVector unsorted;
  unsorted.AppendSorted(5, 0.5f);
  unsorted.AppendSorted(3, 0.5f);
  BowVector v;
  EXPECT_EQ(DecodeBow(EncodeBow(unsorted), kContext, &v).code(), StatusCode::kDataLoss);

  // Direct-index nodes out of order, features out of order under a node.
  const uint32_t a[] = {1, 2};
  const uint32_t b[] = {2, 1};
  FeatureVector nodes_unsorted;
  nodes_unsorted.AppendNode(9, a);
  nodes_unsorted.AppendNode(4, a);
  FeatureVector f;
  EXPECT_EQ(DecodeDirect(EncodeDirect(nodes_unsorted), kContext, &f).code(), StatusCode::kDataLoss);
  FeatureVector features_unsorted;
  features_unsorted.AppendNode(4, b);
  EXPECT_EQ(DecodeDirect(EncodeDirect(features_unsorted), kContext, &f).code(),
            StatusCode::kDataLoss);

  // CheckStorable refuses to write what the decoders would refuse to read.
  EntryRecord entry;
  entry.id = 1;
  entry.bow = unsorted;
  EXPECT_EQ(CheckStorable(entry).code(), StatusCode::kInvalidArgument);
  entry.bow = BowVector();
  entry.direct = nodes_unsorted;
  EXPECT_EQ(CheckStorable(entry).code(), StatusCode::kInvalidArgument);
  entry.direct = features_unsorted;
  EXPECT_EQ(CheckStorable(entry).code(), StatusCode::kInvalidArgument);
  entry.direct = FeatureVector();
  EXPECT_TRUE(CheckStorable(MakeTestEntry(3)).ok());
}

TEST(RecordCodecTest, RandomDamageNeverCrashes) {
  const EntryRecord entry = MakeTestEntry(9, 1, DescriptorFormat::Orb(), 30);
  std::mt19937 rng(12345);
  int rejected = 0;
  for (const Part& original : EncodeParts(entry)) {
    for (int trial = 0; trial < 2000; ++trial) {
      std::string bytes = original.bytes;
      const int flips = 1 + int(rng() % 4);
      for (int i = 0; i < flips; ++i) bytes[rng() % bytes.size()] = char(rng());
      if (rng() % 4 == 0) bytes.resize(rng() % (bytes.size() + 1));
      EntryRecord decoded;
      const Status s = original.decode(bytes, &decoded);
      ASSERT_TRUE(s.ok() || s.code() == StatusCode::kDataLoss) << s.ToString();
      rejected += !s.ok();
    }
  }
  EXPECT_GT(rejected, 0);
  // Pure noise.
  for (int trial = 0; trial < 2000; ++trial) {
    std::string bytes(rng() % 64, '\0');
    for (char& c : bytes) c = char(rng());
    if (!bytes.empty()) bytes[0] = char(kRecordFormat);
    EntryRecord decoded;
    for (const Part& part : EncodeParts(entry)) {
      const Status s = part.decode(bytes, &decoded);
      ASSERT_TRUE(s.ok() || s.code() == StatusCode::kDataLoss) << s.ToString();
    }
  }
}

}  // namespace
}  // namespace recog::storage
