// The object database on RocksDB: models, with their 3D points, survive closing and reopening
// the store, and a replaced or removed model stays replaced or removed.
#include <memory>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include "core/object/builder/model_builder.h"
#include "core/object/recognition/object_database.h"
#include "storage/rocksdb_index_store.h"
#include "storage/store_test_util.h"
#include "tests/testing/data_paths.h"
#include "tests/testing/vocabularies.h"

namespace recog {
namespace {

TEST(ObjectDatabaseRocksDbTest, ModelsSurviveARestart) {
  const std::shared_ptr<const Vocabulary> vocabulary = testing::BundledObjectVocabulary();
  ModelBuilder builder(vocabulary);
  const auto image = [](const std::string& name) {
    return cv::imread(testing::ProjectTestData(name), cv::IMREAD_GRAYSCALE);
  };
  auto poster =
      builder.FromFaceImages("poster", {{BoxSide::kFront, image("corridor/1.jpg")}}, 0.64, 0.48);
  auto other =
      builder.FromFaceImages("other", {{BoxSide::kFront, image("corridor/41.jpg")}}, 0.3, 0.2);
  ASSERT_TRUE(poster.ok() && other.ok());

  testing::TempDir dir("objects");
  {
    auto store = OpenRocksDbIndexStore(dir.Sub("store"), RocksDbStoreOptions());
    ASSERT_TRUE(store.ok()) << store.status().ToString();
    auto database = ObjectDatabase::Open(store->get(), vocabulary);
    ASSERT_TRUE(database.ok()) << database.status().ToString();
    ASSERT_TRUE((*database)->Put(*poster).ok());
    ASSERT_TRUE((*database)->Put(*poster).ok());  // version 2
    ASSERT_TRUE((*database)->Put(*other).ok());
    ASSERT_TRUE((*database)->Remove("other").ok());
  }
  auto store = OpenRocksDbIndexStore(dir.Sub("store"), RocksDbStoreOptions());
  ASSERT_TRUE(store.ok()) << store.status().ToString();
  auto database = ObjectDatabase::Open(store->get(), vocabulary);
  ASSERT_TRUE(database.ok()) << database.status().ToString();
  const std::vector<ObjectMetadata> list = (*database)->List();
  ASSERT_EQ(list.size(), 1u);
  EXPECT_EQ(list[0].name, "poster");
  EXPECT_EQ(list[0].version, 2u);
  auto stored = (*database)->Get("poster");
  ASSERT_TRUE(stored.ok());
  ASSERT_EQ(stored->num_features(), poster->num_features());
  for (size_t i = 0; i < stored->num_features(); ++i) {
    ASSERT_EQ(stored->points[stored->point_of_feature[i]],
              poster->points[poster->point_of_feature[i]]);
  }
  EXPECT_EQ((*database)->Get("other").status().code(), StatusCode::kNotFound);
}

}  // namespace
}  // namespace recog
