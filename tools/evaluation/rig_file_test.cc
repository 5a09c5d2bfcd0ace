// Rig files: exact round trips, and malformed files refused naming the file and the camera.
#include "tools/evaluation/rig_file.h"

#include <filesystem>
#include <fstream>

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
    EXPECT_EQ(a.body_R_camera, b.body_R_camera);
    EXPECT_EQ(a.body_t_camera, b.body_t_camera);
  }
  auto handwritten = ReadRigFile(Write("handwritten.yaml", kRig));
  ASSERT_TRUE(handwritten.ok()) << handwritten.status().ToString();
  EXPECT_EQ(handwritten->front().body_t_camera, cv::Vec3d(0, 0, 0.4));
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
