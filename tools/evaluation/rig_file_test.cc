// Rig files: exact round trips, and malformed files refused naming the file and the camera.
#include "tools/evaluation/rig_file.h"

#include <filesystem>
#include <fstream>
#include <iterator>

#include <gtest/gtest.h>

#include "tools/evaluation/rig_sequence.h"

namespace recog::cli {
namespace {

namespace fs = std::filesystem;

// The default front + rear rig, the rear camera with lens distortion and turned by an angle
// whose sines and cosines have no short decimal form.
std::vector<RigCamera> FrontAndSide() {
  std::vector<RigCamera> rig = DefaultRig(RigSequenceOptions{});
  rig[1].name = "left";
  rig[1].distortion = {-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05};
  rig[1].body_R_camera = Yaw(-90.0 + 1e-3);
  return rig;
}

std::string Write(const std::string& name, const std::string& text) {
  const fs::path path = fs::path(::testing::TempDir()) / name;
  std::ofstream(path) << text;
  return path.string();
}

const char* kRig = R"(cameras:
  - name: front
    width: 640
    height: 480
    fx: 400
    fy: 400
    cx: 319.5
    cy: 239.5
    distortion: []
    body_from_camera:
      rotation: [1, 0, 0, 0, 1, 0, 0, 0, 1]
      translation: [0, 0, 0.4]
)";

TEST(RigFileTest, WrittenRigsReadBackExactly) {
  const std::vector<RigCamera> rig = FrontAndSide();
  const std::string path = (fs::path(::testing::TempDir()) / "front_and_side.yaml").string();
  ASSERT_TRUE(WriteRigFile(rig, path).ok());
  auto read = ReadRigFile(path);
  ASSERT_TRUE(read.ok()) << read.status().ToString();
  ASSERT_EQ(read->size(), rig.size());
  for (size_t i = 0; i < rig.size(); ++i) {
    const RigCamera &a = rig[i], &b = (*read)[i];
    EXPECT_EQ(a.name, b.name);
    EXPECT_EQ(a.size, b.size);
    EXPECT_EQ(a.K, b.K);
    EXPECT_EQ(a.distortion, b.distortion);
    EXPECT_EQ(a.lens, b.lens);
    EXPECT_EQ(a.body_R_camera, b.body_R_camera);
    EXPECT_EQ(a.body_t_camera, b.body_t_camera);
  }
  auto handwritten = ReadRigFile(Write("handwritten.yaml", kRig));
  ASSERT_TRUE(handwritten.ok()) << handwritten.status().ToString();
  EXPECT_EQ(handwritten->front().body_t_camera, cv::Vec3d(0, 0, 0.4));
}

// A fisheye camera's lens is written (only when it is not radtan, the default) and read back.
TEST(RigFileTest, ALensIsWrittenAndReadBack) {
  std::vector<RigCamera> rig = FrontAndSide();
  rig[1].lens = LensModel::kEquidistant;
  rig[1].distortion = {0.0034823894022493434, 0.0007150348452162257, -0.0020532361418706202,
                       0.00020293673591811182};
  const std::string path = (fs::path(::testing::TempDir()) / "fisheye_rig.yaml").string();
  ASSERT_TRUE(WriteRigFile(rig, path).ok());
  std::ifstream in(path);
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_EQ(text.find("lens:"), text.rfind("lens:")) << "one camera has a lens key:\n" << text;
  EXPECT_NE(text.find("lens: equidistant"), std::string::npos) << text;
  auto read = ReadRigFile(path);
  ASSERT_TRUE(read.ok()) << read.status().ToString();
  EXPECT_EQ((*read)[0].lens, LensModel::kRadialTangential);
  EXPECT_EQ((*read)[1].lens, LensModel::kEquidistant);
  EXPECT_EQ((*read)[1].distortion, rig[1].distortion);

  // Written by hand: a double sphere lens by its Kalibr name; a lens of no model, or with the
  // coefficients of another, is refused naming the file and the camera.
  std::string ds = kRig;
  ds.replace(ds.find("    distortion: []"), 18, "    lens: ds\n    distortion: [-0.2, 0.6]");
  auto handwritten = ReadRigFile(Write("rig_ds.yaml", ds));
  ASSERT_TRUE(handwritten.ok()) << handwritten.status().ToString();
  EXPECT_EQ(handwritten->front().lens, LensModel::kDoubleSphere);
  EXPECT_EQ(handwritten->front().distortion, (std::vector<double>{-0.2, 0.6}));
  std::string unknown = ds;
  unknown.replace(unknown.find("lens: ds"), 8, "lens: omni");
  auto refused = ReadRigFile(Write("rig_omni.yaml", unknown));
  EXPECT_EQ(refused.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(refused.status().message().find("rig_omni.yaml"), std::string::npos);
  EXPECT_NE(refused.status().message().find("'omni'"), std::string::npos)
      << refused.status().message();
  std::string three = ds;
  three.replace(three.find("[-0.2, 0.6]"), 11, "[-0.2, 0.6, 0.1]");
  refused = ReadRigFile(Write("rig_ds_three.yaml", three));
  EXPECT_EQ(refused.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(refused.status().message().find("rig camera 'front'"), std::string::npos)
      << refused.status().message();
}

// A rig that does not validate (ValidateRig, core/geometry/camera_rig_test.cc) is not written.
TEST(RigFileTest, AFaultyRigIsNotWritten) {
  std::vector<RigCamera> rig = FrontAndSide();
  rig[1].body_R_camera *= 1.01;
  const std::string path = (fs::path(::testing::TempDir()) / "faulty.yaml").string();
  fs::remove(path);
  const Status s = WriteRigFile(rig, path);
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(s.message().find("'left'"), std::string::npos) << s.message();
  EXPECT_FALSE(fs::exists(path));
}

TEST(RigFileTest, AMalformedFileIsRefusedNamingItAndAMissingOneIsNotFound) {
  EXPECT_EQ(ReadRigFile("/nonexistent/rig.yaml").status().code(), StatusCode::kNotFound);
  std::string no_fy = kRig;
  no_fy.erase(no_fy.find("    fy: 400\n"), 12);
  std::string short_rotation = kRig;
  short_rotation.replace(short_rotation.find("0, 0, 0, 1]"), 11, "0, 1]");
  std::string reflected = kRig;
  reflected.replace(reflected.find("[1, 0, 0,"), 9, "[-1, 0, 0,");
  const std::vector<std::pair<std::string, std::string>> files = {
      {"cameras: [", "rig_unparsable.yaml"}, {"lens: {}\n", "rig_without_cameras.yaml"},
      {no_fy, "rig_without_fy.yaml"},        {short_rotation, "rig_short_rotation.yaml"},
      {reflected, "rig_reflected.yaml"},
  };
  for (const auto& [text, name] : files) {
    const auto read = ReadRigFile(Write(name, text));
    EXPECT_EQ(read.status().code(), StatusCode::kInvalidArgument) << name;
    EXPECT_NE(read.status().message().find(name), std::string::npos) << read.status().message();
  }
  EXPECT_NE(ReadRigFile(Write("rig_without_fy.yaml", no_fy)).status().message().find("'fy'"),
            std::string::npos);
  EXPECT_NE(ReadRigFile(Write("rig_reflected.yaml", reflected)).status().message().find("'front'"),
            std::string::npos);
}

}  // namespace
}  // namespace recog::cli
