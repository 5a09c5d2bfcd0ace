#include "core/object/formats/roboearth.h"

#include <unistd.h>

#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <memory>
#include <set>
#include <string>

#include <gtest/gtest.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>

#include "core/object/builder/model_builder.h"
#include "core/vocabulary/vocabulary_io.h"
#include "tests/testing/data_paths.h"
#include "tests/testing/test_data.h"
#include "tests/testing/vocabularies.h"

namespace recog {
namespace {

namespace fs = std::filesystem;

constexpr char kModels[] = "objects/roboearth/models";

std::string Model(const std::string& name) {
  return testing::SharedData(std::string(kModels) + "/" + name);
}

std::string ReadText(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), {}};
}

void WriteText(const std::string& path, const std::string& text) {
  std::ofstream out(path, std::ios::binary);
  out << text;
}

// Appends the bytes of `value` (the tests run on little-endian hosts, as binary PLY expects).
template <class T>
void Put(std::string* bytes, T value) {
  bytes->append(reinterpret_cast<const char*>(&value), sizeof(value));
}

const char kLionFace003Camera[] =
    "# A contraption file with the bundle.out format in opencv reference system\n"
    "1 0\n"
    "685.376526 0.000000 0.000000\n"
    "0.655848722015 -0.173631129857 -0.734652764628 \n"
    "-0.705264970422 -0.487967693028 -0.514284796642 \n"
    "-0.269190964423 0.855417886945 -0.442488941519 \n"
    "0.296046346491 0.025023676574 3.946509478418 \n";

const char kPlanarMeta[] =
    "<model><name>poster</name><type>planar</type><faces>1</faces><dimensions>"
    "<width>0.5</width><height>0.25</height><depth>0</depth>"
    "<face><index>0</index><width>0.5</width><height>0.25</height>"
    "<oTf>OTF</oTf></face></dimensions></model>";

// kPlanarMeta with its oTf replaced.
std::string PlanarMetaWithOtf(const std::string& otf) {
  std::string text = kPlanarMeta;
  text.replace(text.find("OTF"), 3, otf);
  return text;
}

// A binary little-endian PLY: an element with a list before the vertices, three vertices with x y
// z as doubles, normals as floats and other properties of several types, then a face element.
std::string BinaryPly() {
  std::string bytes =
      "ply\nformat binary_little_endian 1.0\ncomment made by a test\n"
      "element camera 1\nproperty list uchar int ids\n"
      "element vertex 3\nproperty double x\nproperty double y\nproperty double z\n"
      "property int8 flag\nproperty float nx\nproperty float ny\nproperty float nz\n"
      "property ushort label\nproperty uchar red\nproperty int id\n"
      "element face 1\nproperty list uchar int vertex_indices\nend_header\n";
  Put<uint8_t>(&bytes, 2);
  Put<int32_t>(&bytes, 7);
  Put<int32_t>(&bytes, 8);
  for (int i = 0; i < 3; ++i) {
    Put<double>(&bytes, 0.5 + i);
    Put<double>(&bytes, -1.25 * i);
    Put<double>(&bytes, 3.0);
    Put<int8_t>(&bytes, -1);
    Put<float>(&bytes, 0);
    Put<float>(&bytes, 0);
    Put<float>(&bytes, -1);
    Put<uint16_t>(&bytes, 65535);
    Put<uint8_t>(&bytes, 200);
    Put<int32_t>(&bytes, -i);
  }
  Put<uint8_t>(&bytes, 3);
  for (int i = 0; i < 3; ++i) Put<int32_t>(&bytes, i);
  return bytes;
}

class RoboEarthTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("recog_roboearth_test_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  std::string Path(const std::string& name) const { return (dir_ / name).string(); }

  // Writes `text` under the temporary folder and returns its path.
  std::string Fixture(const std::string& name, const std::string& text) const {
    WriteText(Path(name), text);
    return Path(name);
  }

  fs::path dir_;
};

// --- Real RoboEarth models. ---

TEST_F(RoboEarthTest, ReadsTheLionCameraFromItsBundleFile) {
  RECOG_SKIP_WITHOUT_SHARED_DATA("objects/roboearth/models/lion");
  const auto camera = ReadBundleCamera(Model("lion/face_003.txt"));
  ASSERT_TRUE(camera.ok()) << camera.status().ToString();
  EXPECT_DOUBLE_EQ(camera->focal, 685.376526);
  EXPECT_EQ(camera->k1, 0);
  EXPECT_EQ(camera->k2, 0);
  const cv::Matx33d& R = camera->camera_from_object.R;
  EXPECT_DOUBLE_EQ(R(0, 0), 0.655848722015);
  EXPECT_DOUBLE_EQ(R(1, 2), -0.514284796642);
  EXPECT_DOUBLE_EQ(R(2, 1), 0.855417886945);
  EXPECT_EQ(camera->camera_from_object.t,
            cv::Vec3d(0.296046346491, 0.025023676574, 3.946509478418));
  EXPECT_NEAR(cv::determinant(R), 1, 1e-6);
}

TEST_F(RoboEarthTest, RewritingTheLionCameraReproducesItsFile) {
  RECOG_SKIP_WITHOUT_SHARED_DATA("objects/roboearth/models/lion");
  const std::string original = Model("lion/face_003.txt");
  const auto camera = ReadBundleCamera(original);
  ASSERT_TRUE(camera.ok()) << camera.status().ToString();
  ASSERT_TRUE(WriteBundleCamera(Path("face_003.txt"), *camera).ok());
  EXPECT_EQ(ReadText(Path("face_003.txt")), ReadText(original));
}

TEST_F(RoboEarthTest, ReadsTheLionSparsePointsWithNormals) {
  RECOG_SKIP_WITHOUT_SHARED_DATA("objects/roboearth/models/lion");
  const auto cloud = ReadPly(Model("lion/face_003.ply"));
  ASSERT_TRUE(cloud.ok()) << cloud.status().ToString();
  ASSERT_EQ(cloud->points.size(), 105u);
  ASSERT_EQ(cloud->normals.size(), 105u);
  EXPECT_EQ(cloud->points[0], cv::Point3f(0.281936f, 0.244814f, 0.936301f));
  EXPECT_EQ(cloud->normals[0], cv::Vec3f(0.525179f, -0.542038f, 0.656035f));
}

TEST_F(RoboEarthTest, LionDenseCloudProjectsIntoTheImageOfFace003) {
  RECOG_SKIP_WITHOUT_SHARED_DATA("objects/roboearth/models/lion");
  const auto cloud = ReadPly(Model("lion/drawing_model.ply"));
  ASSERT_TRUE(cloud.ok()) << cloud.status().ToString();
  ASSERT_EQ(cloud->points.size(), 11497u);
  ASSERT_EQ(cloud->normals.size(), 11497u);
  const auto camera = ReadBundleCamera(Model("lion/face_003.txt"));
  ASSERT_TRUE(camera.ok()) << camera.status().ToString();
  size_t inside = 0;
  for (const cv::Point3f& p : cloud->points) {
    const cv::Point3d c = camera->camera_from_object.Apply(p);
    if (c.z <= 0) continue;
    const double u = camera->focal * c.x / c.z + 320, v = camera->focal * c.y / c.z + 240;
    if (u >= 0 && u < 640 && v >= 0 && v < 480) ++inside;
  }
  EXPECT_GT(double(inside), 0.99 * double(cloud->points.size()));
}

TEST_F(RoboEarthTest, ReadsTheLionFolderWithTwentyViews) {
  RECOG_SKIP_WITHOUT_SHARED_DATA("objects/roboearth/models/lion");
  const auto folder = ReadRoboEarthFolder(Model("lion"));
  ASSERT_TRUE(folder.ok()) << folder.status().ToString();
  EXPECT_EQ(folder->meta.name, "lion");
  EXPECT_EQ(folder->meta.type, ObjectType::k3D);
  EXPECT_EQ(folder->meta.num_faces, 20);
  EXPECT_EQ(folder->meta.scale, 1);
  EXPECT_TRUE(folder->meta.faces.empty());
  ASSERT_EQ(folder->views.size(), 20u);
  for (int k = 0; k < 20; ++k) {
    const RoboEarthView& view = folder->views[k];
    char stem[16];
    std::snprintf(stem, sizeof(stem), "face_%03d", k);
    EXPECT_EQ(view.index, k);
    EXPECT_EQ(fs::path(view.image_path).filename().string(), std::string(stem) + ".png");
    EXPECT_EQ(fs::path(view.points_path).filename().string(), std::string(stem) + ".ply");
    EXPECT_GT(view.camera.focal, 0);
  }
  EXPECT_DOUBLE_EQ(folder->views[3].camera.focal, 685.376526);
  EXPECT_EQ(fs::path(folder->dense_cloud_path).filename().string(), "drawing_model.ply");
}

TEST_F(RoboEarthTest, ReadsTheBed1MetaAsOnePlanarFace) {
  RECOG_SKIP_WITHOUT_SHARED_DATA("objects/roboearth/models/bed1");
  const auto meta = ReadRoboEarthMeta(Model("bed1/meta.xml"));
  ASSERT_TRUE(meta.ok()) << meta.status().ToString();
  EXPECT_EQ(meta->name, "bed1");
  EXPECT_EQ(meta->type, ObjectType::kPlanar);
  EXPECT_EQ(meta->num_faces, 1);
  EXPECT_DOUBLE_EQ(meta->width, 0.68);
  EXPECT_DOUBLE_EQ(meta->height, 0.28);
  EXPECT_DOUBLE_EQ(meta->depth, 2);
  ASSERT_EQ(meta->faces.size(), 1u);
  const RoboEarthFace& face = meta->faces[0];
  EXPECT_EQ(face.index, 0);
  EXPECT_DOUBLE_EQ(face.width, 0.68);
  EXPECT_DOUBLE_EQ(face.height, 0.28);
  EXPECT_EQ(face.object_from_face.R, cv::Matx33d::eye());
  EXPECT_EQ(face.object_from_face.t, cv::Vec3d(0, 0, -1));
}

TEST_F(RoboEarthTest, ReadsTheBottleMetaFacesWithTheirRotations) {
  RECOG_SKIP_WITHOUT_SHARED_DATA("objects/roboearth/models/bottle1_small");
  const auto meta = ReadRoboEarthMeta(Model("bottle1_small/meta.xml"));
  ASSERT_TRUE(meta.ok()) << meta.status().ToString();
  ASSERT_EQ(meta->faces.size(), 5u);
  for (int i = 0; i < 5; ++i) EXPECT_EQ(meta->faces[i].index, i);
  // Face 1 is the right side: its x axis runs along the object's -z.
  const RigidTransform& side = meta->faces[1].object_from_face;
  EXPECT_NEAR(cv::norm(side.R - cv::Matx33d(0, 0, -1, 0, 1, 0, 1, 0, 0)), 0, 1e-12);
  EXPECT_EQ(side.t, cv::Vec3d(0.025, 0, 0));
  EXPECT_DOUBLE_EQ(meta->faces[3].height, 0.049);
}

TEST_F(RoboEarthTest, ListsAllElevenModelFolders) {
  RECOG_SKIP_WITHOUT_SHARED_DATA(kModels);
  std::set<std::string> names;
  size_t total_views = 0;
  for (const fs::directory_entry& entry : fs::directory_iterator(Model(""))) {
    if (!entry.is_directory()) continue;
    const auto folder = ReadRoboEarthFolder(entry.path().string());
    ASSERT_TRUE(folder.ok()) << folder.status().ToString();
    names.insert(entry.path().filename().string());
    size_t images = 0;
    for (const fs::directory_entry& file : fs::directory_iterator(entry.path())) {
      images += file.path().extension() == ".png";
    }
    EXPECT_EQ(folder->views.size(), images) << entry.path();
    for (const RoboEarthView& view : folder->views) EXPECT_FALSE(view.points_path.empty());
    if (folder->meta.type == ObjectType::k3D) {
      EXPECT_EQ(size_t(folder->meta.num_faces), folder->views.size()) << entry.path();
      EXPECT_FALSE(folder->dense_cloud_path.empty()) << entry.path();
    } else {
      EXPECT_EQ(folder->meta.faces.size(), size_t(folder->meta.num_faces)) << entry.path();
    }
    total_views += folder->views.size();
  }
  EXPECT_EQ(names, (std::set<std::string>{"bed1", "bio", "bottle1", "bottle1_big", "bottle1_medium",
                                          "bottle1_small", "box", "cabinet1", "cabinet_small",
                                          "lion", "van"}));
  EXPECT_EQ(total_views, 73u);
}

// --- Round trips. ---

TEST_F(RoboEarthTest, PlyRoundTripKeepsPointsAndNormalsExactly) {
  PointCloud cloud;
  cv::RNG rng(7);
  for (int i = 0; i < 500; ++i) {
    cloud.points.emplace_back(rng.uniform(-5.f, 5.f), rng.uniform(-5.f, 5.f), 1e-7f * float(i));
    cv::Vec3f n(rng.uniform(-1.f, 1.f), rng.uniform(-1.f, 1.f), 1);
    cloud.normals.push_back(n / cv::norm(n));
  }
  const std::string path = Path("cloud.ply");
  ASSERT_TRUE(WritePly(path, cloud).ok());
  EXPECT_FALSE(fs::exists(path + ".tmp"));
  const auto read = ReadPly(path);
  ASSERT_TRUE(read.ok()) << read.status().ToString();
  EXPECT_EQ(read->points, cloud.points);
  EXPECT_EQ(read->normals, cloud.normals);
}

TEST_F(RoboEarthTest, PlyRoundTripWithoutNormalsHasNoNormals) {
  PointCloud cloud;
  cloud.points = {{1, 2, 3}, {-0.5f, 0.25f, 1e6f}};
  ASSERT_TRUE(WritePly(Path("points.ply"), cloud).ok());
  EXPECT_EQ(ReadText(Path("points.ply")).find("nx"), std::string::npos);
  const auto read = ReadPly(Path("points.ply"));
  ASSERT_TRUE(read.ok()) << read.status().ToString();
  EXPECT_EQ(read->points, cloud.points);
  EXPECT_TRUE(read->normals.empty());
}

TEST_F(RoboEarthTest, WritePlyReplacesAnExistingFile) {
  PointCloud cloud;
  cloud.points = {{1, 2, 3}};
  ASSERT_TRUE(WritePly(Fixture("cloud.ply", "old contents"), cloud).ok());
  const auto read = ReadPly(Path("cloud.ply"));
  ASSERT_TRUE(read.ok()) << read.status().ToString();
  EXPECT_EQ(read->points, cloud.points);
}

TEST_F(RoboEarthTest, ReadsBinaryLittleEndianPlyWithOtherPropertiesAndElements) {
  const auto cloud = ReadPly(Fixture("binary.ply", BinaryPly()));
  ASSERT_TRUE(cloud.ok()) << cloud.status().ToString();
  ASSERT_EQ(cloud->points.size(), 3u);
  ASSERT_EQ(cloud->normals.size(), 3u);
  for (int i = 0; i < 3; ++i) {
    EXPECT_EQ(cloud->points[i], cv::Point3f(0.5f + float(i), -1.25f * float(i), 3));
    EXPECT_EQ(cloud->normals[i], cv::Vec3f(0, 0, -1));
  }
}

TEST_F(RoboEarthTest, ReadsAsciiPlySkippingAnElementBeforeTheVertices) {
  const auto cloud =
      ReadPly(Fixture("ascii.ply",
                      "ply\r\nformat ascii 1.0\r\nobj_info test\r\n"
                      "element camera 2\r\nproperty list uchar float k\r\n"
                      "element vertex 2\r\nproperty uchar red\r\nproperty float z\r\n"
                      "property float y\r\nproperty int16 id\r\nproperty float x\r\n"
                      "element face 1\r\nproperty list uchar int vertex_indices\r\n"
                      "end_header\r\n"
                      "2 0.5 1.5\r\n0\r\n"
                      "255 3 2 -7 1\r\n"
                      "0\t-3e-2  4 32767 -1.5e1\r\n"
                      "this face line is never read\r\n"));
  ASSERT_TRUE(cloud.ok()) << cloud.status().ToString();
  EXPECT_EQ(cloud->points, (std::vector<cv::Point3f>{{1, 2, 3}, {-15, 4, -0.03f}}));
  EXPECT_TRUE(cloud->normals.empty());
}

TEST_F(RoboEarthTest, BundleCameraRoundTripKeepsTheValues) {
  BundleCamera camera;
  camera.focal = 512.125;
  camera.k1 = -0.125;
  camera.k2 = 0.0625;
  cv::Matx33d R;
  cv::Rodrigues(cv::Vec3d(0.3, -1.2, 0.7), R);
  camera.camera_from_object.R = R;
  camera.camera_from_object.t = {0.1, -0.2, 2.5};
  const std::string path = Path("camera.txt");
  ASSERT_TRUE(WriteBundleCamera(path, camera).ok());
  EXPECT_TRUE(ReadText(path).starts_with(
      "# A contraption file with the bundle.out format in opencv reference system\n1 0\n"));
  const auto read = ReadBundleCamera(path);
  ASSERT_TRUE(read.ok()) << read.status().ToString();
  EXPECT_EQ(read->focal, camera.focal);
  EXPECT_EQ(read->k1, camera.k1);
  EXPECT_EQ(read->k2, camera.k2);
  EXPECT_LT(cv::norm(read->camera_from_object.R - R, cv::NORM_INF), 1e-12);
  EXPECT_LT(cv::norm(read->camera_from_object.t - camera.camera_from_object.t, cv::NORM_INF),
            1e-12);
}

TEST_F(RoboEarthTest, MetaRoundTripOf3DModel) {
  RoboEarthMeta meta;
  meta.name = "lion";
  meta.type = ObjectType::k3D;
  meta.num_faces = 20;
  meta.scale = 0.37;
  ASSERT_TRUE(WriteRoboEarthMeta(Path("meta.xml"), meta).ok());
  const auto read = ReadRoboEarthMeta(Path("meta.xml"));
  ASSERT_TRUE(read.ok()) << read.status().ToString();
  EXPECT_EQ(read->name, "lion");
  EXPECT_EQ(read->type, ObjectType::k3D);
  EXPECT_EQ(read->num_faces, 20);
  EXPECT_EQ(read->scale, 0.37);
  EXPECT_TRUE(read->faces.empty());
}

TEST_F(RoboEarthTest, MetaRoundTripOfPlanarModelKeepsTheFaces) {
  RoboEarthMeta meta;
  meta.name = "box";
  meta.type = ObjectType::kPlanar;
  meta.num_faces = 2;
  meta.width = 0.3;
  meta.height = 0.2;
  meta.depth = 0.1;
  RoboEarthFace front{0, 0.3, 0.2, {}};
  front.object_from_face.t = {0, 0, -0.05};
  RoboEarthFace side{1, 0.1, 0.2, {}};
  cv::Rodrigues(cv::Vec3d(0, CV_PI / 2, 0), side.object_from_face.R);
  side.object_from_face.t = {0.15, 0, 0};
  meta.faces = {front, side};
  ASSERT_TRUE(WriteRoboEarthMeta(Path("meta.xml"), meta).ok());
  EXPECT_FALSE(fs::exists(Path("meta.xml.tmp")));
  const auto read = ReadRoboEarthMeta(Path("meta.xml"));
  ASSERT_TRUE(read.ok()) << read.status().ToString();
  EXPECT_EQ(read->type, ObjectType::kPlanar);
  EXPECT_EQ(read->width, 0.3);
  EXPECT_EQ(read->height, 0.2);
  EXPECT_EQ(read->depth, 0.1);
  ASSERT_EQ(read->faces.size(), 2u);
  for (size_t i = 0; i < 2; ++i) {
    EXPECT_EQ(read->faces[i].index, meta.faces[i].index);
    EXPECT_EQ(read->faces[i].width, meta.faces[i].width);
    EXPECT_EQ(read->faces[i].height, meta.faces[i].height);
    EXPECT_EQ(read->faces[i].object_from_face.R, meta.faces[i].object_from_face.R);
    EXPECT_EQ(read->faces[i].object_from_face.t, meta.faces[i].object_from_face.t);
  }
}

TEST_F(RoboEarthTest, MetaFacesAreSortedByIndex) {
  const auto meta = ReadRoboEarthMeta(
      Fixture("meta.xml",
              "<model><name>p</name><type>planar</type><faces>2</faces><dimensions>"
              "<width>1</width><height>1</height><depth>1</depth>"
              "<face><index>5</index><width>1</width><height>1</height>"
              "<oTf>1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1</oTf></face>"
              "<face><index>2</index><width>2</width><height>1</height>"
              "<oTf>\n 1 0 0 0\n 0 1 0 0\n 0 0 1 0.5\n 0 0 0 1\n</oTf></face>"
              "</dimensions></model>"));
  ASSERT_TRUE(meta.ok()) << meta.status().ToString();
  ASSERT_EQ(meta->faces.size(), 2u);
  EXPECT_EQ(meta->faces[0].index, 2);
  EXPECT_EQ(meta->faces[0].width, 2);
  EXPECT_EQ(meta->faces[0].object_from_face.t, cv::Vec3d(0, 0, 0.5));
  EXPECT_EQ(meta->faces[1].index, 5);
}

// --- Failures. ---

TEST_F(RoboEarthTest, MissingFilesAndFoldersAreNotFound) {
  EXPECT_EQ(ReadPly(Path("none.ply")).status().code(), StatusCode::kNotFound);
  EXPECT_EQ(ReadBundleCamera(Path("none.txt")).status().code(), StatusCode::kNotFound);
  EXPECT_EQ(ReadRoboEarthMeta(Path("meta.xml")).status().code(), StatusCode::kNotFound);
  EXPECT_EQ(ReadRoboEarthFolder(Path("none")).status().code(), StatusCode::kNotFound);
  // A folder without meta.xml.
  const auto folder = ReadRoboEarthFolder(dir_.string());
  EXPECT_EQ(folder.status().code(), StatusCode::kNotFound);
  EXPECT_NE(folder.status().message().find("meta.xml"), std::string::npos);
}

TEST_F(RoboEarthTest, TruncatedAsciiPlyIsDataLossNamingTheFileAndLine) {
  const std::string header =
      "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
      "property float z\nend_header\n";
  const std::string path = Fixture("short.ply", header + "1 2 3\n4 5 6\n");
  const Status missing_line = ReadPly(path).status();
  EXPECT_EQ(missing_line.code(), StatusCode::kDataLoss);
  EXPECT_NE(missing_line.message().find(path), std::string::npos);
  EXPECT_NE(missing_line.message().find("line 9"), std::string::npos) << missing_line.message();
  const Status short_line = ReadPly(Fixture("cut.ply", header + "1 2 3\n4 5 6\n7 8")).status();
  EXPECT_EQ(short_line.code(), StatusCode::kDataLoss);
  EXPECT_NE(short_line.message().find("line 10"), std::string::npos) << short_line.message();
  const Status no_end = ReadPly(Fixture("header.ply", "ply\nformat ascii 1.0\n")).status();
  EXPECT_EQ(no_end.code(), StatusCode::kDataLoss);
  EXPECT_NE(no_end.message().find("end_header"), std::string::npos);
}

TEST_F(RoboEarthTest, AVertexCountBeyondTheFileIsDataLoss) {
  const Status ascii = ReadPly(Fixture("huge.ply",
                                       "ply\nformat ascii 1.0\nelement vertex 4000000000\n"
                                       "property float x\nproperty float y\nproperty float z\n"
                                       "end_header\n1 2 3\n"))
                           .status();
  EXPECT_EQ(ascii.code(), StatusCode::kDataLoss);
  const Status binary = ReadPly(Fixture("huge_binary.ply",
                                        "ply\nformat binary_little_endian 1.0\n"
                                        "element vertex 4000000000\nproperty float x\n"
                                        "property float y\nproperty float z\nend_header\n"
                                        "0123456789AB"))
                            .status();
  EXPECT_EQ(binary.code(), StatusCode::kDataLoss);
}

TEST_F(RoboEarthTest, TruncatedBinaryPlyIsDataLoss) {
  const std::string full = BinaryPly();
  const size_t header_end = full.find("end_header\n") + std::strlen("end_header\n");
  // Cut in the middle of the second vertex (the camera element takes 9 bytes, a vertex 44).
  const std::string path = Fixture("cut.ply", full.substr(0, header_end + 9 + 44 + 20));
  const Status status = ReadPly(path).status();
  EXPECT_EQ(status.code(), StatusCode::kDataLoss);
  EXPECT_NE(status.message().find(path), std::string::npos);
  EXPECT_NE(status.message().find("truncated"), std::string::npos);
  // A list whose size runs past the end of the file.
  std::string bad_list = full.substr(0, header_end);
  Put<uint8_t>(&bad_list, 200);
  EXPECT_EQ(ReadPly(Fixture("list.ply", bad_list)).status().code(), StatusCode::kDataLoss);
}

TEST_F(RoboEarthTest, GarbageNumbersInAsciiPlyAreDataLoss) {
  const std::string header =
      "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n"
      "property float z\nend_header\n";
  const Status garbage = ReadPly(Fixture("garbage.ply", header + "1 2 3\n4 five 6\n")).status();
  EXPECT_EQ(garbage.code(), StatusCode::kDataLoss);
  EXPECT_NE(garbage.message().find("line 9"), std::string::npos) << garbage.message();
  EXPECT_NE(garbage.message().find("'five'"), std::string::npos) << garbage.message();
  const Status extra = ReadPly(Fixture("extra.ply", header + "1 2 3 4\n4 5 6\n")).status();
  EXPECT_EQ(extra.code(), StatusCode::kDataLoss);
  const Status bad_count =
      ReadPly(Fixture("count.ply", "ply\nformat ascii 1.0\nelement vertex many\nend_header\n"))
          .status();
  EXPECT_EQ(bad_count.code(), StatusCode::kDataLoss);
  EXPECT_NE(bad_count.message().find("line 3"), std::string::npos) << bad_count.message();
  const Status bad_type = ReadPly(Fixture("type.ply",
                                          "ply\nformat ascii 1.0\nelement vertex 1\n"
                                          "property float128 x\nend_header\n1\n"))
                              .status();
  EXPECT_EQ(bad_type.code(), StatusCode::kDataLoss);
  EXPECT_EQ(ReadPly(Fixture("text.ply", "hello\n")).status().code(), StatusCode::kDataLoss);
}

TEST_F(RoboEarthTest, PlyWithoutVerticesOrCoordinatesIsInvalidArgument) {
  EXPECT_EQ(ReadPly(Fixture("faces.ply",
                            "ply\nformat ascii 1.0\nelement face 0\n"
                            "property list uchar int vertex_indices\nend_header\n"))
                .status()
                .code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(ReadPly(Fixture("xy.ply",
                            "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n"
                            "property float y\nend_header\n1 2\n"))
                .status()
                .code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(ReadPly(Fixture("big.ply",
                            "ply\nformat binary_big_endian 1.0\nelement vertex 0\n"
                            "property float x\nproperty float y\nproperty float z\nend_header\n"))
                .status()
                .code(),
            StatusCode::kInvalidArgument);
}

TEST_F(RoboEarthTest, WritePlyRejectsNormalsThatDoNotMatchThePoints) {
  PointCloud cloud;
  cloud.points = {{0, 0, 1}, {0, 1, 0}};
  cloud.normals.push_back(cv::Vec3f(0, 0, 1));
  EXPECT_EQ(WritePly(Path("bad.ply"), cloud).code(), StatusCode::kInvalidArgument);
  EXPECT_FALSE(fs::exists(Path("bad.ply")));
}

TEST_F(RoboEarthTest, BundleCameraWithGarbageOrMissingNumbersIsDataLoss) {
  std::string garbage = kLionFace003Camera;
  garbage.replace(garbage.find("685.376526"), 10, "685.37x526");
  const std::string path = Fixture("garbage.txt", garbage);
  const Status status = ReadBundleCamera(path).status();
  EXPECT_EQ(status.code(), StatusCode::kDataLoss);
  EXPECT_NE(status.message().find(path), std::string::npos);
  EXPECT_NE(status.message().find("line 3"), std::string::npos) << status.message();

  const std::string full = kLionFace003Camera;
  const std::string cut = full.substr(0, full.find("-0.269190964423"));
  EXPECT_EQ(ReadBundleCamera(Fixture("cut.txt", cut)).status().code(), StatusCode::kDataLoss);
  std::string short_row = full;
  short_row.replace(short_row.find(" 3.946509478418"), 15, "");
  EXPECT_EQ(ReadBundleCamera(Fixture("row.txt", short_row)).status().code(), StatusCode::kDataLoss);
  EXPECT_EQ(
      ReadBundleCamera(Fixture("nocomment.txt", full.substr(full.find('\n') + 1))).status().code(),
      StatusCode::kDataLoss);
  std::string infinite = full;
  infinite.replace(infinite.find("0.296046346491"), 14, "inf");
  EXPECT_EQ(ReadBundleCamera(Fixture("inf.txt", infinite)).status().code(),
            StatusCode::kInvalidArgument);
}

TEST_F(RoboEarthTest, BundleCameraWhoseRIsNotARotationIsInvalidArgument) {
  std::string scaled = kLionFace003Camera;
  scaled.replace(scaled.find("0.655848722015"), 14, "1.655848722015");
  const std::string path = Fixture("scaled.txt", scaled);
  const Status status = ReadBundleCamera(path).status();
  EXPECT_EQ(status.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(status.message().find(path), std::string::npos);
  EXPECT_NE(status.message().find("rotation"), std::string::npos);

  const std::string reflection = "# mirror\n1 0\n500 0 0\n-1 0 0\n0 1 0\n0 0 1\n0 0 2\n";
  EXPECT_EQ(ReadBundleCamera(Fixture("mirror.txt", reflection)).status().code(),
            StatusCode::kInvalidArgument);

  BundleCamera camera;
  camera.focal = 500;
  camera.camera_from_object.R = cv::Matx33d(1, 0, 0, 0, 2, 0, 0, 0, 1);
  EXPECT_EQ(WriteBundleCamera(Path("bad.txt"), camera).code(), StatusCode::kInvalidArgument);
  EXPECT_FALSE(fs::exists(Path("bad.txt")));
}

TEST_F(RoboEarthTest, MetaWithoutNameIsInvalidArgumentNamingTheElement) {
  const std::string path = Fixture(
      "meta.xml",
      "<model><type>3D</type><faces>2</faces><dimensions><scale>1</scale></dimensions></model>");
  const Status status = ReadRoboEarthMeta(path).status();
  EXPECT_EQ(status.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(status.message().find(path), std::string::npos);
  EXPECT_NE(status.message().find("<name>"), std::string::npos) << status.message();
}

TEST_F(RoboEarthTest, MetaWithMissingOrBadValuesIsInvalidArgument) {
  const auto code = [&](const std::string& text) {
    return ReadRoboEarthMeta(Fixture("meta.xml", text)).status().code();
  };
  const Status no_scale =
      ReadRoboEarthMeta(
          Fixture("scale.xml",
                  "<model><name>a</name><type>3D</type><faces>1</faces><dimensions/></model>"))
          .status();
  EXPECT_EQ(no_scale.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(no_scale.message().find("<scale>"), std::string::npos) << no_scale.message();
  EXPECT_EQ(code("<model><name>a</name><type>sphere</type><faces>1</faces>"
                 "<dimensions><scale>1</scale></dimensions></model>"),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(code("<model><name>a</name><type>3D</type><faces>x</faces>"
                 "<dimensions><scale>1</scale></dimensions></model>"),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(code("<other/>"), StatusCode::kInvalidArgument);
  EXPECT_EQ(code(PlanarMetaWithOtf("1 0 0 0 0 1 0 0 0 0 1 0")), StatusCode::kInvalidArgument);
  EXPECT_EQ(code(PlanarMetaWithOtf("1 0 0 0 0 1 0 0 0 0 1 0 0 0 1 1")),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(code(PlanarMetaWithOtf("2 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1")),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(code(PlanarMetaWithOtf("1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1")
                     .replace(std::strlen("<model><name>poster</name><type>planar</type><faces>"),
                              1, "2")),
            StatusCode::kInvalidArgument);
  std::string negative_index = PlanarMetaWithOtf("1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1");
  negative_index.replace(negative_index.find("<index>0"), 8, "<index>-1");
  EXPECT_EQ(code(negative_index), StatusCode::kInvalidArgument);
  EXPECT_EQ(code(PlanarMetaWithOtf("1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1")), StatusCode::kOk);
}

TEST_F(RoboEarthTest, MalformedMetaXmlIsDataLoss) {
  const Status status =
      ReadRoboEarthMeta(Fixture("meta.xml", "<model><name>lion</name>\n<type>3D</model>")).status();
  EXPECT_EQ(status.code(), StatusCode::kDataLoss);
  EXPECT_NE(status.message().find("meta.xml"), std::string::npos);
}

TEST_F(RoboEarthTest, WriteMetaRejectsAnInvalidMeta) {
  RoboEarthMeta meta;
  meta.type = ObjectType::k3D;
  EXPECT_EQ(WriteRoboEarthMeta(Path("meta.xml"), meta).code(), StatusCode::kInvalidArgument);
  meta.name = "flat";
  meta.type = ObjectType::kPlanar;
  meta.num_faces = 1;
  meta.width = meta.height = 1;
  EXPECT_EQ(WriteRoboEarthMeta(Path("meta.xml"), meta).code(), StatusCode::kInvalidArgument);
  EXPECT_FALSE(fs::exists(Path("meta.xml")));
}

TEST_F(RoboEarthTest, FolderWithoutViewsIsInvalidArgument) {
  Fixture("meta.xml", PlanarMetaWithOtf("1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1"));
  Fixture("face_000.png", "not really a png");
  Fixture("face_000.ply", "");
  const Status status = ReadRoboEarthFolder(dir_.string()).status();
  EXPECT_EQ(status.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(status.message().find(dir_.string()), std::string::npos);
}

TEST_F(RoboEarthTest, FolderSkipsViewsWithoutCameraAndSortsThemNumerically) {
  Fixture("meta.xml", PlanarMetaWithOtf("1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1"));
  for (const char* stem : {"face_10", "face_2", "face_7"}) Fixture(std::string(stem) + ".png", "");
  Fixture("face_10.txt", kLionFace003Camera);
  Fixture("face_2.txt", "# fake\n1 0\n600 0 0\n1 0 0\n0 1 0\n0 0 1\n0 0 2\n");
  Fixture("face_2.ply", "");
  Fixture("face_x.png", "");
  Fixture("notes.txt", "");
  const auto folder = ReadRoboEarthFolder(dir_.string());
  ASSERT_TRUE(folder.ok()) << folder.status().ToString();
  EXPECT_EQ(folder->path, dir_.string());
  EXPECT_EQ(folder->meta.name, "poster");
  ASSERT_EQ(folder->views.size(), 2u);
  EXPECT_EQ(folder->views[0].index, 2);
  EXPECT_EQ(folder->views[0].image_path, Path("face_2.png"));
  EXPECT_EQ(folder->views[0].points_path, Path("face_2.ply"));
  EXPECT_EQ(folder->views[0].camera.focal, 600);
  EXPECT_EQ(folder->views[0].camera.camera_from_object.t, cv::Vec3d(0, 0, 2));
  EXPECT_EQ(folder->views[1].index, 10);
  EXPECT_TRUE(folder->views[1].points_path.empty());
  EXPECT_DOUBLE_EQ(folder->views[1].camera.focal, 685.376526);
  EXPECT_TRUE(folder->dense_cloud_path.empty());
}

TEST_F(RoboEarthTest, FolderWithABadCameraReportsTheCameraFile) {
  Fixture("meta.xml", PlanarMetaWithOtf("1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1"));
  Fixture("face_000.png", "");
  Fixture("face_000.txt", "# broken\n1 0\n");
  Fixture("drawing_model.ply", "");
  const Status status = ReadRoboEarthFolder(dir_.string()).status();
  EXPECT_EQ(status.code(), StatusCode::kDataLoss);
  EXPECT_NE(status.message().find("face_000.txt"), std::string::npos) << status.message();
}

// --- Export. ---

cv::Mat PosterImage() { return cv::imread(testing::ProjectTestData("corridor/1.jpg")); }

// A 3D model RoboEarth can hold: a 1 x 0.75 m poster at z = 2 m, seen by one camera at the origin
// whose principal point is the image centre.
const ObjectModel& PosedPoster() {
  static const ObjectModel model = [] {
    const cv::Mat image = PosterImage();
    const PosedImage view{
        "frame", image, {500, 500, image.cols / 2.0, image.rows / 2.0, {}}, RigidTransform()};
    const FacePolygon face{
        {{-0.5, -0.375, 2}, {0.5, -0.375, 2}, {0.5, 0.375, 2}, {-0.5, 0.375, 2}}};
    auto built = ModelBuilder(testing::BundledObjectVocabulary())
                     .FromPosedPolygons("poster", {face}, {view});
    EXPECT_TRUE(built.ok()) << built.status().ToString();
    return std::move(*built);
  }();
  return model;
}

TEST_F(RoboEarthTest, ExportedModelReadsBackAsTheSameObject) {
  const ObjectModel& model = PosedPoster();
  ASSERT_GT(model.points.size(), 50u);
  const std::string dir = Path("poster");
  ASSERT_TRUE(ExportRoboEarthFolder(model, dir).ok());

  const auto folder = ReadRoboEarthFolder(dir);
  ASSERT_TRUE(folder.ok()) << folder.status().ToString();
  EXPECT_EQ(folder->meta.name, "poster");
  EXPECT_EQ(folder->meta.type, ObjectType::k3D);
  EXPECT_EQ(folder->meta.num_faces, 1);
  EXPECT_EQ(folder->meta.scale, 1);
  ASSERT_EQ(folder->views.size(), 1u);
  EXPECT_EQ(folder->views[0].image_path, (fs::path(dir) / "face_000.png").string());
  EXPECT_EQ(folder->views[0].camera.focal, 500);
  EXPECT_EQ(folder->views[0].camera.camera_from_object.R, cv::Matx33d::eye());
  EXPECT_EQ(folder->views[0].camera.camera_from_object.t, cv::Vec3d(0, 0, 0));
  ASSERT_FALSE(folder->dense_cloud_path.empty());
  const auto dense = ReadPly(folder->dense_cloud_path);
  ASSERT_TRUE(dense.ok()) << dense.status().ToString();
  EXPECT_EQ(dense->points, model.points);
  // The whole poster is in view, so the view sees every point.
  const auto seen = ReadPly(folder->views[0].points_path);
  ASSERT_TRUE(seen.ok()) << seen.status().ToString();
  EXPECT_EQ(seen->points.size(), model.points.size());

  auto rebuilt = ModelBuilder(testing::BundledObjectVocabulary()).FromRoboEarth(dir);
  ASSERT_TRUE(rebuilt.ok()) << rebuilt.status().ToString();
  EXPECT_EQ(rebuilt->metadata.name, "poster");
  EXPECT_EQ(rebuilt->metadata.type, ObjectType::k3D);
  ASSERT_EQ(rebuilt->views.size(), 1u);
  EXPECT_EQ(rebuilt->views[0].camera, model.views[0].camera);
  EXPECT_EQ(rebuilt->views[0].camera_from_object.t, cv::Vec3d(0, 0, 0));
  // The same image gives the same keypoints, which find their points again.
  EXPECT_GT(rebuilt->num_features(), model.num_features() / 2);
}

TEST_F(RoboEarthTest, ExportIntoAnEmptyFolderIsFine) {
  fs::create_directories(Path("empty"));
  EXPECT_TRUE(ExportRoboEarthFolder(PosedPoster(), Path("empty")).ok());
  EXPECT_TRUE(fs::exists(Path("empty/face_000.txt")));
}

TEST_F(RoboEarthTest, ExportIntoANonEmptyFolderIsAlreadyExistsAndTouchesNothing) {
  Fixture("notes.txt", "keep me");
  EXPECT_EQ(ExportRoboEarthFolder(PosedPoster(), dir_.string()).code(), StatusCode::kAlreadyExists);
  EXPECT_EQ(ExportRoboEarthFolder(PosedPoster(), Path("notes.txt")).code(),
            StatusCode::kAlreadyExists);
  EXPECT_FALSE(fs::exists(Path("meta.xml")));
  EXPECT_EQ(ReadText(Path("notes.txt")), "keep me");
}

TEST_F(RoboEarthTest, ExportWithoutViewsOrImagesIsFailedPrecondition) {
  ObjectModel model = PosedPoster();
  model.views[0].image_png.clear();
  const Status no_image = ExportRoboEarthFolder(model, Path("out"));
  EXPECT_EQ(no_image.code(), StatusCode::kFailedPrecondition);
  EXPECT_NE(no_image.message().find("view 0 ('frame')"), std::string::npos) << no_image.message();
  model.views.clear();
  EXPECT_EQ(ExportRoboEarthFolder(model, Path("out")).code(), StatusCode::kFailedPrecondition);
  EXPECT_FALSE(fs::exists(Path("out")));
}

TEST_F(RoboEarthTest, ExportOfACameraRoboEarthCannotExpressIsInvalidArgumentNamingTheView) {
  ObjectModel model = PosedPoster();
  model.views[0].camera.cx += 0.4;  // within half a pixel: fine
  EXPECT_TRUE(ExportRoboEarthFolder(model, Path("nearly")).ok());

  model.views[0].camera.cx += 10;
  Status status = ExportRoboEarthFolder(model, Path("out"));
  EXPECT_EQ(status.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(status.message().find("view 0 ('frame')"), std::string::npos) << status.message();
  EXPECT_NE(status.message().find("principal point"), std::string::npos) << status.message();

  model = PosedPoster();
  model.views[0].camera.fy = 520;
  status = ExportRoboEarthFolder(model, Path("out"));
  EXPECT_EQ(status.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(status.message().find("focal length"), std::string::npos) << status.message();

  model = PosedPoster();
  model.views[0].camera.distortion = {0.1, 0, 0, 0};
  EXPECT_EQ(ExportRoboEarthFolder(model, Path("out")).code(), StatusCode::kInvalidArgument);
  EXPECT_FALSE(fs::exists(Path("out")));
}

TEST_F(RoboEarthTest, ExportOfAFaceImagePosterIsInvalidArgument) {
  // Its views are frontal cameras with the principal point at the image corner.
  auto poster = ModelBuilder(testing::BundledObjectVocabulary())
                    .FromFaceImages("poster", {{BoxSide::kFront, PosterImage()}}, 0.64, 0.48);
  ASSERT_TRUE(poster.ok()) << poster.status().ToString();
  const Status status = ExportRoboEarthFolder(*poster, Path("out"));
  EXPECT_EQ(status.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(status.message().find("principal point"), std::string::npos) << status.message();
}

TEST_F(RoboEarthTest, ExportedPlanarModelKeepsItsFacesInTheMeta) {
  // A planar model whose view is a centred camera looking at its single face.
  ObjectModel model = PosedPoster();
  model.metadata.type = ObjectType::kPlanar;
  model.metadata.dimensions = {1, 0.75, 0};
  PlanarFace face;
  face.width = 1;
  face.height = 0.75;
  face.object_from_face.t = {-0.5, -0.375, 2};
  model.faces = {face};
  model.face_of_point.assign(model.points.size(), 0);
  ASSERT_TRUE(ExportRoboEarthFolder(model, Path("planar")).ok());
  const auto meta = ReadRoboEarthMeta(Path("planar/meta.xml"));
  ASSERT_TRUE(meta.ok()) << meta.status().ToString();
  EXPECT_EQ(meta->type, ObjectType::kPlanar);
  EXPECT_EQ(meta->width, 1);
  EXPECT_EQ(meta->height, 0.75);
  ASSERT_EQ(meta->faces.size(), 1u);
  EXPECT_EQ(meta->faces[0].object_from_face.t, cv::Vec3d(-0.5, -0.375, 2));

  auto rebuilt = ModelBuilder(testing::BundledObjectVocabulary()).FromRoboEarth(Path("planar"));
  ASSERT_TRUE(rebuilt.ok()) << rebuilt.status().ToString();
  EXPECT_EQ(rebuilt->metadata.type, ObjectType::kPlanar);
  ASSERT_EQ(rebuilt->faces.size(), 1u);
  // The face comes back as the bounding box of the model's points on it.
  EXPECT_NEAR(rebuilt->faces[0].object_from_face.t[2], 2, 1e-3);
  EXPECT_LE(rebuilt->faces[0].width, 1 + 1e-3);
  EXPECT_GT(rebuilt->num_features(), 0u);
}

}  // namespace
}  // namespace recog
