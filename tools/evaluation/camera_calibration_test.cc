// Calibration files: each format read to its numbers and lens, the --camera flag's files and
// text, and faulty files refused naming the file, the camera and the key.
#include "tools/evaluation/camera_calibration.h"

#include <algorithm>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "tools/evaluation/test_folder.h"

namespace recog::cli {
namespace {

using testing::ExpectError;
using testing::TestFolder;

// EuRoC's cam0 and TUM-VI's cam0, as their calibrations give them.
const CameraIntrinsics kEuroc{458.654,
                              457.296,
                              367.215,
                              248.375,
                              {-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05},
                              LensModel::kRadialTangential};
const CameraIntrinsics kTumVi{
    190.97847715128717,
    190.9733070521226,
    254.93170605935475,
    256.8974428996504,
    {0.0034823894022493434, 0.0007150348452162257, -0.0020532361418706202, 0.00020293673591811182},
    LensModel::kEquidistant};

// A Kalibr camchain of every camera_model and distortion_model pair read, and of two that are
// not, with the keys Kalibr writes besides.
const char* kCamchain = R"(cam0:
  cam_overlaps: [1]
  camera_model: pinhole
  distortion_coeffs: [-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05]
  distortion_model: radtan
  intrinsics: [458.654, 457.296, 367.215, 248.375]
  resolution: [752, 480]
  rostopic: /cam0/image_raw
cam1:
  T_cn_cnm1:
  - [0.9999, -0.0023, -0.0003, -0.1101]
  - [0.0023, 0.9999, 0.0141, 0.0004]
  - [0.0003, -0.0141, 0.9999, -0.0008]
  - [0.0, 0.0, 0.0, 1.0]
  camera_model: pinhole
  distortion_coeffs: [0.0034823894022493434, 0.0007150348452162257, -0.0020532361418706202,
    0.00020293673591811182]
  distortion_model: equidistant
  intrinsics: [190.97847715128717, 190.9733070521226, 254.93170605935475, 256.8974428996504]
  resolution: [512, 512]
cam2:
  camera_model: ds
  distortion_coeffs: []
  distortion_model: none
  intrinsics: [-0.24, 0.57, 156.1, 155.7, 254.6, 256.4]
  resolution: [512, 512]
cam3:
  camera_model: pinhole
  distortion_model: none
  intrinsics: [400, 401, 319.5, 239.5]
  resolution: [640, 480]
cam4:
  camera_model: omni
  distortion_coeffs: [-0.1, 0.01, 0.0, 0.0]
  distortion_model: radtan
  intrinsics: [0.8, 460.0, 460.0, 376.0, 240.0]
  resolution: [752, 480]
cam5:
  camera_model: eucm
  distortion_model: none
  intrinsics: [0.6, 1.1, 156.1, 155.7, 254.6, 256.4]
  resolution: [512, 512]
)";

// EuRoC's cam0/sensor.yaml, OpenCV's "%YAML:1.0" first.
const char* kEurocSensor = R"(%YAML:1.0
---
# General sensor definitions.
sensor_type: camera
comment: VI-Sensor cam0 (MT9M034)

# Sensor extrinsics wrt. the body-frame.
T_BS:
  cols: 4
  rows: 4
  data: [0.0148655429818, -0.999880929698, 0.00414029679422, -0.0216401454975,
         0.999557249008, 0.0149672133247, 0.025715529948, -0.064676986768,
        -0.0257744366974, 0.00375618835797, 0.999660727178, 0.00981073058949,
         0.0, 0.0, 0.0, 1.0]

# Camera specific definitions.
rate_hz: 20
resolution: [752, 480]
camera_model: pinhole
intrinsics: [458.654, 457.296, 367.215, 248.375] #fu, fv, cu, cv
distortion_model: radial-tangential
distortion_coefficients: [-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05]
)";

// camera_calibration's file as camera_info_manager writes it, with `model` and `d`.
std::string RosYaml(const std::string& model, const std::string& d) {
  return "image_width: 640\nimage_height: 480\ncamera_name: narrow_stereo\ncamera_matrix:\n"
         "  rows: 3\n  cols: 3\n  data: [520.5, 0, 319.25, 0, 521.5, 239.75, 0, 0, 1]\n"
         "distortion_model: " +
         model + "\ndistortion_coefficients:\n  rows: 1\n  cols: " +
         std::to_string(std::count(d.begin(), d.end(), ',') + 1) + "\n  data: [" + d +
         "]\nrectification_matrix:\n  rows: 3\n  cols: 3\n  data: [1, 0, 0, 0, 1, 0, 0, 0, 1]\n"
         "projection_matrix:\n  rows: 3\n  cols: 4\n"
         "  data: [520.5, 0, 319.25, 0, 0, 521.5, 239.75, 0, 0, 0, 1, 0]\n";
}

// OpenCV's calibration sample's output (cv::FileStorage).
const char* kOpenCvYaml = R"(%YAML:1.0
---
calibration_time: "Mon 01 Jan 2024 12:00:00 CET"
image_width: 640
image_height: 480
flags: 0
camera_matrix: !!opencv-matrix
   rows: 3
   cols: 3
   dt: d
   data: [ 5.2050000000000000e+02, 0., 3.1925000000000000e+02, 0.,
       5.2150000000000000e+02, 2.3975000000000000e+02, 0., 0., 1. ]
distortion_coefficients: !!opencv-matrix
   rows: 5
   cols: 1
   dt: d
   data: [ -2.9e-01, 8.7e-02, 1.0e-03, -2.0e-04, 0. ]
avg_reprojection_error: 0.21
)";

// `text` with its first `from` replaced by `to`.
std::string Replaced(std::string text, const std::string& from, const std::string& to) {
  const size_t at = text.find(from);
  EXPECT_NE(at, std::string::npos) << from;
  return at == std::string::npos ? text : text.replace(at, from.size(), to);
}

class CameraCalibrationTest : public ::testing::Test {
 protected:
  // Writes `text` as file `name` of the folder; its path.
  std::string File(const std::string& name, const std::string& text) {
    dir_.Text(name, text);
    return dir_ / name;
  }

  TestFolder dir_{"camera_calibration"};
};

TEST_F(CameraCalibrationTest, KalibrCamchainGivesEachCameraWithItsLens) {
  const std::string file = File("camchain.yaml", kCamchain);
  auto cam0 = ReadCalibrationFile(file);  // the default camera
  ASSERT_TRUE(cam0.ok()) << cam0.status().ToString();
  EXPECT_EQ(cam0->camera, kEuroc);
  EXPECT_EQ(cam0->size, cv::Size(752, 480));
  auto cam1 = ReadCalibrationFile(file, "cam1");
  ASSERT_TRUE(cam1.ok()) << cam1.status().ToString();
  EXPECT_EQ(cam1->camera, kTumVi);
  EXPECT_EQ(cam1->size, cv::Size(512, 512));
  // ds: [xi, alpha, fx, fy, cx, cy] becomes fx, fy, cx, cy with the coefficients xi, alpha.
  auto cam2 = ReadCameraCalibration(file, "cam2");
  ASSERT_TRUE(cam2.ok()) << cam2.status().ToString();
  EXPECT_EQ(*cam2, (CameraIntrinsics{
                       156.1, 155.7, 254.6, 256.4, {-0.24, 0.57}, LensModel::kDoubleSphere}));
  auto cam3 = ReadCameraCalibration(file, "cam3");
  ASSERT_TRUE(cam3.ok()) << cam3.status().ToString();
  EXPECT_EQ(*cam3, (CameraIntrinsics{400, 401, 319.5, 239.5, {}, LensModel::kRadialTangential}));
}

TEST_F(CameraCalibrationTest, UnsupportedKalibrModelsAndUnknownCamerasAreRefusedByName) {
  const std::string file = File("camchain.yaml", kCamchain);
  auto omni = ReadCameraCalibration(file, "cam4");
  ExpectError(omni, StatusCode::kInvalidArgument, file);
  ExpectError(omni, StatusCode::kInvalidArgument,
              "cam4: camera_model 'omni' with distortion_model 'radtan' is not supported");
  ExpectError(omni, StatusCode::kInvalidArgument,
              "pinhole with radtan, equidistant or none; ds with none");
  ExpectError(ReadCameraCalibration(file, "cam5"), StatusCode::kInvalidArgument,
              "camera_model 'eucm' with distortion_model 'none' is not supported");
  auto unknown = ReadCameraCalibration(file, "cam9");
  ExpectError(unknown, StatusCode::kInvalidArgument, "no camera 'cam9'");
  ExpectError(unknown, StatusCode::kInvalidArgument, "cam0, cam1, cam2, cam3, cam4, cam5");
  ExpectError(ReadCameraCalibration(file, "left"), StatusCode::kInvalidArgument,
              "no camera 'left'");
  // A pinhole camera with a lens of no pinhole (ds is a camera_model), or with Kalibr's fov.
  const std::string pinhole_ds =
      Replaced(kCamchain, "distortion_model: radtan", "distortion_model: ds");
  ExpectError(ReadCameraCalibration(File("pinhole_ds.yaml", pinhole_ds)),
              StatusCode::kInvalidArgument,
              "camera_model 'pinhole' with distortion_model 'ds' is not supported");
  const std::string fov = Replaced(kCamchain, "distortion_model: radtan", "distortion_model: fov");
  ExpectError(ReadCameraCalibration(File("fov.yaml", fov)), StatusCode::kInvalidArgument,
              "distortion_model 'fov' is not supported");
}

TEST_F(CameraCalibrationTest, EurocAndTumViSensorYamlAreRead) {
  auto euroc = ReadCalibrationFile(File("sensor.yaml", kEurocSensor));
  ASSERT_TRUE(euroc.ok()) << euroc.status().ToString();
  EXPECT_EQ(euroc->camera, kEuroc);
  EXPECT_EQ(euroc->size, cv::Size(752, 480));
  std::string tum_vi = Replaced(kEurocSensor, "radial-tangential", "equidistant");
  tum_vi =
      Replaced(tum_vi, "[458.654, 457.296, 367.215, 248.375]",
               "[190.97847715128717, 190.9733070521226, 254.93170605935475, 256.8974428996504]");
  tum_vi = Replaced(tum_vi, "[-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05]",
                    "[0.0034823894022493434, 0.0007150348452162257, -0.0020532361418706202, "
                    "0.00020293673591811182]");
  auto fisheye = ReadCameraCalibration(File("tum_vi_sensor.yaml", tum_vi));
  ASSERT_TRUE(fisheye.ok()) << fisheye.status().ToString();
  EXPECT_EQ(*fisheye, kTumVi);
  // '#cam1' picks a camchain's camera; a file of one camera has none to pick.
  ExpectError(ReadCameraCalibration(dir_ / "sensor.yaml", "cam1"), StatusCode::kInvalidArgument,
              "holds one camera");
}

TEST_F(CameraCalibrationTest, RosCameraInfoYamlMapsItsDistortionModel) {
  const CameraIntrinsics pinhole{520.5, 521.5, 319.25, 239.75, {}};
  struct Case {
    std::string model, d;
    CameraIntrinsics expected;
  };
  const std::vector<Case> cases = {
      {"plumb_bob",
       "-0.29, 0.087, 0.001, -0.0002, 0.0",
       {520.5, 521.5, 319.25, 239.75, {-0.29, 0.087, 0.001, -0.0002, 0.0}}},
      {"rational_polynomial",
       "-0.29, 0.087, 0.001, -0.0002, 0.01, 0.02, 0.03, 0.04",
       {520.5, 521.5, 319.25, 239.75, {-0.29, 0.087, 0.001, -0.0002, 0.01, 0.02, 0.03, 0.04}}},
      {"equidistant",
       "0.01, -0.002, 0.0003, -0.00004",
       {520.5, 521.5, 319.25, 239.75, {0.01, -0.002, 0.0003, -0.00004}, LensModel::kEquidistant}},
      // No distortion: a pinhole; an ideal fisheye (r = θ) is none.
      {"plumb_bob", "0, 0, 0, 0, 0", pinhole},
      {"equidistant",
       "0, 0, 0, 0",
       {520.5, 521.5, 319.25, 239.75, {0, 0, 0, 0}, LensModel::kEquidistant}},
      {"''", "0, 0, 0, 0, 0", pinhole},
      {"none", "0, 0, 0, 0, 0", pinhole},
  };
  for (const Case& test : cases) {
    SCOPED_TRACE(test.model + ": " + test.d);
    auto read = ReadCalibrationFile(File("ost.yaml", RosYaml(test.model, test.d)));
    ASSERT_TRUE(read.ok()) << read.status().ToString();
    EXPECT_EQ(read->camera, test.expected);
    EXPECT_EQ(read->size, cv::Size(640, 480));
  }
  const std::string fov = File("fov.yaml", RosYaml("fov", "0.9"));
  ExpectError(ReadCameraCalibration(fov), StatusCode::kInvalidArgument, fov);
  ExpectError(ReadCameraCalibration(fov), StatusCode::kInvalidArgument,
              "distortion model 'fov' is not supported (read: plumb_bob, rational_polynomial, "
              "equidistant");
  // Coefficients the lens does not take (Validate's fault).
  ExpectError(ReadCameraCalibration(File("three.yaml", RosYaml("plumb_bob", "0.1, 0.2, 0.3"))),
              StatusCode::kInvalidArgument, "three.yaml");
}

TEST_F(CameraCalibrationTest, OpenCvFileStorageCalibrationIsRadialTangential) {
  auto read = ReadCalibrationFile(File("opencv.yaml", kOpenCvYaml));
  ASSERT_TRUE(read.ok()) << read.status().ToString();
  EXPECT_EQ(read->camera,
            (CameraIntrinsics{520.5, 521.5, 319.25, 239.75, {-0.29, 0.087, 0.001, -0.0002, 0}}));
  EXPECT_EQ(read->size, cv::Size(640, 480));
}

TEST_F(CameraCalibrationTest, FaultyFilesAreRefusedNamingTheFileAndTheKey) {
  EXPECT_EQ(ReadCameraCalibration(dir_ / "missing.yaml").status().code(), StatusCode::kNotFound);

  std::string no_intrinsics = kCamchain;
  no_intrinsics.erase(
      no_intrinsics.find("  intrinsics: [190.97"),
      no_intrinsics.find("  resolution: [512, 512]") - no_intrinsics.find("  intrinsics: [190.97"));
  const std::string file = File("no_intrinsics.yaml", no_intrinsics);
  ExpectError(ReadCameraCalibration(file, "cam1"), StatusCode::kInvalidArgument,
              "calibration file '" + file + "': cam1: missing key 'intrinsics'");
  EXPECT_TRUE(ReadCameraCalibration(file, "cam0").ok()) << "cam0 is whole";

  const std::string short_intrinsics =
      Replaced(kEurocSensor, "[458.654, 457.296, 367.215, 248.375]", "[458.654, 457.296, 367.215]");
  ExpectError(ReadCameraCalibration(File("short.yaml", short_intrinsics)),
              StatusCode::kInvalidArgument,
              "intrinsics of a pinhole camera must be [fx, fy, cx, cy]");
  const std::string word = Replaced(kEurocSensor, "367.215", "cx");
  ExpectError(ReadCameraCalibration(File("word.yaml", word)), StatusCode::kInvalidArgument,
              "intrinsics must be a list of numbers ('cx' is not one)");
  const std::string resolution = Replaced(kEurocSensor, "[752, 480]", "[752]");
  ExpectError(ReadCameraCalibration(File("resolution.yaml", resolution)),
              StatusCode::kInvalidArgument, "resolution must be [width, height]");
  const std::string none_with_coefficients = Replaced(kEurocSensor, "radial-tangential", "none");
  ExpectError(ReadCameraCalibration(File("none.yaml", none_with_coefficients)),
              StatusCode::kInvalidArgument,
              "distortion_model is none but distortion_coefficients are not all 0");
  const std::string alpha = Replaced(kCamchain, "[-0.24, 0.57,", "[-0.24, 1.57,");
  ExpectError(ReadCameraCalibration(File("alpha.yaml", alpha), "cam2"),
              StatusCode::kInvalidArgument, "cam2: ");

  const std::string no_data =
      Replaced(RosYaml("plumb_bob", "0, 0, 0, 0, 0"), "  data: [520.5", "  values: [520.5");
  ExpectError(ReadCameraCalibration(File("no_data.yaml", no_data)), StatusCode::kInvalidArgument,
              "camera_matrix: missing key 'data'");
  const std::string skewed =
      Replaced(RosYaml("plumb_bob", "0, 0, 0, 0, 0"), "[520.5, 0, 319.25", "[520.5, 2, 319.25");
  ExpectError(ReadCameraCalibration(File("skewed.yaml", skewed)), StatusCode::kInvalidArgument,
              "camera_matrix must be 3 x 3 [fx, 0, cx, 0, fy, cy, 0, 0, 1]");

  ExpectError(ReadCameraCalibration(File("unparsable.yaml", "cam0: [")),
              StatusCode::kInvalidArgument, "unparsable.yaml");
  ExpectError(ReadCameraCalibration(File("other.yaml", "cameras: []\n")),
              StatusCode::kInvalidArgument, "is not a calibration file");
}

TEST_F(CameraCalibrationTest, CameraFlagTakesAFileAFilesCameraOrText) {
  const std::string camchain = File("camchain.yaml", kCamchain);
  auto file = ParseCameraFlag("--camera", camchain);
  ASSERT_TRUE(file.ok()) << file.status().ToString();
  EXPECT_EQ(*file, kEuroc);
  auto cam1 = ParseCameraFlag("--camera", camchain + "#cam1");
  ASSERT_TRUE(cam1.ok()) << cam1.status().ToString();
  EXPECT_EQ(*cam1, kTumVi);
  auto text = ParseCameraFlag("--camera", "458.654,457.296,367.215,248.375");
  ASSERT_TRUE(text.ok()) << text.status().ToString();
  EXPECT_EQ(*text, (CameraIntrinsics{458.654, 457.296, 367.215, 248.375, {}}));
  auto lens = ParseCameraFlag("--camera", "equidistant:190.9,190.9,254.9,256.9,0.1,0,0,0");
  ASSERT_TRUE(lens.ok()) << lens.status().ToString();
  EXPECT_EQ(lens->lens, LensModel::kEquidistant);

  auto omni = ParseCameraFlag("--depth-camera", camchain + "#cam4");
  ExpectError(omni, StatusCode::kInvalidArgument, "--depth-camera: calibration file");
  ExpectError(omni, StatusCode::kInvalidArgument, "camera_model 'omni'");
  ExpectError(ParseCameraFlag("--camera", dir_ / "missing.yaml"), StatusCode::kNotFound,
              "--camera: calibration file '" + dir_ / "missing.yaml" + "' does not exist");
  ExpectError(ParseCameraFlag("--camera", "kalibr.yaml#cam1"), StatusCode::kNotFound,
              "'kalibr.yaml' does not exist");
  const auto bad = ParseCameraFlag("--camera", "458.654,457.296");
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.status().message().rfind("--camera", 0), 0u) << bad.status().message();
}

// CameraInfo's distortion models (bags use this too: ros_bag.h).
TEST(RosCameraIntrinsicsTest, ModelsMapToLensesAndZerosToThePinhole) {
  const auto with_d = [](std::vector<double> d) {
    return CameraIntrinsics{50, 51, 31.5, 23.5, std::move(d)};
  };
  const CameraIntrinsics pinhole = with_d({});
  auto empty = RosCameraIntrinsics(pinhole, "");
  ASSERT_TRUE(empty.ok());
  EXPECT_EQ(*empty, pinhole);
  // Older drivers leave the model empty with plumb_bob's coefficients.
  auto unnamed = RosCameraIntrinsics(with_d({0.1, -0.2, 0, 0, 0.01}), "");
  ASSERT_TRUE(unnamed.ok());
  EXPECT_EQ(*unnamed, with_d({0.1, -0.2, 0, 0, 0.01}));
  auto unknown_zeros = RosCameraIntrinsics(with_d({0}), "fov");
  ASSERT_TRUE(unknown_zeros.ok());
  EXPECT_EQ(*unknown_zeros, pinhole);
  auto fisheye = RosCameraIntrinsics(with_d({0.1, 0.01, 0, 0}), "equidistant");
  ASSERT_TRUE(fisheye.ok());
  EXPECT_EQ(fisheye->lens, LensModel::kEquidistant);
  EXPECT_EQ(RosCameraIntrinsics(with_d({0.9}), "fov").status().code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(RosCameraIntrinsics(with_d({0.1, 0.01, 0}), "equidistant").status().code(),
            StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace recog::cli
