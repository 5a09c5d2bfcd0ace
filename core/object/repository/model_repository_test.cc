// ModelRepository: versioned uploads over an ObjectDatabase, downloads of every version, listing
// with filters and pages, removal, change notifications (with the versions already stored),
// copies of another repository's versions (replicas), and the reconciliation of an interrupted
// upload or removal (or an object put into the database directly) when the repository opens.
#include "core/object/repository/model_repository.h"

#include <atomic>
#include <functional>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "core/index/memory_index_store.h"
#include "core/object/formats/model_file.h"
#include "tests/testing/synthetic.h"
#include "tests/testing/vocabularies.h"

namespace recog {
namespace {

// Stands in for SHA-256: any deterministic function of the bytes will do.
std::string FakeSha256(std::string_view bytes) {
  return "fake:" + std::to_string(bytes.size()) + ":" +
         std::to_string(std::hash<std::string_view>()(bytes));
}

// A small valid 3D model: 40 points, two random ORB descriptors each; `seed` makes it unique.
ObjectModel TestModel(const std::string& name, uint64_t seed,
                      const std::string& object_class = "toy") {
  ObjectModel model;
  model.metadata.name = name;
  model.metadata.object_class = object_class;
  model.metadata.type = ObjectType::k3D;
  model.metadata.dimensions = {0.1, 0.2, 0.3};
  model.metadata.source = "test:" + std::to_string(seed);
  model.metadata.version = 7;  // whatever the file says, the repository numbers the versions
  for (int i = 0; i < 40; ++i) {
    model.points.emplace_back(0.01f * float(i), 0.02f * float(seed % 7), 0.5f);
    model.point_of_feature.push_back(uint32_t(i));
    model.point_of_feature.push_back(uint32_t(i));
  }
  model.descriptors = testing::RandomDescriptors(80, seed);
  return model;
}

std::string File(const ObjectModel& model) {
  auto bytes = EncodeObjectModel(model);
  EXPECT_TRUE(bytes.ok()) << bytes.status().ToString();
  return bytes.ok() ? *bytes : std::string();
}

std::vector<std::string> Names(const std::vector<ModelVersionInfo>& infos) {
  std::vector<std::string> names;
  for (const ModelVersionInfo& info : infos) names.push_back(info.metadata.name);
  return names;
}

std::vector<uint32_t> VersionNumbers(const std::vector<ModelVersionInfo>& infos) {
  std::vector<uint32_t> versions;
  for (const ModelVersionInfo& info : infos) versions.push_back(info.metadata.version);
  return versions;
}

class ModelRepositoryTest : public ::testing::Test {
 protected:
  void SetUp() override { Reopen(); }

  // Opens the object database and the repository (again) over the same store.
  void Reopen() {
    repository_.reset();
    objects_.reset();
    auto objects = ObjectDatabase::Open(&store_, testing::BundledObjectVocabulary());
    ASSERT_TRUE(objects.ok()) << objects.status().ToString();
    objects_ = std::move(*objects);
    auto repository = ModelRepository::Open(&store_, objects_, FakeSha256);
    ASSERT_TRUE(repository.ok()) << repository.status().ToString();
    repository_ = std::move(*repository);
  }

  ModelVersionInfo MustPut(const ObjectModel& model, std::vector<std::string> tags = {},
                           const std::string& name = "") {
    auto info = repository_->Put(File(model), name, std::move(tags));
    EXPECT_TRUE(info.ok()) << info.status().ToString();
    return info.ok() ? *info : ModelVersionInfo();
  }

  std::string StoredFile(const std::string& name, uint32_t version) {
    auto got = repository_->Get(name, version);
    EXPECT_TRUE(got.ok()) << got.status().ToString();
    return got.ok() ? got->second : std::string();
  }

  std::vector<std::string> BlobKeys() { return *store_.ListBlobKeys(""); }

  // Every page of a listing, following the tokens.
  std::vector<ModelPage> AllPages(const ModelFilter& filter, size_t page_size) {
    std::vector<ModelPage> pages;
    std::string token;
    do {
      auto page = repository_->List(filter, page_size, token);
      EXPECT_TRUE(page.ok()) << page.status().ToString();
      if (!page.ok() || pages.size() > 100) break;
      token = page->next_page_token;
      pages.push_back(std::move(*page));
    } while (!token.empty());
    return pages;
  }

  MemoryIndexStore store_;
  std::shared_ptr<ObjectDatabase> objects_;
  std::unique_ptr<ModelRepository> repository_;
};

TEST_F(ModelRepositoryTest, ANewNameBecomesVersionOneAndIsRecognised) {
  const ObjectModel model = TestModel("mug", 1, "cup");
  const ModelVersionInfo info = MustPut(model);
  EXPECT_EQ(info.metadata.name, "mug");
  EXPECT_EQ(info.metadata.version, 1u);
  EXPECT_EQ(info.metadata.object_class, "cup");
  EXPECT_EQ(info.metadata.source, model.metadata.source);
  EXPECT_EQ(info.num_points, 40u);
  EXPECT_EQ(info.num_descriptors, 80u);
  EXPECT_GT(info.created_unix_ms, 0);

  // The stored file is the upload with its final version; size and hash describe it.
  const std::string stored = StoredFile("mug", 1);
  EXPECT_EQ(info.size_bytes, stored.size());
  EXPECT_EQ(info.sha256, FakeSha256(stored));
  auto decoded = DecodeObjectModel(stored, "download");
  ASSERT_TRUE(decoded.ok()) << decoded.status().ToString();
  EXPECT_EQ(decoded->metadata.version, 1u);
  EXPECT_EQ(decoded->metadata.name, "mug");
  EXPECT_EQ(cv::norm(decoded->descriptors, model.descriptors, cv::NORM_HAMMING), 0);

  ASSERT_EQ(objects_->List().size(), 1u);
  EXPECT_EQ(objects_->List()[0], info.metadata);
  EXPECT_EQ(objects_->index().size(), 1u);
}

TEST_F(ModelRepositoryTest, PuttingAgainAddsAVersionAndKeepsTheOldOneDownloadable) {
  const ModelVersionInfo v1 = MustPut(TestModel("mug", 1));
  const std::string v1_file = StoredFile("mug", 1);
  const ModelVersionInfo v2 = MustPut(TestModel("mug", 2));
  EXPECT_EQ(v2.metadata.version, 2u);

  auto latest = repository_->Get("mug", 0);
  ASSERT_TRUE(latest.ok()) << latest.status().ToString();
  EXPECT_EQ(latest->first, v2);
  EXPECT_EQ(DecodeObjectModel(latest->second, "v2")->metadata.source, "test:2");
  auto first = repository_->Get("mug", 1);
  ASSERT_TRUE(first.ok()) << first.status().ToString();
  EXPECT_EQ(first->first, v1);
  EXPECT_EQ(first->second, v1_file);

  EXPECT_EQ(repository_->Versions("mug"), (std::vector<ModelVersionInfo>{v1, v2}));
  // Recognition uses the latest version only.
  ASSERT_EQ(objects_->List().size(), 1u);
  EXPECT_EQ(objects_->List()[0].version, 2u);
  EXPECT_EQ(objects_->List()[0].source, "test:2");

  EXPECT_EQ(repository_->Get("mug", 3).status().code(), StatusCode::kNotFound);
  EXPECT_EQ(repository_->Get("cup", 0).status().code(), StatusCode::kNotFound);
  EXPECT_EQ(repository_->Get("../mug", 1).status().code(), StatusCode::kNotFound);
  EXPECT_TRUE(repository_->Versions("cup").empty());
}

TEST_F(ModelRepositoryTest, ANameGivenAtUploadRenamesTheModel) {
  const ModelVersionInfo info = MustPut(TestModel("upload", 1), {}, "box-7");
  EXPECT_EQ(info.metadata.name, "box-7");
  EXPECT_EQ(DecodeObjectModel(StoredFile("box-7", 0), "download")->metadata.name, "box-7");
  EXPECT_TRUE(repository_->Versions("upload").empty());
  ASSERT_EQ(objects_->List().size(), 1u);
  EXPECT_EQ(objects_->List()[0].name, "box-7");

  EXPECT_EQ(repository_->Put(File(TestModel("upload", 2)), "bad name", {}).status().code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(repository_->Put(File(TestModel("upload", 2)), "a/b", {}).status().code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(BlobKeys().size(), 1u);
}

TEST_F(ModelRepositoryTest, TagsAreKeptSortedWithoutDuplicatesAndBadOnesAreRefused) {
  const ModelVersionInfo info = MustPut(TestModel("mug", 1), {"shelf", "kitchen", "shelf"});
  EXPECT_EQ(info.tags, (std::vector<std::string>{"kitchen", "shelf"}));
  EXPECT_EQ(repository_->Get("mug", 1)->first.tags, info.tags);

  const std::vector<std::vector<std::string>> bad = {{""},
                                                     {std::string(65, 't')},
                                                     {"line\nbreak"},
                                                     std::vector<std::string>(33, "many"),
                                                     {"not \xFF\xFE utf-8"}};
  for (const std::vector<std::string>& tags : bad) {
    EXPECT_EQ(repository_->Put(File(TestModel("other", 2)), "", tags).status().code(),
              StatusCode::kInvalidArgument);
  }
  EXPECT_TRUE(repository_->Versions("other").empty());
  EXPECT_EQ(BlobKeys().size(), 1u);
  // The longest tag and the most tags are fine.
  std::vector<std::string> most;
  for (int i = 0; i < 32; ++i) most.push_back(std::string(62, 'a') + std::to_string(10 + i));
  EXPECT_TRUE(repository_->Put(File(TestModel("other", 2)), "", most).ok());
}

TEST_F(ModelRepositoryTest, ListFiltersTheLatestVersionsByPrefixClassAndTag) {
  MustPut(TestModel("cup-1", 1, "cup"), {"kitchen"});
  MustPut(TestModel("cup-2", 2, "cup"));
  MustPut(TestModel("box-1", 3, "box"), {"kitchen", "heavy"});
  MustPut(TestModel("box-1", 4, "crate"), {"heavy"});  // version 2 is what List shows
  MustPut(TestModel("cupboard", 5, "furniture"));

  auto list = [&](const ModelFilter& filter) {
    auto page = repository_->List(filter, 0, "");
    EXPECT_TRUE(page.ok()) << page.status().ToString();
    EXPECT_EQ(page->next_page_token, "");
    return page.ok() ? Names(page->models) : std::vector<std::string>();
  };
  EXPECT_EQ(list({}), (std::vector<std::string>{"box-1", "cup-1", "cup-2", "cupboard"}));
  EXPECT_EQ(list({"cup-", "", ""}), (std::vector<std::string>{"cup-1", "cup-2"}));
  EXPECT_EQ(list({"cup", "", ""}), (std::vector<std::string>{"cup-1", "cup-2", "cupboard"}));
  EXPECT_EQ(list({"", "cup", ""}), (std::vector<std::string>{"cup-1", "cup-2"}));
  EXPECT_EQ(list({"", "box", ""}), std::vector<std::string>{});
  EXPECT_EQ(list({"", "crate", ""}), std::vector<std::string>{"box-1"});
  EXPECT_EQ(list({"", "", "kitchen"}), std::vector<std::string>{"cup-1"});
  EXPECT_EQ(list({"", "", "heavy"}), std::vector<std::string>{"box-1"});
  EXPECT_EQ(list({"cup", "cup", "kitchen"}), std::vector<std::string>{"cup-1"});
  EXPECT_EQ(list({"zzz", "", ""}), std::vector<std::string>{});

  auto page = repository_->List({"box", "", ""}, 0, "");
  ASSERT_TRUE(page.ok());
  ASSERT_EQ(page->models.size(), 1u);
  EXPECT_EQ(page->models[0], repository_->Versions("box-1")[1]);
}

TEST_F(ModelRepositoryTest, ListPagesThroughEveryModelInNameOrder) {
  std::vector<std::string> all;
  std::vector<std::string> odd;
  for (int i = 0; i < 23; ++i) {
    std::string name = "m";  // not "m" + std::to_string(...): GCC 12 -Wrestrict false positive
    name += std::to_string(100 + i);
    MustPut(TestModel(name, uint64_t(i)),
            i % 2 == 1 ? std::vector<std::string>{"odd"} : std::vector<std::string>{});
    all.push_back(name);
    if (i % 2 == 1) odd.push_back(name);
  }
  for (size_t page_size : {size_t(1), size_t(5), size_t(10), size_t(23), size_t(0)}) {
    SCOPED_TRACE(page_size);
    const std::vector<ModelPage> pages = AllPages({}, page_size);
    const size_t size = page_size == 0 ? ModelRepository::kDefaultPageSize : page_size;
    EXPECT_EQ(pages.size(), (all.size() + size - 1) / size);
    std::vector<std::string> seen;
    for (const ModelPage& page : pages) {
      EXPECT_LE(page.models.size(), size);
      for (const std::string& name : Names(page.models)) seen.push_back(name);
    }
    EXPECT_EQ(seen, all);
  }
  // A filter with pages: 11 odd models, 4 a page.
  const std::vector<ModelPage> pages = AllPages({"", "", "odd"}, 4);
  ASSERT_EQ(pages.size(), 3u);
  std::vector<std::string> seen;
  for (const ModelPage& page : pages) {
    for (const std::string& name : Names(page.models)) seen.push_back(name);
  }
  EXPECT_EQ(seen, odd);
  // Pages larger than the maximum are cut to it.
  auto huge = repository_->List({}, 1000000, "");
  ASSERT_TRUE(huge.ok());
  EXPECT_EQ(huge->models.size(), all.size());
}

TEST_F(ModelRepositoryTest, APageTokenSurvivesChangesAndABadOneIsInvalidArgument) {
  for (const char* name : {"a", "b", "c", "d"}) MustPut(TestModel(name, 1));
  auto first = repository_->List({}, 2, "");
  ASSERT_TRUE(first.ok());
  EXPECT_EQ(Names(first->models), (std::vector<std::string>{"a", "b"}));
  ASSERT_FALSE(first->next_page_token.empty());
  // The model the token ends at is removed, and one is added before it: the next page goes on.
  ASSERT_TRUE(repository_->Remove("b").ok());
  MustPut(TestModel("a0", 2));
  auto second = repository_->List({}, 2, first->next_page_token);
  ASSERT_TRUE(second.ok()) << second.status().ToString();
  EXPECT_EQ(Names(second->models), (std::vector<std::string>{"c", "d"}));
  EXPECT_EQ(second->next_page_token, "");

  for (const std::string& token : {std::string("garbage"), std::string("after:"),
                                   std::string("after:bad name"), std::string("b")}) {
    EXPECT_EQ(repository_->List({}, 2, token).status().code(), StatusCode::kInvalidArgument)
        << token;
  }
}

TEST_F(ModelRepositoryTest, RemoveDeletesEveryVersionAndTheObject) {
  MustPut(TestModel("mug", 1));
  MustPut(TestModel("mug", 2));
  MustPut(TestModel("box", 3));
  ASSERT_TRUE(repository_->Remove("mug").ok());

  for (uint32_t version : {0u, 1u, 2u}) {
    EXPECT_EQ(repository_->Get("mug", version).status().code(), StatusCode::kNotFound);
  }
  EXPECT_TRUE(repository_->Versions("mug").empty());
  EXPECT_EQ(objects_->Get("mug").status().code(), StatusCode::kNotFound);
  EXPECT_EQ(objects_->size(), 1u);
  EXPECT_EQ(objects_->index().size(), 1u);
  EXPECT_EQ(BlobKeys(), std::vector<std::string>{"model/box/0000000001"});
  EXPECT_EQ(Names(repository_->List({}, 0, "")->models), std::vector<std::string>{"box"});
  EXPECT_EQ(repository_->Remove("mug").code(), StatusCode::kNotFound);

  // The name starts over.
  EXPECT_EQ(MustPut(TestModel("mug", 4)).metadata.version, 1u);
}

TEST_F(ModelRepositoryTest, BytesThatAreNoModelFileAreRefusedAndStoreNothing) {
  const std::string valid = File(TestModel("mug", 1));
  std::string flipped = valid;
  flipped[valid.size() / 2] ^= 0x01;
  for (const std::string& bytes :
       {std::string(), std::string("garbage"), valid.substr(0, valid.size() - 1), flipped}) {
    EXPECT_EQ(repository_->Put(bytes, "", {}).status().code(), StatusCode::kInvalidArgument)
        << bytes.size() << " bytes";
  }
  EXPECT_TRUE(BlobKeys().empty());
  EXPECT_EQ(objects_->size(), 0u);
}

TEST_F(ModelRepositoryTest, AModelTheDatabaseCannotIndexIsRefusedAndStoresNothing) {
  ObjectModel other_descriptors = TestModel("brief16", 1);
  other_descriptors.descriptor = {DescriptorType::kBinary, 16};
  other_descriptors.descriptors = testing::RandomDescriptors(80, 1, other_descriptors.descriptor);
  auto put = repository_->Put(File(other_descriptors), "", {});
  EXPECT_EQ(put.status().code(), StatusCode::kInvalidArgument) << put.status().ToString();

  ObjectModel featureless = TestModel("empty", 2);
  featureless.descriptors = cv::Mat();
  featureless.point_of_feature.clear();
  EXPECT_EQ(repository_->Put(File(featureless), "", {}).status().code(),
            StatusCode::kInvalidArgument);

  EXPECT_TRUE(BlobKeys().empty());
  EXPECT_EQ(objects_->size(), 0u);
}

TEST_F(ModelRepositoryTest, WatchersSeeEveryChangeInOrderAndNothingAfterUnwatch) {
  std::vector<ModelEvent> first;
  std::vector<ModelEvent> second;
  const uint64_t a = repository_->Watch([&](const ModelEvent& e) { first.push_back(e); });
  const uint64_t b = repository_->Watch([&](const ModelEvent& e) { second.push_back(e); });
  EXPECT_NE(a, b);

  const ModelVersionInfo mug1 = MustPut(TestModel("mug", 1));
  const ModelVersionInfo mug2 = MustPut(TestModel("mug", 2));
  const ModelVersionInfo box1 = MustPut(TestModel("box", 3));
  EXPECT_FALSE(repository_->Put("garbage", "", {}).ok());  // a failure is no change
  ASSERT_TRUE(repository_->Remove("mug").ok());
  EXPECT_EQ(repository_->Remove("mug").code(), StatusCode::kNotFound);

  ASSERT_EQ(first.size(), 4u);
  const ModelEvent::Kind put = ModelEvent::Kind::kPut;
  const std::vector<std::pair<ModelEvent::Kind, ModelVersionInfo>> expected = {
      {put, mug1}, {put, mug2}, {put, box1}, {ModelEvent::Kind::kDelete, mug2}};
  for (size_t i = 0; i < expected.size(); ++i) {
    SCOPED_TRACE(i);
    EXPECT_EQ(first[i].kind, expected[i].first);
    EXPECT_EQ(first[i].info, expected[i].second);
    EXPECT_EQ(first[i].sequence, i + 1);
  }

  repository_->Unwatch(b);
  repository_->Unwatch(b);      // twice is harmless
  repository_->Unwatch(12345);  // and so is an unknown id
  MustPut(TestModel("cup", 4));
  EXPECT_EQ(first.size(), 5u);
  EXPECT_EQ(first.back().info.metadata.name, "cup");
  EXPECT_EQ(first.back().sequence, 5u);
  EXPECT_EQ(second.size(), 4u);
}

TEST_F(ModelRepositoryTest, WatchingWithTheExistingVersionsListsThemFirstByNameOldestFirst) {
  const ModelVersionInfo mug1 = MustPut(TestModel("mug", 1));
  const ModelVersionInfo mug2 = MustPut(TestModel("mug", 2));
  const ModelVersionInfo box1 = MustPut(TestModel("box", 3));
  std::vector<ModelVersionInfo> existing = {mug1};  // replaced, not appended to
  std::vector<ModelEvent> events;
  repository_->Watch([&](const ModelEvent& e) { events.push_back(e); }, &existing);
  EXPECT_EQ(existing, (std::vector<ModelVersionInfo>{box1, mug1, mug2}));
  EXPECT_TRUE(events.empty());
  const ModelVersionInfo cup1 = MustPut(TestModel("cup", 4));
  ASSERT_EQ(events.size(), 1u);
  EXPECT_EQ(events[0].info, cup1);
}

TEST_F(ModelRepositoryTest, AWatchStartedDuringPutsGetsEachVersionOnceAsExistingOrAsAnEvent) {
  constexpr uint32_t kVersions = 40;
  std::atomic<uint32_t> stored{0};
  std::thread writer([&] {
    for (uint32_t i = 1; i <= kVersions; ++i) {
      MustPut(TestModel("mug", i));
      stored = i;
    }
  });
  while (stored < kVersions / 4) std::this_thread::yield();
  std::vector<ModelVersionInfo> existing;
  std::vector<uint32_t> told;  // written by the writer thread, read after join
  repository_->Watch([&](const ModelEvent& e) { told.push_back(e.info.metadata.version); },
                     &existing);
  writer.join();
  std::vector<uint32_t> seen = VersionNumbers(existing);
  EXPECT_GE(seen.size(), kVersions / 4);
  seen.insert(seen.end(), told.begin(), told.end());
  std::vector<uint32_t> all(kVersions);
  for (uint32_t i = 0; i < kVersions; ++i) all[i] = i + 1;
  EXPECT_EQ(seen, all);
}

// A second repository over its own store, as on a replica.
struct ReplicaRepository {
  ReplicaRepository() {
    auto opened = ObjectDatabase::Open(&store, testing::BundledObjectVocabulary());
    EXPECT_TRUE(opened.ok()) << opened.status().ToString();
    if (opened.ok()) objects = std::move(*opened);
    auto repository = ModelRepository::Open(&store, objects, FakeSha256);
    EXPECT_TRUE(repository.ok()) << repository.status().ToString();
    if (repository.ok()) models = std::move(*repository);
  }
  MemoryIndexStore store;
  std::shared_ptr<ObjectDatabase> objects;
  std::unique_ptr<ModelRepository> models;
};

TEST_F(ModelRepositoryTest, ACopyKeepsTheOriginalsVersionTagsCreationTimeAndBytes) {
  MustPut(TestModel("mug", 1));
  const ModelVersionInfo mug2 = MustPut(TestModel("mug", 2), {"kitchen", "blue"});
  const ModelVersionInfo mug3 = MustPut(TestModel("mug", 3));
  ReplicaRepository replica;
  ASSERT_NE(replica.models, nullptr);
  std::vector<ModelEvent> events;
  replica.models->Watch([&](const ModelEvent& e) { events.push_back(e); });

  // Versions 2 and 3 only: a replica keeps the primary's numbers even when it starts later.
  for (const ModelVersionInfo& info : {mug2, mug3}) {
    auto copied = replica.models->PutCopy(info, StoredFile("mug", info.metadata.version));
    ASSERT_TRUE(copied.ok()) << copied.status().ToString();
    EXPECT_EQ(*copied, info);
  }
  EXPECT_EQ(replica.models->Versions("mug"), (std::vector<ModelVersionInfo>{mug2, mug3}));
  auto file = replica.models->Get("mug", 2);
  ASSERT_TRUE(file.ok()) << file.status().ToString();
  EXPECT_EQ(file->second, StoredFile("mug", 2));
  ASSERT_EQ(replica.objects->List().size(), 1u);
  EXPECT_EQ(replica.objects->List()[0].version, 3u);  // the one recognised
  ASSERT_EQ(events.size(), 2u);
  EXPECT_EQ(events[1].kind, ModelEvent::Kind::kPut);
  EXPECT_EQ(events[1].info, mug3);
  // An upload to the replica itself continues after the copied versions.
  auto own = replica.models->Put(File(TestModel("mug", 9)), "", {});
  ASSERT_TRUE(own.ok()) << own.status().ToString();
  EXPECT_EQ(own->metadata.version, 4u);
}

TEST_F(ModelRepositoryTest, ACopyUnlikeItsDescriptionOrNotNewerIsRefusedAndStoresNothing) {
  const ModelVersionInfo mug1 = MustPut(TestModel("mug", 1));
  const ModelVersionInfo mug2 = MustPut(TestModel("mug", 2));
  const std::string file1 = StoredFile("mug", 1);
  ReplicaRepository replica;
  ASSERT_NE(replica.models, nullptr);
  ASSERT_TRUE(replica.models->PutCopy(mug2, StoredFile("mug", 2)).ok());
  const std::vector<std::string> keys = *replica.store.ListBlobKeys("");

  ModelVersionInfo wrong_hash = mug1;
  wrong_hash.sha256 = "fake:0:0";
  ModelVersionInfo wrong_size = mug1;
  wrong_size.size_bytes += 1;
  ModelVersionInfo wrong_version = mug1;
  wrong_version.metadata.version = 3;  // the file says 1
  ModelVersionInfo wrong_name = mug1;
  wrong_name.metadata.name = "cup";
  const struct {
    const char* what;
    ModelVersionInfo info;
    std::string file;
    StatusCode code;
  } cases[] = {
      {"another SHA-256", wrong_hash, file1, StatusCode::kInvalidArgument},
      {"another size", wrong_size, file1, StatusCode::kInvalidArgument},
      {"another version in the file", wrong_version, file1, StatusCode::kInvalidArgument},
      {"another name in the file", wrong_name, file1, StatusCode::kInvalidArgument},
      {"no model file", mug1, "garbage", StatusCode::kInvalidArgument},
      {"an older version", mug1, file1, StatusCode::kFailedPrecondition},
      {"the same version again", mug2, StoredFile("mug", 2), StatusCode::kFailedPrecondition},
  };
  for (const auto& c : cases) {
    SCOPED_TRACE(c.what);
    auto copied = replica.models->PutCopy(c.info, c.file);
    EXPECT_EQ(copied.status().code(), c.code) << copied.status().ToString();
  }
  EXPECT_EQ(replica.models->Versions("mug"), (std::vector<ModelVersionInfo>{mug2}));
  EXPECT_TRUE(replica.models->Versions("cup").empty());
  EXPECT_EQ(*replica.store.ListBlobKeys(""), keys);
}

TEST_F(ModelRepositoryTest, ReopeningKeepsEveryVersion) {
  MustPut(TestModel("mug", 1), {"kitchen"});
  MustPut(TestModel("mug", 2));
  MustPut(TestModel("box", 3), {}, "crate");
  const std::vector<ModelVersionInfo> mug = repository_->Versions("mug");
  const std::vector<ModelVersionInfo> crate = repository_->Versions("crate");
  const std::string mug1 = StoredFile("mug", 1);
  const std::vector<std::string> keys = BlobKeys();

  Reopen();
  EXPECT_EQ(repository_->Versions("mug"), mug);
  EXPECT_EQ(repository_->Versions("crate"), crate);
  EXPECT_EQ(StoredFile("mug", 1), mug1);
  EXPECT_EQ(BlobKeys(), keys);
  EXPECT_EQ(objects_->size(), 2u);
  EXPECT_EQ(MustPut(TestModel("mug", 4)).metadata.version, 3u);
}

TEST_F(ModelRepositoryTest, OpeningDeletesTheVersionsOfAnInterruptedPutOrRemove) {
  MustPut(TestModel("mug", 1));
  const std::vector<ModelVersionInfo> mug = repository_->Versions("mug");
  // A put that stopped after writing its version (whatever it holds), and a removal that stopped
  // after removing the object.
  ASSERT_TRUE(store_.PutBlob("model/mug/0000000002", "half an upload").ok());
  ASSERT_TRUE(store_.PutBlob("model/ghost/0000000001", "gone").ok());
  ASSERT_TRUE(store_.PutBlob("model/ghost/0000000004", "gone").ok());
  ASSERT_TRUE(store_.PutBlob("unrelated", "not the repository's").ok());

  Reopen();
  EXPECT_EQ(repository_->Versions("mug"), mug);
  EXPECT_TRUE(repository_->Versions("ghost").empty());
  EXPECT_EQ(BlobKeys(), (std::vector<std::string>{"model/mug/0000000001", "unrelated"}));
  EXPECT_EQ(MustPut(TestModel("mug", 2)).metadata.version, 2u);
}

TEST_F(ModelRepositoryTest, OpeningRecordsObjectsPutIntoTheDatabaseDirectly) {
  MustPut(TestModel("mug", 1));
  // Older code wrote the database only: a new object, and a new version of "mug".
  ASSERT_TRUE(objects_->Put(TestModel("legacy", 2)).ok());
  ObjectModel newer = TestModel("mug", 3);
  newer.metadata.version = 1;  // the database makes it 2
  ASSERT_TRUE(objects_->Put(newer).ok());

  Reopen();
  const std::vector<ModelVersionInfo> legacy = repository_->Versions("legacy");
  ASSERT_EQ(legacy.size(), 1u);
  EXPECT_EQ(legacy[0].metadata.version, 7u);  // the version the database has
  EXPECT_TRUE(legacy[0].tags.empty());
  EXPECT_EQ(legacy[0].num_descriptors, 80u);
  auto file = repository_->Get("legacy", 0);
  ASSERT_TRUE(file.ok()) << file.status().ToString();
  EXPECT_EQ(file->first.sha256, FakeSha256(file->second));
  auto model = DecodeObjectModel(file->second, "legacy");
  ASSERT_TRUE(model.ok()) << model.status().ToString();
  EXPECT_EQ(model->metadata, objects_->Get("legacy")->metadata);
  EXPECT_EQ(cv::norm(model->descriptors, TestModel("legacy", 2).descriptors, cv::NORM_HAMMING), 0);

  EXPECT_EQ(VersionNumbers(repository_->Versions("mug")), (std::vector<uint32_t>{1, 2}));
  EXPECT_EQ(DecodeObjectModel(StoredFile("mug", 2), "mug")->metadata.source, "test:3");
  // Reconciled once: a second open changes nothing.
  const std::vector<std::string> keys = BlobKeys();
  Reopen();
  EXPECT_EQ(BlobKeys(), keys);
  EXPECT_EQ(repository_->Versions("legacy"), legacy);
}

TEST_F(ModelRepositoryTest, ADamagedStoredVersionIsDataLoss) {
  MustPut(TestModel("mug", 1));
  const std::string key = "model/mug/0000000001";
  const std::string good = *store_.GetBlob(key);

  // Damaged while the repository is open: the download fails.
  ASSERT_TRUE(store_.PutBlob(key, good.substr(0, good.size() - 1)).ok());
  EXPECT_EQ(repository_->Get("mug", 1).status().code(), StatusCode::kDataLoss);

  // Damaged values, and a value under another version's key, fail the open.
  std::string other_format = good;
  other_format[0] = 9;
  std::string long_header = good;
  long_header[4] = char(0x7f);  // the top byte of the header size
  const std::vector<std::string> damaged = {"",           "\x01",      good.substr(0, 20),
                                            other_format, long_header, good + "x"};
  for (const std::string& value : damaged) {
    SCOPED_TRACE(value.size());
    ASSERT_TRUE(store_.PutBlob(key, value).ok());
    repository_.reset();
    auto reopened = ModelRepository::Open(&store_, objects_, FakeSha256);
    EXPECT_EQ(reopened.status().code(), StatusCode::kDataLoss) << reopened.status().ToString();
  }
  ASSERT_TRUE(store_.PutBlob(key, good).ok());
  ObjectModel newer = TestModel("mug", 2);
  newer.metadata.version = 1;
  ASSERT_TRUE(objects_->Put(newer).ok());  // the database is at version 2 now
  ASSERT_TRUE(store_.PutBlob("model/mug/0000000002", good).ok());
  auto reopened = ModelRepository::Open(&store_, objects_, FakeSha256);
  EXPECT_EQ(reopened.status().code(), StatusCode::kDataLoss) << reopened.status().ToString();
  ASSERT_TRUE(store_.DeleteBlob("model/mug/0000000002").ok());

  // A key the repository did not write.
  ASSERT_TRUE(store_.PutBlob("model/mug/12", good).ok());
  reopened = ModelRepository::Open(&store_, objects_, FakeSha256);
  EXPECT_EQ(reopened.status().code(), StatusCode::kDataLoss) << reopened.status().ToString();
  ASSERT_TRUE(store_.DeleteBlob("model/mug/12").ok());
  EXPECT_TRUE(ModelRepository::Open(&store_, objects_, FakeSha256).ok());
}

TEST_F(ModelRepositoryTest, OpenNeedsAStoreADatabaseAndAHashFunction) {
  EXPECT_EQ(ModelRepository::Open(nullptr, objects_, FakeSha256).status().code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(ModelRepository::Open(&store_, nullptr, FakeSha256).status().code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(ModelRepository::Open(&store_, objects_, nullptr).status().code(),
            StatusCode::kInvalidArgument);
}

TEST_F(ModelRepositoryTest, ConcurrentPutsAndReadsKeepEveryVersion) {
  constexpr int kVersions = 5;
  std::atomic<bool> stop{false};
  std::atomic<int> failures{0};
  std::thread reader([&] {
    while (!stop) {
      const StatusOr<ModelPage> page = repository_->List({}, 0, "");
      if (!page.ok()) {
        ++failures;
        continue;
      }
      for (const ModelVersionInfo& info : page->models) {
        if (!repository_->Get(info.metadata.name, info.metadata.version).ok()) ++failures;
      }
    }
  });
  std::vector<std::thread> writers;
  for (int t = 0; t < 2; ++t) {
    writers.emplace_back([&, t] {
      for (int i = 0; i < kVersions; ++i) {
        const std::string name = "object-" + std::to_string(t);
        if (!repository_->Put(File(TestModel(name, uint64_t(10 * t + i))), "", {}).ok()) {
          ++failures;
        }
      }
    });
  }
  for (std::thread& writer : writers) writer.join();
  stop = true;
  reader.join();
  EXPECT_EQ(failures.load(), 0);
  for (const char* name : {"object-0", "object-1"}) {
    EXPECT_EQ(VersionNumbers(repository_->Versions(name)), (std::vector<uint32_t>{1, 2, 3, 4, 5}));
  }
  EXPECT_EQ(objects_->size(), 2u);
}

}  // namespace
}  // namespace recog
