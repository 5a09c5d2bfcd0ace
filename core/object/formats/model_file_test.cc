#include "core/object/formats/model_file.h"

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <random>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

// Header-only so that the test can re-seal hand-edited files without linking xxhash itself.
#define XXH_INLINE_ALL
#include <xxhash.h>

namespace recog {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

constexpr size_t kHeaderSize = 40;

// --- Models ---

ObjectMetadata Metadata(const std::string& name, ObjectType type) {
  ObjectMetadata meta;
  meta.name = name;
  meta.object_class = "toy animal";
  meta.type = type;
  meta.dimensions = {0.21, 0.14, type == ObjectType::kPlanar ? 0.0 : 0.09};
  meta.units = "m";
  meta.source = "roboearth:/data/" + name;
  meta.version = 7;
  return meta;
}

// num_points random points in a 20 cm cube, each described by features_per_point random
// descriptors.
void AddRandomPoints(size_t num_points, int features_per_point, uint32_t seed, ObjectModel* model) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> coordinate(-0.1f, 0.1f);
  std::uniform_int_distribution<int> byte(0, 255);
  for (size_t i = 0; i < num_points; ++i) {
    model->points.emplace_back(coordinate(rng), coordinate(rng), coordinate(rng));
  }
  const int n = int(num_points) * features_per_point;
  model->descriptors.create(n, int(model->descriptor.size_bytes), CV_8U);
  for (int r = 0; r < n; ++r) {
    for (int c = 0; c < model->descriptors.cols; ++c)
      model->descriptors.at<uint8_t>(r, c) = byte(rng);
    model->point_of_feature.push_back(uint32_t(r / features_per_point));
  }
}

RigidTransform Pose(double angle, const cv::Vec3d& t) {
  RigidTransform pose;
  pose.R = {std::cos(angle), 0, std::sin(angle), 0, 1, 0, -std::sin(angle), 0, std::cos(angle)};
  pose.t = t;
  return pose;
}

std::vector<uint8_t> SmallPng(int size, uint32_t seed) {
  cv::Mat image(size, size, CV_8UC3);
  cv::RNG rng(seed);
  rng.fill(image, cv::RNG::UNIFORM, 0, 256);
  std::vector<uint8_t> png;
  EXPECT_TRUE(cv::imencode(".png", image, png));
  return png;
}

TrainingView View(const std::string& name, double angle, int image_size) {
  TrainingView view;
  view.name = name;
  view.camera = {525.5, 526.25, 319.75, 239.5, {0.1, -0.25, 0.001, -0.002, 0.05}};
  view.camera_from_object = Pose(angle, {0.01, -0.02, 0.6});
  view.image_png = SmallPng(image_size, uint32_t(angle * 1000) + 1);
  return view;
}

ObjectModel Model3D() {
  ObjectModel model;
  model.metadata = Metadata("lion", ObjectType::k3D);
  AddRandomPoints(50, 2, 42, &model);
  return model;
}

// Two faces of a box, each point on one of them; a view per face.
ObjectModel PlanarModel(size_t num_points, int image_size) {
  ObjectModel model;
  model.metadata = Metadata("cereal_box", ObjectType::kPlanar);
  AddRandomPoints(num_points, 1, 7, &model);
  model.faces.push_back({0.21, 0.3, Pose(0, {0, 0, 0})});
  model.faces.push_back({0.07, 0.3, Pose(CV_PI / 2, {0.21, 0, 0})});
  for (size_t i = 0; i < num_points; ++i) model.face_of_point.push_back(uint32_t(i % 2));
  model.views.push_back(View("face_000", 0.0, image_size));
  model.views.push_back(View("face_001", CV_PI / 2, image_size));
  return model;
}

// Small enough to loop over every byte of its encoding; it has every section.
ObjectModel TinyModel() { return PlanarModel(4, 2); }

void ExpectSameTransform(const RigidTransform& expected, const RigidTransform& actual) {
  EXPECT_EQ(expected.R, actual.R);
  EXPECT_EQ(expected.t, actual.t);
}

// Every field, exactly: the format stores values bit for bit.
void ExpectSameModel(const ObjectModel& expected, const ObjectModel& actual) {
  EXPECT_EQ(expected.metadata, actual.metadata);
  EXPECT_EQ(expected.descriptor, actual.descriptor);
  EXPECT_EQ(expected.points, actual.points);
  EXPECT_EQ(expected.point_of_feature, actual.point_of_feature);
  ASSERT_EQ(expected.descriptors.rows, actual.descriptors.rows);
  ASSERT_EQ(expected.descriptors.cols, actual.descriptors.cols);
  if (!expected.descriptors.empty()) {
    EXPECT_EQ(actual.descriptors.type(), CV_8U);
    EXPECT_EQ(cv::norm(expected.descriptors, actual.descriptors, cv::NORM_HAMMING), 0.0);
  }
  ASSERT_EQ(expected.faces.size(), actual.faces.size());
  for (size_t i = 0; i < expected.faces.size(); ++i) {
    EXPECT_EQ(expected.faces[i].width, actual.faces[i].width);
    EXPECT_EQ(expected.faces[i].height, actual.faces[i].height);
    ExpectSameTransform(expected.faces[i].object_from_face, actual.faces[i].object_from_face);
  }
  EXPECT_EQ(expected.face_of_point, actual.face_of_point);
  ASSERT_EQ(expected.views.size(), actual.views.size());
  for (size_t i = 0; i < expected.views.size(); ++i) {
    EXPECT_EQ(expected.views[i].name, actual.views[i].name);
    EXPECT_EQ(expected.views[i].camera, actual.views[i].camera);
    ExpectSameTransform(expected.views[i].camera_from_object, actual.views[i].camera_from_object);
    EXPECT_EQ(expected.views[i].image_png, actual.views[i].image_png);
  }
}

std::string Encode(const ObjectModel& model) {
  auto bytes = EncodeObjectModel(model);
  EXPECT_TRUE(bytes.ok()) << bytes.status().ToString();
  return bytes.ok() ? *bytes : std::string();
}

// --- Taking files apart and sealing hand-edited ones (fresh checksums) ---

template <class T>
T Get(const std::string& bytes, size_t offset) {
  T value;
  std::memcpy(&value, bytes.data() + offset, sizeof(T));
  return value;
}
template <class T>
void Set(std::string* bytes, size_t offset, T value) {
  std::memcpy(bytes->data() + offset, &value, sizeof(T));
}
template <class T>
void Append(std::string* bytes, T value) {
  bytes->append(sizeof(T), '\0');
  Set(bytes, bytes->size() - sizeof(T), value);
}

struct RawSection {
  std::string tag;  // "META"
  std::string payload;
};

std::vector<RawSection> Split(const std::string& file) {
  std::vector<RawSection> sections;
  size_t at = kHeaderSize;
  for (uint32_t i = 0; i < Get<uint32_t>(file, 12); ++i) {
    const uint64_t size = Get<uint64_t>(file, at + 4);
    sections.push_back({file.substr(at, 4), file.substr(at + 12, size)});
    at += 12 + size;
  }
  EXPECT_EQ(at, file.size());
  return sections;
}

// Recomputes the header checksum after the header was edited.
void SealHeader(std::string* file) { Set<uint64_t>(file, 32, XXH3_64bits(file->data(), 32)); }

std::string Assemble(const std::vector<RawSection>& sections) {
  std::string body;
  for (const RawSection& s : sections) {
    body += s.tag;
    Append<uint64_t>(&body, s.payload.size());
    body += s.payload;
  }
  std::string file = "RECOGOBJ";
  Append<uint32_t>(&file, 1);
  Append<uint32_t>(&file, uint32_t(sections.size()));
  Append<uint64_t>(&file, body.size());
  Append<uint64_t>(&file, XXH3_64bits(body.data(), body.size()));
  Append<uint64_t>(&file, 0);
  SealHeader(&file);
  return file + body;
}

RawSection* Find(std::vector<RawSection>* sections, const std::string& tag) {
  for (RawSection& s : *sections) {
    if (s.tag == tag) return &s;
  }
  ADD_FAILURE() << "no " << tag << " section";
  return nullptr;
}

StatusOr<ObjectModel> Decode(const std::string& bytes) {
  return DecodeObjectModel(bytes, "test.robj");
}

// --- Encoding and decoding ---

TEST(ModelFileTest, RoundTripsA3DModel) {
  const ObjectModel model = Model3D();
  ASSERT_TRUE(model.Validate().ok());
  const std::string bytes = Encode(model);
  auto decoded = Decode(bytes);
  ASSERT_TRUE(decoded.ok()) << decoded.status().ToString();
  ExpectSameModel(model, *decoded);
  EXPECT_EQ(decoded->num_features(), 100u);
  // Encoding is deterministic: the decoded copy encodes to the same bytes.
  EXPECT_EQ(Encode(*decoded), bytes);
}

// Its text goes back out in protobuf strings and JSON, which must be UTF-8: bytes FF FE in a
// RoboEarth meta.xml name once made a class that broke every client's model listing.
TEST(ModelFileTest, TextThatIsNotUtf8IsRefused) {
  ObjectModel model = PlanarModel(60, 16);
  model.metadata.object_class = "caf\xC3\xA9";  // UTF-8 is fine
  ASSERT_TRUE(model.Validate().ok());
  const auto refused = [](const ObjectModel& bad, const std::string& field) {
    const Status status = bad.Validate();
    EXPECT_EQ(status.code(), StatusCode::kInvalidArgument) << field;
    EXPECT_NE(status.message().find(field + " is not UTF-8"), std::string::npos)
        << status.message();
    EXPECT_FALSE(EncodeObjectModel(bad).ok());
  };
  ObjectModel bad = model;
  bad.metadata.object_class = "\xFF\xFE";
  refused(bad, "the class");
  bad = model;
  bad.metadata.source = "roboearth:/\xC3";
  refused(bad, "the source");
  bad = model;
  bad.metadata.units = "\xB5m";
  refused(bad, "the units");
  bad = model;
  bad.views[0].name = "face_\xFF";
  refused(bad, "a view's name");
}

TEST(ModelFileTest, RoundTripsAPlanarModelWithViews) {
  const ObjectModel model = PlanarModel(60, 16);
  ASSERT_TRUE(model.Validate().ok());
  auto decoded = Decode(Encode(model));
  ASSERT_TRUE(decoded.ok()) << decoded.status().ToString();
  ExpectSameModel(model, *decoded);
  // The stored PNG is the original image, byte for byte.
  const cv::Mat image = cv::imdecode(decoded->views[1].image_png, cv::IMREAD_UNCHANGED);
  EXPECT_EQ(image.size(), cv::Size(16, 16));
}

TEST(ModelFileTest, RoundTripsAModelWithoutFeaturesOrImages) {
  ObjectModel model;
  model.metadata = Metadata("empty", ObjectType::k3D);
  model.metadata.object_class = "";
  model.views.push_back(View("bare", 0.3, 2));
  model.views[0].image_png.clear();
  model.views[0].camera.distortion.clear();
  auto decoded = Decode(Encode(model));
  ASSERT_TRUE(decoded.ok()) << decoded.status().ToString();
  ExpectSameModel(model, *decoded);
  EXPECT_TRUE(decoded->descriptors.empty());
}

TEST(ModelFileTest, WritesNonContinuousDescriptorsRowByRow) {
  ObjectModel model = Model3D();
  // The same descriptors as a column window of a wider matrix: rows are not contiguous.
  cv::Mat wide(model.descriptors.rows, model.descriptors.cols + 16, CV_8U, cv::Scalar(0xAB));
  model.descriptors.copyTo(wide.colRange(8, 8 + model.descriptors.cols));
  ObjectModel windowed = model;
  windowed.descriptors = wide.colRange(8, 8 + model.descriptors.cols);
  ASSERT_FALSE(windowed.descriptors.isContinuous());

  const std::string bytes = Encode(windowed);
  EXPECT_EQ(bytes, Encode(model));
  auto decoded = Decode(bytes);
  ASSERT_TRUE(decoded.ok()) << decoded.status().ToString();
  EXPECT_TRUE(decoded->descriptors.isContinuous());
  ExpectSameModel(model, *decoded);
}

TEST(ModelFileTest, FollowsTheDocumentedLayout) {
  const ObjectModel model = TinyModel();
  const std::string bytes = Encode(model);
  EXPECT_EQ(bytes.substr(0, 8), "RECOGOBJ");
  EXPECT_EQ(Get<uint32_t>(bytes, 8), 1u);
  EXPECT_EQ(Get<uint64_t>(bytes, 16), bytes.size() - kHeaderSize);
  EXPECT_EQ(Get<uint64_t>(bytes, 24),
            XXH3_64bits(bytes.data() + kHeaderSize, bytes.size() - kHeaderSize));
  EXPECT_EQ(Get<uint64_t>(bytes, 32), XXH3_64bits(bytes.data(), 32));

  std::vector<RawSection> sections = Split(bytes);
  std::vector<std::string> tags;
  for (const RawSection& s : sections) tags.push_back(s.tag);
  EXPECT_THAT(tags, ::testing::ElementsAre("META", "DESC", "PNTS", "FACE", "VIEW"));
  EXPECT_EQ(Assemble(sections), bytes);

  const std::string& points = Find(&sections, "PNTS")->payload;
  ASSERT_EQ(points.size(), 4u + 4 * 12);
  EXPECT_EQ(Get<uint32_t>(points, 0), 4u);
  EXPECT_EQ(Get<float>(points, 4 + 12 + 8), model.points[1].z);

  const std::string& meta = Find(&sections, "META")->payload;
  EXPECT_EQ(Get<uint32_t>(meta, 0), model.metadata.name.size());
  EXPECT_EQ(meta.substr(4, model.metadata.name.size()), model.metadata.name);

  // A 3D model without faces or views writes only the required sections.
  tags.clear();
  ObjectModel bare = TinyModel();
  bare.metadata.type = ObjectType::k3D;
  bare.faces.clear();
  bare.face_of_point.clear();
  bare.views.clear();
  for (const RawSection& s : Split(Encode(bare))) tags.push_back(s.tag);
  EXPECT_THAT(tags, ::testing::ElementsAre("META", "DESC", "PNTS"));
}

TEST(ModelFileTest, RejectsAnInvalidModelOnEncode) {
  ObjectModel model = Model3D();
  model.point_of_feature[3] = uint32_t(model.points.size());
  auto bytes = EncodeObjectModel(model);
  ASSERT_FALSE(bytes.ok());
  EXPECT_EQ(bytes.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(bytes.status().message(), HasSubstr("feature of a missing point"));

  ObjectModel unnamed = Model3D();
  unnamed.metadata.name = "no spaces allowed";
  EXPECT_EQ(EncodeObjectModel(unnamed).status().code(), StatusCode::kInvalidArgument);

  // A format the reader would refuse is refused on the way out too, even without features.
  ObjectModel odd_format;
  odd_format.metadata = Metadata("odd", ObjectType::k3D);
  odd_format.descriptor.size_bytes = 7;
  ASSERT_TRUE(odd_format.Validate().ok());
  EXPECT_EQ(EncodeObjectModel(odd_format).status().code(), StatusCode::kInvalidArgument);
}

// --- Corruption ---

TEST(ModelFileTest, EveryTruncationIsDataLoss) {
  const std::string bytes = Encode(TinyModel());
  ASSERT_GT(bytes.size(), kHeaderSize);
  for (size_t length = 0; length < bytes.size(); ++length) {
    auto decoded = Decode(bytes.substr(0, length));
    ASSERT_FALSE(decoded.ok()) << "length " << length;
    EXPECT_EQ(decoded.status().code(), StatusCode::kDataLoss) << "length " << length;
    EXPECT_THAT(decoded.status().message(), HasSubstr("test.robj")) << "length " << length;
  }
}

TEST(ModelFileTest, EveryFlippedByteIsDataLoss) {
  const std::string bytes = Encode(TinyModel());
  for (size_t i = 0; i < bytes.size(); ++i) {
    std::string damaged = bytes;
    damaged[i] = char(damaged[i] ^ 0x5A);
    auto decoded = Decode(damaged);
    ASSERT_FALSE(decoded.ok()) << "byte " << i;
    EXPECT_EQ(decoded.status().code(), StatusCode::kDataLoss) << "byte " << i;
  }
}

TEST(ModelFileTest, TrailingBytesAreDataLoss) {
  auto decoded = Decode(Encode(TinyModel()) + "x");
  EXPECT_EQ(decoded.status().code(), StatusCode::kDataLoss);
  EXPECT_THAT(decoded.status().message(), HasSubstr("truncated or padded"));
}

TEST(ModelFileTest, WrongMagicIsDataLoss) {
  std::string bytes = Encode(TinyModel());
  bytes.replace(0, 8, "RECOGVOC");
  auto decoded = Decode(bytes);
  EXPECT_EQ(decoded.status().code(), StatusCode::kDataLoss);
  EXPECT_THAT(decoded.status().message(), HasSubstr("bad magic"));
  EXPECT_EQ(Decode("ply\nformat ascii 1.0\n").status().code(), StatusCode::kDataLoss);
}

TEST(ModelFileTest, NewerVersionIsFailedPrecondition) {
  std::string bytes = Encode(TinyModel());
  Set<uint32_t>(&bytes, 8, 2);
  SealHeader(&bytes);
  auto decoded = Decode(bytes);
  EXPECT_EQ(decoded.status().code(), StatusCode::kFailedPrecondition);
  EXPECT_THAT(decoded.status().message(), HasSubstr("written by a newer version"));
  EXPECT_THAT(decoded.status().message(), HasSubstr("test.robj"));
}

TEST(ModelFileTest, SkipsAnUnknownSection) {
  const ObjectModel model = TinyModel();
  std::vector<RawSection> sections = Split(Encode(model));
  sections.push_back({"XTRA", std::string(100, '\x7f')});
  sections.insert(sections.begin(), RawSection{"ZERO", ""});
  auto decoded = Decode(Assemble(sections));
  ASSERT_TRUE(decoded.ok()) << decoded.status().ToString();
  ExpectSameModel(model, *decoded);
}

TEST(ModelFileTest, ReadsSectionsInAnyOrder) {
  const ObjectModel model = TinyModel();
  std::vector<RawSection> sections = Split(Encode(model));
  std::reverse(sections.begin(), sections.end());
  auto decoded = Decode(Assemble(sections));
  ASSERT_TRUE(decoded.ok()) << decoded.status().ToString();
  ExpectSameModel(model, *decoded);
}

TEST(ModelFileTest, OptionalSectionsMayBeMissing) {
  ObjectModel model = Model3D();
  model.views.push_back(View("face_000", 0.1, 4));
  std::vector<RawSection> sections = Split(Encode(model));
  ASSERT_EQ(sections.back().tag, "VIEW");
  sections.pop_back();
  auto decoded = Decode(Assemble(sections));
  ASSERT_TRUE(decoded.ok()) << decoded.status().ToString();
  model.views.clear();
  ExpectSameModel(model, *decoded);
}

TEST(ModelFileTest, MissingRequiredSectionIsDataLoss) {
  for (const std::string tag : {"META", "DESC", "PNTS"}) {
    std::vector<RawSection> sections = Split(Encode(TinyModel()));
    std::erase_if(sections, [&](const RawSection& s) { return s.tag == tag; });
    auto decoded = Decode(Assemble(sections));
    EXPECT_EQ(decoded.status().code(), StatusCode::kDataLoss) << tag;
    EXPECT_THAT(decoded.status().message(), HasSubstr("missing '" + tag + "' section"));
  }
  // A planar model needs its faces: dropping FACE leaves a model that fails validation.
  std::vector<RawSection> sections = Split(Encode(TinyModel()));
  std::erase_if(sections, [](const RawSection& s) { return s.tag == "FACE"; });
  auto decoded = Decode(Assemble(sections));
  EXPECT_EQ(decoded.status().code(), StatusCode::kDataLoss);
  EXPECT_THAT(decoded.status().message(), HasSubstr("a planar model needs faces"));
}

TEST(ModelFileTest, DuplicateSectionIsDataLoss) {
  for (const std::string tag : {"META", "DESC", "PNTS", "FACE", "VIEW"}) {
    std::vector<RawSection> sections = Split(Encode(TinyModel()));
    sections.push_back(*Find(&sections, tag));
    auto decoded = Decode(Assemble(sections));
    EXPECT_EQ(decoded.status().code(), StatusCode::kDataLoss) << tag;
    EXPECT_THAT(decoded.status().message(), HasSubstr("duplicate '" + tag + "' section"));
  }
}

TEST(ModelFileTest, SectionCountNotMatchingTheBodyIsDataLoss) {
  std::string bytes = Encode(TinyModel());
  for (uint32_t count : {4u, 6u, 0xFFFFFFFFu}) {
    std::string edited = bytes;
    Set<uint32_t>(&edited, 12, count);
    SealHeader(&edited);
    EXPECT_EQ(Decode(edited).status().code(), StatusCode::kDataLoss) << count;
  }
}

// Counts and lengths that promise more than the section holds are caught before any allocation,
// even in a file whose checksums are intact.
TEST(ModelFileTest, HugeCountsAreDataLoss) {
  struct Edit {
    std::string tag;
    size_t offset;  // of a u32 count or length in the payload
  };
  const ObjectModel model = TinyModel();
  const size_t name_length = model.metadata.name.size();
  for (const Edit& edit :
       {Edit{"META", 0}, Edit{"META", 4 + name_length}, Edit{"DESC", 5}, Edit{"PNTS", 0},
        Edit{"FACE", 0}, Edit{"VIEW", 0}, Edit{"VIEW", 4}, Edit{"VIEW", 4 + 4 + 8 + 32}}) {
    std::vector<RawSection> sections = Split(Encode(model));
    Set<uint32_t>(&Find(&sections, edit.tag)->payload, edit.offset, 0xFFFFFFF0u);
    auto decoded = Decode(Assemble(sections));
    EXPECT_EQ(decoded.status().code(), StatusCode::kDataLoss) << edit.tag << "@" << edit.offset;
    EXPECT_THAT(decoded.status().message(), HasSubstr("'" + edit.tag + "' section"));
  }
}

TEST(ModelFileTest, EveryTruncatedSectionIsDataLoss) {
  const std::vector<RawSection> original = Split(Encode(TinyModel()));
  for (size_t s = 0; s < original.size(); ++s) {
    for (size_t length = 0; length < original[s].payload.size(); ++length) {
      std::vector<RawSection> sections = original;
      sections[s].payload.resize(length);
      auto decoded = Decode(Assemble(sections));
      EXPECT_EQ(decoded.status().code(), StatusCode::kDataLoss)
          << original[s].tag << " cut to " << length;
    }
  }
}

TEST(ModelFileTest, ResealedByteFlipsNeverCrashTheParser) {
  const std::vector<RawSection> original = Split(Encode(TinyModel()));
  int rejected = 0;
  for (size_t s = 0; s < original.size(); ++s) {
    for (size_t i = 0; i < original[s].payload.size(); ++i) {
      for (int mask : {0x01, 0x80, 0xFF}) {
        std::vector<RawSection> sections = original;
        sections[s].payload[i] = char(sections[s].payload[i] ^ mask);
        auto decoded = Decode(Assemble(sections));
        if (decoded.ok()) continue;  // e.g. a changed coordinate is still a valid model
        ++rejected;
        EXPECT_EQ(decoded.status().code(), StatusCode::kDataLoss)
            << original[s].tag << " byte " << i << ": " << decoded.status().ToString();
      }
    }
  }
  EXPECT_GT(rejected, 0);
}

TEST(ModelFileTest, DecodedModelIsValidated) {
  const ObjectModel model = Model3D();
  std::vector<RawSection> sections = Split(Encode(model));
  std::string& desc = Find(&sections, "DESC")->payload;
  // The first point index follows type, size, count and the descriptor rows.
  const size_t first_index = 1 + 4 + 4 + model.num_features() * model.descriptor.size_bytes;
  ASSERT_EQ(Get<uint32_t>(desc, first_index), 0u);
  Set<uint32_t>(&desc, first_index, 50);
  auto decoded = Decode(Assemble(sections));
  EXPECT_EQ(decoded.status().code(), StatusCode::kDataLoss);
  EXPECT_THAT(decoded.status().message(), HasSubstr("test.robj is corrupt"));
  EXPECT_THAT(decoded.status().message(), HasSubstr("feature of a missing point"));
}

// --- Files ---

class ModelFileIoTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("recog_model_file_test_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  std::string Path(const std::string& name) const { return (dir_ / name).string(); }
  std::vector<std::string> Entries() const {
    std::vector<std::string> names;
    for (const auto& entry : fs::directory_iterator(dir_)) {
      names.push_back(entry.path().filename().string());
    }
    return names;
  }
  static std::string ReadAll(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    return {std::istreambuf_iterator<char>(in), {}};
  }
  static void WriteAll(const std::string& path, const std::string& bytes) {
    std::ofstream out(path, std::ios::binary);
    out.write(bytes.data(), std::streamsize(bytes.size()));
  }

  fs::path dir_;
};

TEST_F(ModelFileIoTest, SavesAndLoadsAtomically) {
  const ObjectModel model = PlanarModel(30, 8);
  const std::string path = Path("cereal_box.robj");
  ASSERT_TRUE(SaveObjectModel(model, path).ok());
  EXPECT_THAT(Entries(), ::testing::ElementsAre("cereal_box.robj"));  // no .tmp left behind
  EXPECT_EQ(ReadAll(path), Encode(model));
  auto loaded = LoadObjectModel(path);
  ASSERT_TRUE(loaded.ok()) << loaded.status().ToString();
  ExpectSameModel(model, *loaded);

  // Saving again replaces the file.
  ObjectModel newer = Model3D();
  newer.metadata.version = 8;
  ASSERT_TRUE(SaveObjectModel(newer, path).ok());
  EXPECT_THAT(Entries(), ::testing::ElementsAre("cereal_box.robj"));
  loaded = LoadObjectModel(path);
  ASSERT_TRUE(loaded.ok()) << loaded.status().ToString();
  ExpectSameModel(newer, *loaded);
}

TEST_F(ModelFileIoTest, InvalidModelIsNotSaved) {
  ObjectModel model = Model3D();
  model.point_of_feature.back() = 1000;
  EXPECT_EQ(SaveObjectModel(model, Path("bad.robj")).code(), StatusCode::kInvalidArgument);
  EXPECT_TRUE(Entries().empty());
}

TEST_F(ModelFileIoTest, MissingFileIsNotFound) {
  auto loaded = LoadObjectModel(Path("absent.robj"));
  EXPECT_EQ(loaded.status().code(), StatusCode::kNotFound);
  EXPECT_THAT(loaded.status().message(), HasSubstr("absent.robj"));
  EXPECT_EQ(SaveObjectModel(Model3D(), Path("no/such/dir/m.robj")).code(), StatusCode::kNotFound);
}

TEST_F(ModelFileIoTest, DirectoryIsNotAModelFile) {
  EXPECT_EQ(LoadObjectModel(dir_.string()).status().code(), StatusCode::kInvalidArgument);
}

TEST_F(ModelFileIoTest, CorruptFileIsDataLossNamingThePath) {
  const std::string path = Path("m.robj");
  std::string bytes = Encode(TinyModel());
  bytes[bytes.size() - 3] = char(bytes[bytes.size() - 3] ^ 1);
  WriteAll(path, bytes);
  auto loaded = LoadObjectModel(path);
  EXPECT_EQ(loaded.status().code(), StatusCode::kDataLoss);
  EXPECT_THAT(loaded.status().message(), HasSubstr("'" + path + "' is corrupt"));
  EXPECT_THAT(loaded.status().message(), HasSubstr("body checksum mismatch"));

  WriteAll(path, "");
  EXPECT_EQ(LoadObjectModel(path).status().code(), StatusCode::kDataLoss);
}

}  // namespace
}  // namespace recog
