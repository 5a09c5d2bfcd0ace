// Rig files: exact round trips, and every fault refused naming the camera.
#include "tools/evaluation/rig_file.h"

#include <filesystem>
#include <fstream>

#include <gtest/gtest.h>

namespace recog::cli {
namespace {

namespace fs = std::filesystem;

std::vector<RigCamera> FrontAndSide() {
  return {{"front",
           {640, 480},
           {400, 0, 319.5, 0, 401, 239.5, 0, 0, 1},
           {},
           {cv::Matx33d::eye(), {0, 0, 0.4}}},
          {"left",
           {752, 480},
           {458.654, 0, 367.215, 0, 457.296, 248.375, 0, 0, 1},
           {-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05},
           {Yaw(-90.0 + 1e-3), {-0.25, 0.01, 0.1}}}};
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
    EXPECT_EQ(a.body_from_camera.world_from_camera, b.body_from_camera.world_from_camera);
    EXPECT_EQ(a.body_from_camera.center, b.body_from_camera.center);
  }
  auto handwritten = ReadRigFile(Write("handwritten.yaml", kRig));
  ASSERT_TRUE(handwritten.ok()) << handwritten.status().ToString();
  EXPECT_EQ(handwritten->front().body_from_camera.center, cv::Vec3d(0, 0, 0.4));
}

// What a robotics engineer gets wrong in a rig file is refused, naming the camera.
TEST(RigFileTest, AFaultyRigIsRefusedNamingTheCamera) {
  struct Case {
    std::string fault;
    void (*apply)(RigCamera*);
  };
  const std::vector<Case> cases = {
      {"is not a rotation", [](RigCamera* c) { c->body_from_camera.world_from_camera *= 1.01; }},
      {"is not a rotation",  // a reflection: orthonormal, det -1
       [](RigCamera* c) { c->body_from_camera.world_from_camera = {-1, 0, 0, 0, 1, 0, 0, 0, 1}; }},
      {"is not a rotation",
       [](RigCamera* c) { c->body_from_camera.world_from_camera = Yaw(10) * 0.0; }},
      {"fx and fy", [](RigCamera* c) { c->K(1, 1) = 0; }},
      {"width and height", [](RigCamera* c) { c->size.width = 0; }},
      {"distortion has 3 values",
       [](RigCamera* c) {
         c->distortion = {0.1, 0.2, 0.3};
       }},
      {"translation must be finite", [](RigCamera* c) { c->body_from_camera.center[1] = NAN; }},
  };
  for (const Case& test : cases) {
    std::vector<RigCamera> rig = FrontAndSide();
    test.apply(&rig[1]);
    const Status s = ValidateRig(rig);
    EXPECT_EQ(s.code(), StatusCode::kInvalidArgument) << test.fault;
    EXPECT_NE(s.message().find("'left'"), std::string::npos) << s.message();
    EXPECT_NE(s.message().find(test.fault), std::string::npos) << s.message();
    EXPECT_EQ(WriteRigFile(rig, (fs::path(::testing::TempDir()) / "bad.yaml").string()).code(),
              StatusCode::kInvalidArgument);
  }
  std::vector<RigCamera> twice = FrontAndSide();
  twice[1].name = "front";
  EXPECT_NE(ValidateRig(twice).message().find("'front' is used twice"), std::string::npos);
  std::vector<RigCamera> dots = FrontAndSide();
  dots[0].name = "..";
  EXPECT_NE(ValidateRig(dots).message().find("not a folder name"), std::string::npos);
  EXPECT_EQ(ValidateRig({}).code(), StatusCode::kInvalidArgument);
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
