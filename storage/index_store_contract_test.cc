// The IndexStore contract (core/index/index_store.h), checked against every implementation:
// MemoryIndexStore, and RocksDbIndexStore with each sync policy. A new implementation gets the
// whole suite by adding one factory to kFactories.
#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstring>
#include <functional>
#include <limits>
#include <memory>
#include <ostream>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "core/index/index_store.h"
#include "core/index/memory_index_store.h"
#include "storage/rocksdb_index_store.h"
#include "storage/store_test_util.h"

namespace recog {
namespace {

using testing::EntryDifference;
using testing::MakeTestEntry;
using testing::TempDir;
using testing::TestMapConfig;

struct StoreFactory {
  std::string name;
  // Opens a store kept under `dir` (an empty directory owned by the test).
  std::function<std::unique_ptr<IndexStore>(const std::string& dir)> make;
};

void PrintTo(const StoreFactory& factory, std::ostream* os) { *os << factory.name; }

std::unique_ptr<IndexStore> OpenRocksDb(const std::string& dir, SyncPolicy sync) {
  RocksDbStoreOptions options;
  options.sync = sync;
  options.group_sync_interval_ms = 5;
  auto store = OpenRocksDbIndexStore(dir + "/store", options);
  if (!store.ok()) {
    ADD_FAILURE() << store.status().ToString();
    return nullptr;
  }
  return std::move(store).value();
}

const StoreFactory kFactories[] = {
    {"Memory", [](const std::string&) { return std::make_unique<MemoryIndexStore>(); }},
    {"RocksDbEveryWrite",
     [](const std::string& dir) { return OpenRocksDb(dir, SyncPolicy::kEveryWrite); }},
    {"RocksDbGrouped",
     [](const std::string& dir) { return OpenRocksDb(dir, SyncPolicy::kGrouped); }},
};

class IndexStoreContractTest : public ::testing::TestWithParam<StoreFactory> {
 protected:
  void SetUp() override {
    store_ = GetParam().make(dir_.path().string());
    ASSERT_NE(store_, nullptr);
  }

  MapInfo NewMap(const std::string& name, DescriptorFormat format = DescriptorFormat::Orb()) {
    auto map = store_->CreateMap(TestMapConfig(name, format));
    EXPECT_TRUE(map.ok()) << map.status().ToString();
    return map.ok() ? *map : MapInfo{};
  }

  // Every entry of `map` with the requested parts, in visiting order.
  std::vector<EntryRecord> ScanAll(MapId map, uint32_t parts = kEntryAllParts) {
    std::vector<EntryRecord> out;
    const Status s = store_->ScanEntries(map, 0, parts, [&](EntryRecord& e) {
      out.push_back(std::move(e));
      return Status::Ok();
    });
    EXPECT_TRUE(s.ok()) << s.ToString();
    return out;
  }

  TempDir dir_{"contract"};  // declared first: outlives the store
  std::unique_ptr<IndexStore> store_;
};

// --- Maps ---

TEST_P(IndexStoreContractTest, CreatedMapsHaveDistinctIdsAndCanBeReadBack) {
  const MapInfo a = NewMap("office");
  const MapInfo b = NewMap("lab-2.west_wing", DescriptorFormat::Sift());
  EXPECT_NE(a.id, b.id);
  EXPECT_EQ(a.config, TestMapConfig("office"));
  EXPECT_EQ(b.config, TestMapConfig("lab-2.west_wing", DescriptorFormat::Sift()));
  EXPECT_GT(a.created_unix_ms, 0);

  auto got = store_->GetMap("lab-2.west_wing");
  ASSERT_TRUE(got.ok()) << got.status().ToString();
  EXPECT_EQ(*got, b);
}

TEST_P(IndexStoreContractTest, ListMapsReturnsEveryMapByName) {
  NewMap("zeta");
  NewMap("alpha");
  NewMap("mid");
  auto maps = store_->ListMaps();
  ASSERT_TRUE(maps.ok());
  ASSERT_EQ(maps->size(), 3u);
  EXPECT_EQ((*maps)[0].config.name, "alpha");
  EXPECT_EQ((*maps)[1].config.name, "mid");
  EXPECT_EQ((*maps)[2].config.name, "zeta");
}

TEST_P(IndexStoreContractTest, CreatingAnExistingMapIsAlreadyExists) {
  const MapInfo first = NewMap("office");
  auto again = store_->CreateMap(TestMapConfig("office", DescriptorFormat::Sift()));
  EXPECT_EQ(again.status().code(), StatusCode::kAlreadyExists);
  // The original is untouched.
  EXPECT_EQ(*store_->GetMap("office"), first);
}

TEST_P(IndexStoreContractTest, InvalidMapConfigsAreInvalidArgument) {
  const std::vector<std::string> bad = {"", "has space", "slash/name", "dollar$",
                                        std::string(129, 'a')};
  for (const std::string& name : bad) {
    EXPECT_EQ(store_->CreateMap(TestMapConfig(name)).status().code(), StatusCode::kInvalidArgument)
        << "'" << name << "'";
  }
  MapConfig no_vocabulary = TestMapConfig("ok");
  no_vocabulary.vocabulary_checksum = 0;
  EXPECT_EQ(store_->CreateMap(no_vocabulary).status().code(), StatusCode::kInvalidArgument);
  EXPECT_TRUE(store_->ListMaps()->empty());
  // 128 characters is the longest valid name.
  EXPECT_TRUE(store_->CreateMap(TestMapConfig(std::string(128, 'a'))).ok());
}

TEST_P(IndexStoreContractTest, UnknownMapNamesAreNotFound) {
  EXPECT_EQ(store_->GetMap("nowhere").status().code(), StatusCode::kNotFound);
  EXPECT_EQ(store_->DeleteMap("nowhere").code(), StatusCode::kNotFound);
}

TEST_P(IndexStoreContractTest, DeletedMapIsGoneAndItsIdIsNeverReused) {
  const MapInfo a = NewMap("a");
  const MapInfo b = NewMap("b");
  ASSERT_TRUE(store_->DeleteMap("b").ok());
  EXPECT_EQ(store_->GetMap("b").status().code(), StatusCode::kNotFound);
  EXPECT_EQ(store_->DeleteMap("b").code(), StatusCode::kNotFound);
  EXPECT_EQ(store_->ListMaps()->size(), 1u);

  const MapInfo b2 = NewMap("b");
  const MapInfo c = NewMap("c");
  for (MapId old : {a.id, b.id}) {
    EXPECT_NE(b2.id, old);
    EXPECT_NE(c.id, old);
  }
  EXPECT_NE(b2.id, c.id);
}

// --- Entries ---

TEST_P(IndexStoreContractTest, AllPartsRoundTripExactlyForBinaryAndFloatDescriptors) {
  for (const DescriptorFormat format : {DescriptorFormat::Orb(), DescriptorFormat::Sift()}) {
    SCOPED_TRACE(format.ToString());
    const MapInfo map = NewMap("map-" + format.ToString(), format);
    for (EntryId id = 0; id < 5; ++id) {
      const EntryRecord entry = MakeTestEntry(id, 7, format, 300);
      ASSERT_TRUE(store_->CommitEntry(map.id, entry).ok());
    }
    for (EntryId id = 0; id < 5; ++id) {
      const EntryRecord expected = MakeTestEntry(id, 7, format, 300);
      EntryRecord got;
      const Status s = store_->ReadEntry(map.id, id, kEntryAllParts, &got);
      ASSERT_TRUE(s.ok()) << s.ToString();
      EXPECT_EQ(EntryDifference(got, expected), "");
      EXPECT_EQ(got.descriptors.type(), format.cv_type());
      EXPECT_EQ(got.descriptors.cols, format.cols());
    }
  }
}

TEST_P(IndexStoreContractTest, EachPartCanBeReadAlone) {
  const MapInfo map = NewMap("office");
  const EntryRecord entry = MakeTestEntry(3, 1);
  ASSERT_TRUE(store_->CommitEntry(map.id, entry).ok());
  for (uint32_t part : {kEntryMetadata, kEntryBow, kEntryDirect, kEntryFeatures}) {
    SCOPED_TRACE(part);
    EntryRecord got;
    ASSERT_TRUE(store_->ReadEntry(map.id, 3, part, &got).ok());
    EXPECT_EQ(EntryDifference(got, entry, part), "");
    // The parts not asked for are left empty.
    EntryRecord empty;
    empty.id = 3;
    EXPECT_EQ(EntryDifference(got, empty, kEntryAllParts & ~part), "");
  }
}

TEST_P(IndexStoreContractTest, MetadataKeepsBinaryUserDataAndSpecialValues) {
  const MapInfo map = NewMap("office");
  EntryRecord entry = MakeTestEntry(0);
  entry.metadata.user_data = std::string("\0\x01\xff\x80zero\0end", 11);
  entry.metadata.user_data += std::string(64 * 1024 - 11, '\xfe');
  entry.metadata.timestamp = -1.0 / 3.0;
  entry.metadata.num_features = UINT32_MAX;
  ASSERT_TRUE(store_->CommitEntry(map.id, entry).ok());
  EntryRecord got;
  ASSERT_TRUE(store_->ReadEntry(map.id, 0, kEntryMetadata, &got).ok());
  EXPECT_EQ(got.metadata, entry.metadata);
  EXPECT_EQ(got.metadata.user_data.size(), 64u * 1024u);
}

TEST_P(IndexStoreContractTest, AnEntryWithoutFeaturesRoundTrips) {
  const MapInfo map = NewMap("office");
  EntryRecord entry;
  entry.id = 0;
  ASSERT_TRUE(store_->CommitEntry(map.id, entry).ok());
  EntryRecord got;
  ASSERT_TRUE(store_->ReadEntry(map.id, 0, kEntryAllParts, &got).ok());
  EXPECT_EQ(EntryDifference(got, entry), "");
  EXPECT_TRUE(got.descriptors.empty());
  EXPECT_TRUE(got.keypoints.empty());
}

// A place frame with depth or stereo keeps a 3D point per keypoint, NaN where the keypoint had no
// depth (core/geometry/frame_points.h); the points come back bit for bit.
TEST_P(IndexStoreContractTest, APlaceFramesPointsRoundTripWithTheMissingOnes) {
  const MapInfo map = NewMap("office");
  EntryRecord entry = MakeTestEntry(0, 3, DescriptorFormat::Orb(), 50);
  ASSERT_FALSE(entry.keypoints.empty());
  const float nan = std::numeric_limits<float>::quiet_NaN();
  entry.points.clear();
  for (size_t i = 0; i < entry.keypoints.size(); ++i) {
    entry.points.push_back(i % 3 == 0
                               ? cv::Point3f(nan, nan, nan)
                               : cv::Point3f(0.01f * float(i), -0.5f, 1.0f + 0.1f * float(i)));
  }
  ASSERT_TRUE(store_->CommitEntry(map.id, entry).ok());
  EntryRecord got;
  ASSERT_TRUE(store_->ReadEntry(map.id, 0, kEntryFeatures, &got).ok());
  ASSERT_EQ(got.points.size(), entry.points.size());
  EXPECT_EQ(std::memcmp(got.points.data(), entry.points.data(),
                        entry.points.size() * sizeof(cv::Point3f)),
            0);
  EXPECT_TRUE(std::isnan(got.points[0].z));
}

TEST_P(IndexStoreContractTest, CommittingATakenIdIsAlreadyExistsAndKeepsTheOriginal) {
  const MapInfo map = NewMap("office");
  ASSERT_TRUE(store_->CommitEntry(map.id, MakeTestEntry(4, 1)).ok());
  EXPECT_EQ(store_->CommitEntry(map.id, MakeTestEntry(4, 2)).code(), StatusCode::kAlreadyExists);
  EntryRecord got;
  ASSERT_TRUE(store_->ReadEntry(map.id, 4, kEntryAllParts, &got).ok());
  EXPECT_EQ(EntryDifference(got, MakeTestEntry(4, 1)), "");
}

TEST_P(IndexStoreContractTest, AnEntryWithoutIdIsInvalidArgument) {
  const MapInfo map = NewMap("office");
  EntryRecord entry = MakeTestEntry(0);
  entry.id = kInvalidEntryId;
  EXPECT_EQ(store_->CommitEntry(map.id, entry).code(), StatusCode::kInvalidArgument);
  EXPECT_TRUE(ScanAll(map.id).empty());
}

TEST_P(IndexStoreContractTest, RemovedEntryIsNotFound) {
  const MapInfo map = NewMap("office");
  for (EntryId id = 0; id < 3; ++id)
    ASSERT_TRUE(store_->CommitEntry(map.id, MakeTestEntry(id)).ok());
  ASSERT_TRUE(store_->RemoveEntry(map.id, 1).ok());
  EntryRecord got;
  EXPECT_EQ(store_->ReadEntry(map.id, 1, kEntryAllParts, &got).code(), StatusCode::kNotFound);
  EXPECT_EQ(store_->ReadEntry(map.id, 1, kEntryBow, &got).code(), StatusCode::kNotFound);
  EXPECT_EQ(store_->RemoveEntry(map.id, 1).code(), StatusCode::kNotFound);
  EXPECT_EQ(store_->RemoveEntry(map.id, 99).code(), StatusCode::kNotFound);
  EXPECT_EQ(store_->ReadEntry(map.id, 99, kEntryMetadata, &got).code(), StatusCode::kNotFound);
  const std::vector<EntryRecord> left = ScanAll(map.id);
  ASSERT_EQ(left.size(), 2u);
  EXPECT_EQ(left[0].id, 0u);
  EXPECT_EQ(left[1].id, 2u);
}

TEST_P(IndexStoreContractTest, ScanVisitsEntriesInIdOrderWithOnlyTheRequestedParts) {
  const MapInfo map = NewMap("office");
  // Ids whose little-endian bytes sort differently from their values.
  const std::vector<EntryId> ids = {300, 2, 0x01000000, 256, 1, 65536, 0xfffffffe};
  for (EntryId id : ids) ASSERT_TRUE(store_->CommitEntry(map.id, MakeTestEntry(id)).ok());
  std::vector<EntryId> sorted = ids;
  std::sort(sorted.begin(), sorted.end());

  for (uint32_t parts : {uint32_t(kEntryAllParts), uint32_t(kEntryMetadata), uint32_t(kEntryBow),
                         uint32_t(kEntryDirect | kEntryFeatures), uint32_t(0)}) {
    SCOPED_TRACE(parts);
    const std::vector<EntryRecord> seen = ScanAll(map.id, parts);
    ASSERT_EQ(seen.size(), sorted.size());
    for (size_t i = 0; i < seen.size(); ++i) {
      EXPECT_EQ(seen[i].id, sorted[i]);
      EXPECT_EQ(EntryDifference(seen[i], MakeTestEntry(sorted[i]), parts), "");
      EntryRecord empty;
      empty.id = sorted[i];
      EXPECT_EQ(EntryDifference(seen[i], empty, kEntryAllParts & ~parts), "");
    }
  }
}

TEST_P(IndexStoreContractTest, ScanStopsAtTheFirstVisitorError) {
  const MapInfo map = NewMap("office");
  for (EntryId id = 0; id < 5; ++id)
    ASSERT_TRUE(store_->CommitEntry(map.id, MakeTestEntry(id)).ok());
  int visits = 0;
  const Status s = store_->ScanEntries(map.id, 0, kEntryMetadata, [&](EntryRecord& e) {
    ++visits;
    return e.id == 2 ? Status::Internal("stop here") : Status::Ok();
  });
  EXPECT_EQ(s.code(), StatusCode::kInternal);
  EXPECT_EQ(s.message(), "stop here");
  EXPECT_EQ(visits, 3);
}

TEST_P(IndexStoreContractTest, ScanVisitorMayCallTheStore) {
  const MapInfo map = NewMap("office");
  for (EntryId id = 0; id < 3; ++id)
    ASSERT_TRUE(store_->CommitEntry(map.id, MakeTestEntry(id)).ok());
  const Status s = store_->ScanEntries(map.id, 0, kEntryMetadata, [&](EntryRecord& e) {
    EntryRecord again;
    RECOG_RETURN_IF_ERROR(store_->ReadEntry(map.id, e.id, kEntryBow, &again));
    return store_->NextEntryId(map.id).status();
  });
  EXPECT_TRUE(s.ok()) << s.ToString();
}

TEST_P(IndexStoreContractTest, ScanOfAnEmptyMapVisitsNothingAndMapsDoNotMix) {
  const MapInfo a = NewMap("a");
  const MapInfo b = NewMap("b");
  EXPECT_TRUE(ScanAll(a.id).empty());
  for (EntryId id = 0; id < 3; ++id) ASSERT_TRUE(store_->CommitEntry(b.id, MakeTestEntry(id)).ok());
  EXPECT_TRUE(ScanAll(a.id).empty());
  EXPECT_EQ(ScanAll(b.id).size(), 3u);
  EntryRecord got;
  EXPECT_EQ(store_->ReadEntry(a.id, 0, kEntryAllParts, &got).code(), StatusCode::kNotFound);
}

TEST_P(IndexStoreContractTest, NextEntryIdFollowsTheLargestCommittedId) {
  const MapInfo map = NewMap("office");
  EXPECT_EQ(*store_->NextEntryId(map.id), 0u);
  ASSERT_TRUE(store_->CommitEntry(map.id, MakeTestEntry(0)).ok());
  EXPECT_EQ(*store_->NextEntryId(map.id), 1u);
  ASSERT_TRUE(store_->CommitEntry(map.id, MakeTestEntry(7)).ok());
  EXPECT_EQ(*store_->NextEntryId(map.id), 8u);
  ASSERT_TRUE(store_->CommitEntry(map.id, MakeTestEntry(3)).ok());  // a gap filled later
  EXPECT_EQ(*store_->NextEntryId(map.id), 8u);
  EXPECT_EQ(store_->CommitEntry(map.id, MakeTestEntry(7)).code(), StatusCode::kAlreadyExists);
  EXPECT_EQ(*store_->NextEntryId(map.id), 8u);
}

TEST_P(IndexStoreContractTest, NextEntryIdSurvivesRemovalOfTheLastEntry) {
  const MapInfo map = NewMap("office");
  for (EntryId id = 0; id < 4; ++id)
    ASSERT_TRUE(store_->CommitEntry(map.id, MakeTestEntry(id)).ok());
  ASSERT_TRUE(store_->RemoveEntry(map.id, 3).ok());
  ASSERT_TRUE(store_->RemoveEntry(map.id, 2).ok());
  EXPECT_EQ(*store_->NextEntryId(map.id), 4u);
  for (EntryId id = 0; id < 2; ++id) ASSERT_TRUE(store_->RemoveEntry(map.id, id).ok());
  EXPECT_EQ(*store_->NextEntryId(map.id), 4u);
}

TEST_P(IndexStoreContractTest, DeleteMapRemovesAllItsEntriesAndOnlyThem) {
  const MapInfo doomed = NewMap("doomed");
  const MapInfo kept = NewMap("kept");
  for (EntryId id = 0; id < 10; ++id) {
    ASSERT_TRUE(store_->CommitEntry(doomed.id, MakeTestEntry(id, 1)).ok());
    ASSERT_TRUE(store_->CommitEntry(kept.id, MakeTestEntry(id, 2)).ok());
  }
  ASSERT_TRUE(store_->DeleteMap("doomed").ok());

  const MapInfo again = NewMap("doomed");
  EXPECT_NE(again.id, doomed.id);
  EXPECT_TRUE(ScanAll(again.id).empty());
  EXPECT_EQ(*store_->NextEntryId(again.id), 0u);
  EntryRecord got;
  EXPECT_EQ(store_->ReadEntry(again.id, 0, kEntryAllParts, &got).code(), StatusCode::kNotFound);

  const std::vector<EntryRecord> left = ScanAll(kept.id);
  ASSERT_EQ(left.size(), 10u);
  for (const EntryRecord& e : left) EXPECT_EQ(EntryDifference(e, MakeTestEntry(e.id, 2)), "");
}

TEST_P(IndexStoreContractTest, UnknownOrDeletedMapIsNotFoundEverywhere) {
  const MapInfo deleted = NewMap("deleted");
  ASSERT_TRUE(store_->CommitEntry(deleted.id, MakeTestEntry(0)).ok());
  ASSERT_TRUE(store_->DeleteMap("deleted").ok());
  for (MapId map : {deleted.id, MapId(987654)}) {
    SCOPED_TRACE(map);
    EntryRecord got;
    EXPECT_EQ(store_->CommitEntry(map, MakeTestEntry(1)).code(), StatusCode::kNotFound);
    EXPECT_EQ(store_->RemoveEntry(map, 0).code(), StatusCode::kNotFound);
    EXPECT_EQ(store_->ReadEntry(map, 0, kEntryAllParts, &got).code(), StatusCode::kNotFound);
    EXPECT_EQ(store_->ScanEntries(map, 0, kEntryAllParts, [](EntryRecord&) { return Status::Ok(); })
                  .code(),
              StatusCode::kNotFound);
    EXPECT_EQ(store_->NextEntryId(map).status().code(), StatusCode::kNotFound);
  }
}

TEST_P(IndexStoreContractTest, ConcurrentCommitsFromFourThreadsToTwoMapsAllLand) {
  const MapInfo maps[2] = {NewMap("left"), NewMap("right")};
  constexpr EntryId kPerThread = 25;
  std::atomic<int> failures{0};
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t) {
    threads.emplace_back([&, t] {
      // Threads t and t + 2 share a map: one commits the even ids, the other the odd ones.
      const MapId map = maps[t % 2].id;
      for (EntryId k = 0; k < kPerThread; ++k) {
        const EntryId id = 2 * k + EntryId(t / 2);
        if (!store_->CommitEntry(map, MakeTestEntry(id, map)).ok()) ++failures;
        EntryRecord got;
        if (!store_->ReadEntry(map, id, kEntryMetadata, &got).ok()) ++failures;
      }
    });
  }
  for (std::thread& t : threads) t.join();
  EXPECT_EQ(failures.load(), 0);
  for (const MapInfo& map : maps) {
    const std::vector<EntryRecord> all = ScanAll(map.id);
    ASSERT_EQ(all.size(), 2 * kPerThread);
    for (size_t i = 0; i < all.size(); ++i) {
      EXPECT_EQ(all[i].id, EntryId(i));
      EXPECT_EQ(EntryDifference(all[i], MakeTestEntry(EntryId(i), map.id)), "");
    }
    EXPECT_EQ(*store_->NextEntryId(map.id), 2 * kPerThread);
  }
}

// --- Blobs ---

TEST_P(IndexStoreContractTest, ABlobRoundTripsExactlyAndPutOverwritesIt) {
  const std::string binary = std::string("\0\x01\xff\x80model\0", 10) + std::string(1000, '\xfe');
  ASSERT_TRUE(store_->PutBlob("model/box/1", binary).ok());
  auto got = store_->GetBlob("model/box/1");
  ASSERT_TRUE(got.ok()) << got.status().ToString();
  EXPECT_EQ(*got, binary);

  ASSERT_TRUE(store_->PutBlob("model/box/1", "shorter").ok());
  EXPECT_EQ(*store_->GetBlob("model/box/1"), "shorter");
  ASSERT_TRUE(store_->PutBlob("model/box/1", "").ok());  // an empty value is a value
  got = store_->GetBlob("model/box/1");
  ASSERT_TRUE(got.ok()) << got.status().ToString();
  EXPECT_EQ(*got, "");
}

TEST_P(IndexStoreContractTest, AModelSizedBlobRoundTrips) {
  std::string value(5 << 20, '\0');
  std::mt19937 rng(11);
  for (char& c : value) c = char(rng());
  ASSERT_TRUE(store_->PutBlob("big", value).ok());
  auto got = store_->GetBlob("big");
  ASSERT_TRUE(got.ok()) << got.status().ToString();
  EXPECT_TRUE(*got == value);
}

TEST_P(IndexStoreContractTest, DeletedOrUnknownBlobsAreNotFound) {
  ASSERT_TRUE(store_->PutBlob("a", "1").ok());
  ASSERT_TRUE(store_->PutBlob("b", "2").ok());
  ASSERT_TRUE(store_->DeleteBlob("a").ok());
  EXPECT_EQ(store_->GetBlob("a").status().code(), StatusCode::kNotFound);
  EXPECT_EQ(store_->DeleteBlob("a").code(), StatusCode::kNotFound);
  EXPECT_EQ(store_->GetBlob("never").status().code(), StatusCode::kNotFound);
  EXPECT_EQ(store_->DeleteBlob("never").code(), StatusCode::kNotFound);
  EXPECT_EQ(*store_->ListBlobKeys(""), std::vector<std::string>{"b"});
  // A deleted key can be written again.
  ASSERT_TRUE(store_->PutBlob("a", "3").ok());
  EXPECT_EQ(*store_->GetBlob("a"), "3");
}

TEST_P(IndexStoreContractTest, ListBlobKeysReturnsTheKeysWithThePrefixInByteOrder) {
  // "\x80" sorts after every ASCII byte: the order is that of unsigned bytes.
  const std::vector<std::string> keys = {
      "model/b/1", "other",  std::string("model/\x80", 7), "model/a/2", "model",
      "model/a/1", "modelx", std::string("\0zero", 5)};
  for (const std::string& key : keys) ASSERT_TRUE(store_->PutBlob(key, "v:" + key).ok());

  auto listed = store_->ListBlobKeys("model/");
  ASSERT_TRUE(listed.ok()) << listed.status().ToString();
  EXPECT_EQ(*listed, (std::vector<std::string>{"model/a/1", "model/a/2", "model/b/1",
                                               std::string("model/\x80", 7)}));
  EXPECT_EQ(*store_->ListBlobKeys("model/a/"),
            (std::vector<std::string>{"model/a/1", "model/a/2"}));
  EXPECT_TRUE(store_->ListBlobKeys("nothing")->empty());
  EXPECT_TRUE(store_->ListBlobKeys("model/a/1/")->empty());
  std::vector<std::string> all = keys;
  std::sort(all.begin(), all.end());
  EXPECT_EQ(*store_->ListBlobKeys(""), all);
}

TEST_P(IndexStoreContractTest, BadBlobKeysAndOversizedValuesAreInvalidArgumentAndStoreNothing) {
  const std::string too_long(IndexStore::kMaxBlobKeyBytes + 1, 'k');
  for (const std::string& key : {std::string(), too_long}) {
    SCOPED_TRACE(key.size());
    EXPECT_EQ(store_->PutBlob(key, "value").code(), StatusCode::kInvalidArgument);
    EXPECT_EQ(store_->GetBlob(key).status().code(), StatusCode::kInvalidArgument);
    EXPECT_EQ(store_->DeleteBlob(key).code(), StatusCode::kInvalidArgument);
  }
  const std::string too_big(IndexStore::kMaxBlobBytes + 1, 'x');
  EXPECT_EQ(store_->PutBlob("big", too_big).code(), StatusCode::kInvalidArgument);
  EXPECT_TRUE(store_->ListBlobKeys("")->empty());
  // The longest key is fine, and so is any byte in it.
  std::string longest(IndexStore::kMaxBlobKeyBytes, 'k');
  longest[0] = '\0';
  longest[1] = '/';
  ASSERT_TRUE(store_->PutBlob(longest, "value").ok());
  EXPECT_EQ(*store_->GetBlob(longest), "value");
}

TEST_P(IndexStoreContractTest, BlobsAndMapsAreIndependent) {
  const MapInfo map = NewMap("office");
  ASSERT_TRUE(store_->CommitEntry(map.id, MakeTestEntry(0)).ok());
  ASSERT_TRUE(store_->PutBlob("office", "a blob named like the map").ok());
  ASSERT_TRUE(store_->DeleteMap("office").ok());
  EXPECT_EQ(*store_->GetBlob("office"), "a blob named like the map");
  ASSERT_TRUE(store_->DeleteBlob("office").ok());
  const MapInfo again = NewMap("office");
  EXPECT_TRUE(ScanAll(again.id).empty());
  EXPECT_EQ(store_->ListMaps()->size(), 1u);
}

TEST_P(IndexStoreContractTest, ConcurrentBlobWritesFromFourThreadsAllLand) {
  constexpr int kPerThread = 20;
  std::atomic<int> failures{0};
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t) {
    threads.emplace_back([&, t] {
      for (int i = 0; i < kPerThread; ++i) {
        std::string key = "t";  // not "t" + std::to_string(t): GCC 12 -Wrestrict false positive
        key += std::to_string(t) + "/" + std::to_string(i);
        if (!store_->PutBlob(key, key + std::string(size_t(1000 * i), 'v')).ok()) ++failures;
        // Every other blob is deleted again.
        if (i % 2 == 1 && !store_->DeleteBlob(key).ok()) ++failures;
      }
    });
  }
  for (std::thread& t : threads) t.join();
  EXPECT_EQ(failures.load(), 0);
  const std::vector<std::string> keys = *store_->ListBlobKeys("");
  EXPECT_EQ(keys.size(), size_t(4 * kPerThread / 2));
  for (const std::string& key : keys) {
    const size_t i = std::stoul(key.substr(key.find('/') + 1));
    EXPECT_EQ(i % 2, 0u) << key;
    EXPECT_EQ(*store_->GetBlob(key), key + std::string(1000 * i, 'v'));
  }
}

TEST_P(IndexStoreContractTest, FlushSucceeds) {
  const MapInfo map = NewMap("office");
  ASSERT_TRUE(store_->CommitEntry(map.id, MakeTestEntry(0)).ok());
  EXPECT_TRUE(store_->Flush().ok());
}

// --- Index snapshots ---

// Writes `bytes` as the snapshot of `map` covering the ids below `covers`; returns Commit's status.
Status PutSnapshot(IndexStore& store, MapId map, EntryId covers, const std::string& bytes) {
  RECOG_ASSIGN_OR_RETURN(std::unique_ptr<IndexStore::SnapshotWriter> writer,
                         store.WriteSnapshot(map, covers));
  // In two pieces, as a writer appends.
  RECOG_RETURN_IF_ERROR(writer->Append(std::string_view(bytes).substr(0, bytes.size() / 2)));
  RECOG_RETURN_IF_ERROR(writer->Append(std::string_view(bytes).substr(bytes.size() / 2)));
  return writer->Commit();
}

// The snapshot of `map` as (covers, bytes); NOT_FOUND when it has none.
StatusOr<std::pair<EntryId, std::string>> GetSnapshot(IndexStore& store, MapId map) {
  RECOG_ASSIGN_OR_RETURN(std::unique_ptr<IndexStore::SnapshotReader> reader,
                         store.ReadSnapshot(map));
  std::string bytes(reader->size(), '\0');
  RECOG_RETURN_IF_ERROR(reader->Read(bytes.data(), bytes.size()));
  char past_the_end = 0;
  if (reader->Read(&past_the_end, 1).code() != StatusCode::kDataLoss) {
    return Status::Internal("the reader read past the snapshot's end");
  }
  return std::make_pair(reader->covers(), bytes);
}

TEST_P(IndexStoreContractTest, ScanEntriesStartsAtTheGivenId) {
  const MapInfo map = NewMap("office");
  for (EntryId id : {0u, 2u, 5u, 9u})
    ASSERT_TRUE(store_->CommitEntry(map.id, MakeTestEntry(id)).ok());
  for (const auto& [first, expected] : std::vector<std::pair<EntryId, std::vector<EntryId>>>{
           {0, {0, 2, 5, 9}}, {2, {2, 5, 9}}, {3, {5, 9}}, {9, {9}}, {10, {}}}) {
    std::vector<EntryId> ids;
    ASSERT_TRUE(store_
                    ->ScanEntries(map.id, first, kEntryMetadata,
                                  [&](EntryRecord& e) {
                                    ids.push_back(e.id);
                                    return Status::Ok();
                                  })
                    .ok());
    EXPECT_EQ(ids, expected) << "from " << first;
  }
}

TEST_P(IndexStoreContractTest, ASnapshotIsReadBackWhole) {
  const MapInfo map = NewMap("office");
  EXPECT_EQ(store_->ReadSnapshot(map.id).status().code(), StatusCode::kNotFound);
  for (EntryId id = 0; id < 3; ++id)
    ASSERT_TRUE(store_->CommitEntry(map.id, MakeTestEntry(id)).ok());
  // Larger than a reader's buffer, with every byte value.
  std::string bytes(3 << 20, '\0');
  for (size_t i = 0; i < bytes.size(); ++i) bytes[i] = char(i * 7 + i / 4096);
  ASSERT_TRUE(PutSnapshot(*store_, map.id, 3, bytes).ok());
  auto got = GetSnapshot(*store_, map.id);
  ASSERT_TRUE(got.ok()) << got.status().ToString();
  EXPECT_EQ(got->first, 3u);
  EXPECT_TRUE(got->second == bytes);

  // A second one replaces it; an abandoned writer changes nothing.
  ASSERT_TRUE(PutSnapshot(*store_, map.id, 2, "smaller").ok());
  {
    auto abandoned = store_->WriteSnapshot(map.id, 3);
    ASSERT_TRUE(abandoned.ok());
    ASSERT_TRUE((*abandoned)->Append("never committed").ok());
  }
  got = GetSnapshot(*store_, map.id);
  ASSERT_TRUE(got.ok()) << got.status().ToString();
  EXPECT_EQ(got->first, 2u);
  EXPECT_EQ(got->second, "smaller");
}

TEST_P(IndexStoreContractTest, EntriesAddedAfterASnapshotKeepIt) {
  const MapInfo map = NewMap("office");
  ASSERT_TRUE(store_->CommitEntry(map.id, MakeTestEntry(0)).ok());
  ASSERT_TRUE(PutSnapshot(*store_, map.id, 1, "index").ok());
  ASSERT_TRUE(store_->CommitEntry(map.id, MakeTestEntry(1)).ok());
  ASSERT_TRUE(store_->CommitEntry(map.id, MakeTestEntry(7)).ok());
  auto got = GetSnapshot(*store_, map.id);
  ASSERT_TRUE(got.ok()) << got.status().ToString();
  EXPECT_EQ(got->first, 1u);
}

TEST_P(IndexStoreContractTest, WritesThatMakeASnapshotStaleDropIt) {
  const std::vector<std::pair<std::string, std::function<Status(IndexStore&, MapId)>>> writes = {
      {"removing an entry", [](IndexStore& s, MapId m) { return s.RemoveEntry(m, 4); }},
      {"committing an id below the bound",
       [](IndexStore& s, MapId m) { return s.CommitEntry(m, MakeTestEntry(1)); }},
      {"dropping it", [](IndexStore& s, MapId m) { return s.DropSnapshot(m); }},
  };
  for (const auto& [what, write] : writes) {
    SCOPED_TRACE(what);
    const MapInfo map = NewMap("map-" + std::to_string(&write - &writes[0].second));
    for (EntryId id : {0u, 4u, 5u})
      ASSERT_TRUE(store_->CommitEntry(map.id, MakeTestEntry(id)).ok());
    ASSERT_TRUE(PutSnapshot(*store_, map.id, 6, "index").ok());
    ASSERT_TRUE(write(*store_, map.id).ok());
    EXPECT_EQ(store_->ReadSnapshot(map.id).status().code(), StatusCode::kNotFound);
    // A write that fails drops nothing more, and a new snapshot can be written.
    ASSERT_TRUE(PutSnapshot(*store_, map.id, 6, "again").ok());
    EXPECT_EQ(store_->RemoveEntry(map.id, 99).code(), StatusCode::kNotFound);
    EXPECT_TRUE(GetSnapshot(*store_, map.id).ok());
  }
}

TEST_P(IndexStoreContractTest, ASnapshotWrittenAcrossAStaleningWriteIsRefused) {
  const MapInfo map = NewMap("office");
  for (EntryId id = 0; id < 3; ++id)
    ASSERT_TRUE(store_->CommitEntry(map.id, MakeTestEntry(id)).ok());
  ASSERT_TRUE(PutSnapshot(*store_, map.id, 3, "old").ok());
  auto writer = store_->WriteSnapshot(map.id, 3);
  ASSERT_TRUE(writer.ok());
  ASSERT_TRUE((*writer)->Append("new, but entry 1 is removed meanwhile").ok());
  ASSERT_TRUE(store_->RemoveEntry(map.id, 1).ok());
  EXPECT_EQ((*writer)->Commit().code(), StatusCode::kFailedPrecondition);
  EXPECT_EQ(store_->ReadSnapshot(map.id).status().code(), StatusCode::kNotFound);
}

TEST_P(IndexStoreContractTest, DeletingAMapDropsItsSnapshot) {
  MapInfo map = NewMap("office");
  ASSERT_TRUE(store_->CommitEntry(map.id, MakeTestEntry(0)).ok());
  ASSERT_TRUE(PutSnapshot(*store_, map.id, 1, "index").ok());
  ASSERT_TRUE(store_->DeleteMap("office").ok());
  EXPECT_EQ(store_->ReadSnapshot(map.id).status().code(), StatusCode::kNotFound);
  map = NewMap("office");
  EXPECT_EQ(store_->ReadSnapshot(map.id).status().code(), StatusCode::kNotFound);
}

TEST_P(IndexStoreContractTest, SnapshotsOfUnknownMapsOrBeyondTheEntriesAreRefused) {
  const MapInfo map = NewMap("office");
  ASSERT_TRUE(store_->CommitEntry(map.id, MakeTestEntry(0)).ok());
  EXPECT_EQ(store_->WriteSnapshot(map.id, 2).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(store_->WriteSnapshot(map.id + 100, 0).status().code(), StatusCode::kNotFound);
  EXPECT_EQ(store_->ReadSnapshot(map.id + 100).status().code(), StatusCode::kNotFound);
  EXPECT_EQ(store_->DropSnapshot(map.id + 100).code(), StatusCode::kNotFound);
}

INSTANTIATE_TEST_SUITE_P(AllStores, IndexStoreContractTest, ::testing::ValuesIn(kFactories),
                         [](const ::testing::TestParamInfo<StoreFactory>& info) {
                           return info.param.name;
                         });

}  // namespace
}  // namespace recog
