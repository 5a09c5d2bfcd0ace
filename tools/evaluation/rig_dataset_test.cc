// Rig sequences on disk: the plain, EuRoC and KITTI layouts read back with their cameras and
// frames, and faulty ones refused with the code and the name of what is wrong.
#include "tools/evaluation/rig_dataset.h"

#include <filesystem>

#include <gtest/gtest.h>

#include "tools/evaluation/rig_file.h"
#include "tools/evaluation/test_folder.h"

namespace recog::cli {
namespace {

namespace fs = std::filesystem;

using testing::ExpectError;

// Fixtures of 64x48 images, the size of the rig's cameras.
class Folder : public testing::TestFolder {
 public:
  explicit Folder(const std::string& name) : TestFolder("rig_dataset_" + name, {64, 48}) {}
};

// A front camera at the body origin and a rear one 0.4 m behind it, turned round.
std::vector<RigCamera> FrontAndRear() {
  RigCamera front;
  front.name = "front";
  front.size = {64, 48};
  front.K = {50, 0, 31.5, 0, 50, 23.5, 0, 0, 1};
  RigCamera rear = front;
  rear.name = "rear";
  rear.body_R_camera = {-1, 0, 0, 0, 1, 0, 0, 0, -1};
  rear.body_t_camera = {0, 0, -0.4};
  return {front, rear};
}

// Writes the plain layout of FrontAndRear with `frames` images per camera in plain folders.
void WritePlainFolders(const Folder& dir, int front_frames, int rear_frames) {
  ASSERT_TRUE(WriteRigFile(FrontAndRear(), dir / "rig.yaml").ok());
  for (int i = 0; i < front_frames; ++i) dir.Png("front/" + std::to_string(i * 5) + ".png");
  for (int i = 0; i < rear_frames; ++i) dir.Png("rear/" + std::to_string(i * 5) + ".png");
}

TEST(RigDatasetTest, PlainTumCamerasGiveTimestampsAndDepths) {
  Folder dir("plain_tum");
  ASSERT_TRUE(WriteRigFile(FrontAndRear(), dir / "rig.yaml").ok());
  for (const char* camera : {"front", "rear"}) {
    for (const char* name : {"rgb/0.png", "rgb/1.png", "rgb/2.png"}) {
      dir.Png(std::string(camera) + "/" + name);
    }
    dir.Text(
        std::string(camera) + "/rgb.txt",
        "# timestamp filename\n10.000000 rgb/0.png\n10.500000 rgb/1.png\n11.000000 rgb/2.png\n");
  }
  // Only the front camera has depth, and none near its second frame.
  dir.Png("front/depth/0.png");
  dir.Png("front/depth/2.png");
  dir.Text("front/depth.txt", "10.005000 depth/0.png\n11.000000 depth/2.png\n");

  auto layout = DetectRigLayout(dir.path());
  ASSERT_TRUE(layout.ok()) << layout.status().ToString();
  EXPECT_EQ(*layout, RigLayout::kPlain);
  auto rig = ReadRigDataset(dir.path());
  ASSERT_TRUE(rig.ok()) << rig.status().ToString();
  EXPECT_EQ(rig->layout, RigLayout::kPlain);
  ASSERT_EQ(rig->cameras.size(), 2u);
  EXPECT_EQ(rig->cameras[0].name, "front");
  EXPECT_EQ(rig->cameras[1].name, "rear");
  EXPECT_EQ(rig->cameras[1].K, FrontAndRear()[1].K);
  EXPECT_EQ(rig->cameras[1].body_R_camera, FrontAndRear()[1].body_R_camera);
  EXPECT_EQ(rig->cameras[1].body_t_camera, cv::Vec3d(0, 0, -0.4));
  EXPECT_EQ(rig->timestamps, (std::vector<std::optional<double>>{10.0, 10.5, 11.0}));
  ASSERT_EQ(rig->images.size(), 3u);
  ASSERT_EQ(rig->depths.size(), 3u);
  EXPECT_EQ(rig->images[1],
            (std::vector<std::string>{dir / "front/rgb/1.png", dir / "rear/rgb/1.png"}));
  EXPECT_EQ(rig->depths[0], (std::vector<std::string>{dir / "front/depth/0.png", ""}));
  EXPECT_EQ(rig->depths[1], (std::vector<std::string>{"", ""}));
  EXPECT_EQ(rig->depths[2], (std::vector<std::string>{dir / "front/depth/2.png", ""}));
}

TEST(RigDatasetTest, PlainLayoutReadsFromItsFolderOrItsRigFile) {
  Folder dir("plain_folders");
  WritePlainFolders(dir, 3, 3);
  for (const std::string& path : {dir.path(), dir / "rig.yaml"}) {
    SCOPED_TRACE(path);
    auto layout = DetectRigLayout(path);
    ASSERT_TRUE(layout.ok()) << layout.status().ToString();
    EXPECT_EQ(*layout, RigLayout::kPlain);
    auto rig = ReadRigDataset(path);
    ASSERT_TRUE(rig.ok()) << rig.status().ToString();
    ASSERT_EQ(rig->cameras.size(), 2u);
    EXPECT_EQ(rig->cameras[0].size, cv::Size(64, 48));
    // Plain folders have no timestamps and no depth; images in natural order (5 before 10).
    EXPECT_EQ(rig->timestamps, (std::vector<std::optional<double>>(3, std::nullopt)));
    ASSERT_EQ(rig->images.size(), 3u);
    EXPECT_EQ(rig->images[1], (std::vector<std::string>{dir / "front/5.png", dir / "rear/5.png"}));
    EXPECT_EQ(rig->images[2][0], dir / "front/10.png");
    for (const auto& depths : rig->depths) EXPECT_EQ(depths, (std::vector<std::string>{"", ""}));
  }
}

TEST(RigDatasetTest, PlainCamerasWithDifferentFrameCountsAreRefused) {
  Folder dir("plain_counts");
  WritePlainFolders(dir, 3, 2);
  auto rig = ReadRigDataset(dir.path());
  ExpectError(rig, StatusCode::kInvalidArgument, "'rear'");
  ExpectError(rig, StatusCode::kInvalidArgument, "has 2 frames");
}

TEST(RigDatasetTest, PlainMissingCameraFolderIsNotFound) {
  Folder dir("plain_missing");
  WritePlainFolders(dir, 2, 0);
  auto rig = ReadRigDataset(dir / "rig.yaml");
  ExpectError(rig, StatusCode::kNotFound, "rig camera 'rear'");
  ExpectError(rig, StatusCode::kNotFound, dir / "rear");
}

// EuRoC MAV sensor.yaml as the dataset has it (OpenCV's "%YAML:1.0" first), with T_BS's data.
std::string EurocSensor(const std::string& t_bs_data, const std::string& intrinsics,
                        const std::string& distortion,
                        const std::string& model = "radial-tangential") {
  return "%YAML:1.0\n---\n# General sensor definitions.\nsensor_type: camera\n"
         "comment: VI-Sensor cam (MT9M034)\n\n# Sensor extrinsics wrt. the body-frame.\n"
         "T_BS:\n  cols: 4\n  rows: 4\n  data: [" +
         t_bs_data +
         "]\n\n# Camera specific definitions.\nrate_hz: 20\nresolution: [752, 480]\n"
         "camera_model: pinhole\nintrinsics: [" +
         intrinsics + "] #fu, fv, cu, cv\ndistortion_model: " + model +
         "\ndistortion_coefficients: [" + distortion + "]\n";
}

// cam0: EuRoC's own (camera x along body -y...). cam1: nearly the body's axes, its rotation
// printed to 6 digits (|R Rᵀ - I| = 1.5e-6, more than ValidateRig allows).
const char* kCam0Pose =
    "0.0148655429818, -0.999880929698, 0.00414029679422, -0.0216401454975,\n"
    "         0.999557249008, 0.0149672133247, 0.025715529948, -0.064676986768,\n"
    "        -0.0257744366974, 0.00375618835797, 0.999660727178, 0.00981073058949,\n"
    "         0.0, 0.0, 0.0, 1.0";
const char* kCam1Pose =
    "0.999708, -0.012355, -0.02079, -0.0198436,\n"
    "         0.011997, 0.999779, -0.01725, 0.0603,\n"
    "         0.020998, 0.016995, 0.999635, 0.0008,\n"
    "         0.0, 0.0, 0.0, 1.0";

class RigDatasetEurocTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_.Text("mav0/cam0/sensor.yaml",
              EurocSensor(kCam0Pose, "458.654, 457.296, 367.215, 248.375",
                          "-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05"));
    dir_.Text("mav0/cam1/sensor.yaml",
              EurocSensor(kCam1Pose, "457.587, 456.134, 379.999, 255.238",
                          "-0.28368365, 0.07451284, -0.00010473, -3.55590700e-05"));
    // cam1 dropped the second frame.
    std::string cam0 = "#timestamp [ns],filename\n", cam1 = cam0;
    for (const std::string ns :
         {"1403636579763555584", "1403636579813555456", "1403636579863555584"}) {
      dir_.Png("mav0/cam0/data/" + ns + ".png");
      cam0 += ns + "," + ns + ".png\n";
      if (ns == "1403636579813555456") continue;
      dir_.Png("mav0/cam1/data/" + ns + ".png");
      cam1 += ns + "," + ns + ".png\n";
    }
    dir_.Text("mav0/cam0/data.csv", cam0);
    dir_.Text("mav0/cam1/data.csv", cam1);
  }
  Folder dir_{"euroc"};
};

TEST_F(RigDatasetEurocTest, CamerasFromSensorYamlAndFramesEveryCameraHas) {
  for (const std::string& path : {dir_.path(), dir_ / "mav0"}) {
    auto layout = DetectRigLayout(path);
    ASSERT_TRUE(layout.ok()) << layout.status().ToString();
    EXPECT_EQ(*layout, RigLayout::kEuroc);
  }
  auto rig = ReadRigDataset(dir_.path());
  ASSERT_TRUE(rig.ok()) << rig.status().ToString();
  EXPECT_EQ(rig->layout, RigLayout::kEuroc);
  ASSERT_EQ(rig->cameras.size(), 2u);
  const RigCamera& cam1 = rig->cameras[1];
  EXPECT_EQ(rig->cameras[0].name, "cam0");
  EXPECT_EQ(cam1.name, "cam1");
  EXPECT_EQ(cam1.size, cv::Size(752, 480));
  EXPECT_EQ(cam1.K, cv::Matx33d(457.587, 0, 379.999, 0, 456.134, 255.238, 0, 0, 1));
  EXPECT_EQ(cam1.distortion,
            (std::vector<double>{-0.28368365, 0.07451284, -0.00010473, -3.55590700e-05}));
  EXPECT_EQ(cam1.body_t_camera, cv::Vec3d(-0.0198436, 0.0603, 0.0008));
  // The rotation as written, made exactly orthonormal.
  const cv::Matx33d written(0.999708, -0.012355, -0.02079, 0.011997, 0.999779, -0.01725, 0.020998,
                            0.016995, 0.999635);
  EXPECT_LT(cv::norm(cam1.body_R_camera - written), 2e-6);
  EXPECT_LT(cv::norm(cam1.body_R_camera * cam1.body_R_camera.t() - cv::Matx33d::eye()), 1e-12);
  EXPECT_NEAR(cv::determinant(cam1.body_R_camera), 1.0, 1e-12);
  EXPECT_NEAR(rig->cameras[0].body_R_camera(1, 0), 0.999557249008, 1e-9);
  EXPECT_EQ(rig->cameras[0].body_t_camera,
            cv::Vec3d(-0.0216401454975, -0.064676986768, 0.00981073058949));

  // Only the timestamps both cameras have.
  ASSERT_EQ(rig->images.size(), 2u);
  ASSERT_EQ(rig->timestamps.size(), 2u);
  EXPECT_NEAR(rig->timestamps[1].value(), 1403636579.863555584, 1e-6);
  EXPECT_EQ(rig->images[0],
            (std::vector<std::string>{dir_ / "mav0/cam0/data/1403636579763555584.png",
                                      dir_ / "mav0/cam1/data/1403636579763555584.png"}));
  EXPECT_EQ(rig->images[1][1], dir_ / "mav0/cam1/data/1403636579863555584.png");
  EXPECT_EQ(rig->depths, (std::vector<std::vector<std::string>>(2, {"", ""})));

  // No timestamp in common.
  dir_.Text("mav0/cam1/data.csv", "1403636579813555457,1403636579863555584.png\n");
  ExpectError(ReadRigDataset(dir_.path()), StatusCode::kInvalidArgument, "no timestamp in common");
}

TEST_F(RigDatasetEurocTest, MalformedSensorYamlIsRefusedNamingTheFile) {
  const std::string file = dir_ / "mav0/cam1/sensor.yaml";
  dir_.Text("mav0/cam1/sensor.yaml",
            EurocSensor("1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0",
                        "457.587, 456.134, 379.999, 255.238", "0, 0, 0, 0"));
  auto rig = ReadRigDataset(dir_.path());
  ExpectError(rig, StatusCode::kInvalidArgument, file);
  ExpectError(rig, StatusCode::kInvalidArgument, "T_BS data must be a list of 16 numbers");
  // A matrix that is no rotation, even up to rounding, is not made one.
  dir_.Text("mav0/cam1/sensor.yaml",
            EurocSensor("1.1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1",
                        "457.587, 456.134, 379.999, 255.238", "0, 0, 0, 0"));
  rig = ReadRigDataset(dir_.path());
  ExpectError(rig, StatusCode::kInvalidArgument, file);
  ExpectError(rig, StatusCode::kInvalidArgument, "rig camera 'cam1'");
}

// TUM-VI's cameras are fisheyes: sensor.yaml's equidistant model gives the rig camera its lens;
// a model that is not read is refused naming the file and the model.
TEST_F(RigDatasetEurocTest, AnEquidistantCameraKeepsItsLens) {
  const std::string tum_vi_k =
      "0.0034823894022493434, 0.0007150348452162257, "
      "-0.0020532361418706202, 0.00020293673591811182";
  dir_.Text("mav0/cam1/sensor.yaml",
            EurocSensor(kCam1Pose,
                        "190.97847715128717, 190.9733070521226, 254.93170605935475, "
                        "256.8974428996504",
                        tum_vi_k, "equidistant"));
  auto rig = ReadRigDataset(dir_.path());
  ASSERT_TRUE(rig.ok()) << rig.status().ToString();
  EXPECT_EQ(rig->cameras[0].lens, LensModel::kRadialTangential);
  const RigCamera& cam1 = rig->cameras[1];
  EXPECT_EQ(cam1.lens, LensModel::kEquidistant);
  EXPECT_EQ(cam1.distortion, (std::vector<double>{0.0034823894022493434, 0.0007150348452162257,
                                                  -0.0020532361418706202, 0.00020293673591811182}));
  EXPECT_EQ(cam1.K(0, 0), 190.97847715128717);
  EXPECT_EQ(cam1.K(1, 2), 256.8974428996504);

  dir_.Text("mav0/cam1/sensor.yaml",
            EurocSensor(kCam1Pose, "190.9, 190.9, 254.9, 256.8", "0.1, 0.2", "fov"));
  rig = ReadRigDataset(dir_.path());
  ExpectError(rig, StatusCode::kInvalidArgument, dir_ / "mav0/cam1/sensor.yaml");
  ExpectError(rig, StatusCode::kInvalidArgument, "distortion_model 'fov' is not supported");
}

// KITTI odometry sequence 00's calibration, P1 with a 0.54 m baseline; P2 has no image_2 folder.
const char* kKittiCalib =
    "P0: 7.188560000000e+02 0.000000000000e+00 6.071928000000e+02 0.000000000000e+00 "
    "0.000000000000e+00 7.188560000000e+02 1.852157000000e+02 0.000000000000e+00 "
    "0.000000000000e+00 0.000000000000e+00 1.000000000000e+00 0.000000000000e+00\n"
    "P1: 7.188560000000e+02 0.000000000000e+00 6.071928000000e+02 -3.881822400000e+02 "
    "0.000000000000e+00 7.188560000000e+02 1.852157000000e+02 0.000000000000e+00 "
    "0.000000000000e+00 0.000000000000e+00 1.000000000000e+00 0.000000000000e+00\n"
    "P2: 7.188560000000e+02 0.000000000000e+00 6.071928000000e+02 4.538225000000e+01 "
    "0.000000000000e+00 7.188560000000e+02 1.852157000000e+02 -1.130887000000e-01 "
    "0.000000000000e+00 0.000000000000e+00 1.000000000000e+00 3.779761000000e-03\n"
    "Tr: 4.276802385584e-04 -9.999672484946e-01 -8.084491683471e-03 -1.198459927713e-02 "
    "-7.210626507497e-03 8.081198471645e-03 -9.999413164504e-01 -5.403984729748e-02 "
    "9.999738645903e-01 4.859485810390e-04 -7.206933692422e-03 -2.921968648686e-01\n";

class RigDatasetKittiTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_.Text("calib.txt", kKittiCalib);
    dir_.Text("times.txt", "0.000000e+00\n1.036400e-01\n");
    for (const char* name :
         {"image_0/000000.png", "image_0/000001.png", "image_1/000000.png", "image_1/000001.png"}) {
      dir_.Png(name);
    }
  }
  Folder dir_{"kitti"};
};

TEST_F(RigDatasetKittiTest, CamerasFromProjectionMatricesInCamera0sFrame) {
  auto layout = DetectRigLayout(dir_.path());
  ASSERT_TRUE(layout.ok()) << layout.status().ToString();
  EXPECT_EQ(*layout, RigLayout::kKitti);
  auto rig = ReadRigDataset(dir_.path());
  ASSERT_TRUE(rig.ok()) << rig.status().ToString();
  EXPECT_EQ(rig->layout, RigLayout::kKitti);
  ASSERT_EQ(rig->cameras.size(), 2u);  // no image_2 folder
  const cv::Matx33d K(718.856, 0, 607.1928, 0, 718.856, 185.2157, 0, 0, 1);
  for (const RigCamera& camera : rig->cameras) {
    EXPECT_EQ(camera.size, cv::Size(64, 48));
    EXPECT_EQ(camera.K, K);
    EXPECT_TRUE(camera.distortion.empty());
    EXPECT_EQ(camera.body_R_camera, cv::Matx33d::eye());
  }
  EXPECT_EQ(rig->cameras[0].name, "image_0");
  EXPECT_EQ(rig->cameras[1].name, "image_1");
  EXPECT_EQ(rig->cameras[0].body_t_camera, cv::Vec3d(0, 0, 0));
  EXPECT_NEAR(rig->cameras[1].body_t_camera[0], 0.54, 1e-12);
  EXPECT_EQ(rig->cameras[1].body_t_camera[1], 0.0);
  EXPECT_EQ(rig->cameras[1].body_t_camera[2], 0.0);
  EXPECT_EQ(rig->timestamps, (std::vector<std::optional<double>>{0.0, 0.10364}));
  ASSERT_EQ(rig->images.size(), 2u);
  EXPECT_EQ(rig->images[1],
            (std::vector<std::string>{dir_ / "image_0/000001.png", dir_ / "image_1/000001.png"}));
  EXPECT_EQ(rig->depths, (std::vector<std::vector<std::string>>(2, {"", ""})));
}

TEST_F(RigDatasetKittiTest, MissingImagesAreRefusedNamingTheCamera) {
  // image_1 lacks a frame that image_0 has.
  fs::remove(dir_ / "image_1/000001.png");
  auto rig = ReadRigDataset(dir_.path());
  ExpectError(rig, StatusCode::kInvalidArgument, "camera 'image_1' has 1 frames");
  ExpectError(rig, StatusCode::kInvalidArgument, dir_ / "image_1/000001.png");
  // times.txt lists a frame no camera has.
  dir_.Png("image_1/000001.png");
  dir_.Text("times.txt", "0.0\n0.1\n0.2\n");
  ExpectError(ReadRigDataset(dir_.path()), StatusCode::kNotFound, dir_ / "image_0/000002.png");
  // A malformed projection matrix.
  dir_.Text("times.txt", "0.0\n0.1\n");
  dir_.Text("calib.txt", "P0: 1 0 0 0 0 1 0 0 0 0 1\n");
  ExpectError(ReadRigDataset(dir_.path()), StatusCode::kInvalidArgument, "calib.txt' line 1");
}

// The colour cameras of a KITTI sequence (image_2, image_3), without the grey ones.
TEST_F(RigDatasetKittiTest, AColourSequenceIsReadFromItsOwnCameras) {
  fs::remove_all(dir_ / "image_0");
  fs::remove_all(dir_ / "image_1");
  dir_.Png("image_2/000000.png");
  dir_.Png("image_2/000001.png");
  auto layout = DetectRigLayout(dir_.path());
  ASSERT_TRUE(layout.ok()) << layout.status().ToString();
  EXPECT_EQ(*layout, RigLayout::kKitti);
  auto rig = ReadRigDataset(dir_.path());
  ASSERT_TRUE(rig.ok()) << rig.status().ToString();
  ASSERT_EQ(rig->cameras.size(), 1u);
  EXPECT_EQ(rig->cameras[0].name, "image_2");
  EXPECT_EQ(rig->images[1], (std::vector<std::string>{dir_ / "image_2/000001.png"}));
}

// Detected by its times and images (dataset_layouts.h), a KITTI folder without calib.txt is
// refused by the reader naming the file, not taken for no rig at all.
TEST_F(RigDatasetKittiTest, AMissingCalibrationIsNamed) {
  fs::remove(dir_ / "calib.txt");
  auto layout = DetectRigLayout(dir_.path());
  ASSERT_TRUE(layout.ok()) << layout.status().ToString();
  EXPECT_EQ(*layout, RigLayout::kKitti);
  ExpectError(ReadRigDataset(dir_.path()), StatusCode::kNotFound, dir_ / "calib.txt");
}

TEST(RigDatasetTest, ATumFolderIsNoRig) {
  Folder dir("tum");
  dir.Png("rgb/0.png");
  dir.Text("rgb.txt", "10.0 rgb/0.png\n");
  ExpectError(DetectRigLayout(dir.path()), StatusCode::kInvalidArgument, "not a rig sequence");
}

TEST(RigDatasetTest, DetectRigLayoutRefusesAnEmptyFolderAndAMissingPath) {
  Folder dir("empty");
  auto empty = DetectRigLayout(dir.path());
  ExpectError(empty, StatusCode::kInvalidArgument, dir.path());
  ExpectError(empty, StatusCode::kInvalidArgument, "rig.yaml");
  ExpectError(DetectRigLayout(dir / "missing"), StatusCode::kNotFound, dir / "missing");
  ExpectError(ReadRigDataset(dir / "missing"), StatusCode::kNotFound, dir / "missing");
  EXPECT_EQ(RigLayoutName(RigLayout::kPlain), "plain");
  EXPECT_EQ(RigLayoutName(RigLayout::kEuroc), "euroc");
  EXPECT_EQ(RigLayoutName(RigLayout::kKitti), "kitti");
}

}  // namespace
}  // namespace recog::cli
