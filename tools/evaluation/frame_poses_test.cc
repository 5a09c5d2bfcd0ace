// Pose lists (the poses.txt of a real recording) and scoring recognition against them (recog eval
// sequence --poses): reading, every kind of malformed line, frames matched by their number, the
// summary and its CSV and plot.
#include "tools/evaluation/frame_poses.h"

#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <sstream>

#include <gtest/gtest.h>
#include <opencv2/calib3d.hpp>

namespace recog::cli {
namespace {

namespace fs = std::filesystem;

class FramePosesTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("recog_frame_poses_" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  // Writes `text` to a file of the scratch folder and returns its path.
  std::string Write(const std::string& name, const std::string& text) const {
    const std::string path = (dir_ / name).string();
    std::ofstream(path) << text;
    return path;
  }

  fs::path dir_;
};

constexpr char kIdentity[] = "1 0 0 0 1 0 0 0 1";

TEST(FrameNumberTest, IsTheNumberEndingTheStem) {
  EXPECT_EQ(FrameNumber("data/images/color_image_0007.png"), 7);
  EXPECT_EQ(FrameNumber("000012.png"), 12);
  EXPECT_EQ(FrameNumber("image7"), 7);
  EXPECT_EQ(FrameNumber("/x/0.jpg"), 0);
  EXPECT_EQ(FrameNumber("frame.png"), std::nullopt);
  EXPECT_EQ(FrameNumber("12/frame.png"), std::nullopt);  // the folder's number is not the frame's
  EXPECT_EQ(FrameNumber("7_left.png"), std::nullopt);
  EXPECT_EQ(FrameNumber("image99999999999999999999.png"), std::nullopt);  // does not fit an int
}

TEST_F(FramePosesTest, ReadsFramesAndPosesSkippingCommentsAndBlankLines) {
  const std::string path = Write("poses.txt",
                                 "# frame r11 .. r33 tx ty tz\n"
                                 "\n"
                                 "0000 " +
                                     std::string(kIdentity) +
                                     "  0.1 -0.2 0.5\n"
                                     "0007 0 -1 0 1 0 0 0 0 1 0 0 1.25  # turned about z\n"
                                     "   12 " +
                                     std::string(kIdentity) + " 0 0 2\n");
  auto poses = ReadFramePoses(path);
  ASSERT_TRUE(poses.ok()) << poses.status().ToString();
  ASSERT_EQ(poses->size(), 3u);
  EXPECT_EQ(poses->at(0).t, cv::Vec3d(0.1, -0.2, 0.5));
  EXPECT_EQ(poses->at(0).R, cv::Matx33d::eye());
  EXPECT_EQ(poses->at(7).R, cv::Matx33d(0, -1, 0, 1, 0, 0, 0, 0, 1));
  EXPECT_EQ(poses->at(7).t, cv::Vec3d(0, 0, 1.25));
  EXPECT_EQ(poses->at(12).t, cv::Vec3d(0, 0, 2));
}

TEST_F(FramePosesTest, AMalformedLineIsAnErrorNamingTheFileAndLine) {
  const std::string good = "0 " + std::string(kIdentity) + " 0 0 1\n";
  const struct {
    std::string line, message;
  } cases[] = {
      {"1 " + std::string(kIdentity) + " 0 0", "got 12 fields"},
      {"1 " + std::string(kIdentity) + " 0 0 1 9", "got 14 fields"},
      {"1 " + std::string(kIdentity) + " 0 zero 1", "'zero' is not a finite number"},
      {"1 " + std::string(kIdentity) + " 0 nan 1", "'nan' is not a finite number"},
      {"x1 " + std::string(kIdentity) + " 0 0 1", "'x1' is not a frame number"},
      {"-1 " + std::string(kIdentity) + " 0 0 1", "'-1' is not a frame number"},
      {"1.5 " + std::string(kIdentity) + " 0 0 1", "'1.5' is not a frame number"},
      {"1 2 0 0 0 1 0 0 0 1 0 0 1", "not a rotation matrix"},
      {"1 -1 0 0 0 1 0 0 0 1 0 0 1", "not a rotation matrix"},  // a reflection
      {"0000 " + std::string(kIdentity) + " 0 0 2", "frame 0 again (first on line 2)"},
  };
  for (const auto& c : cases) {
    const std::string path = Write("bad.txt", "# header\n" + good + c.line + "\n" + good);
    const Status s = ReadFramePoses(path).status();
    EXPECT_EQ(s.code(), StatusCode::kInvalidArgument) << c.line;
    EXPECT_NE(s.message().find(path + ":3: "), std::string::npos) << s.message();
    EXPECT_NE(s.message().find(c.message), std::string::npos) << s.message();
  }
  EXPECT_EQ(ReadFramePoses(Write("empty.txt", "# nothing\n\n")).status().code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(ReadFramePoses((dir_ / "none.txt").string()).status().code(), StatusCode::kNotFound);
  EXPECT_EQ(ReadFramePoses(dir_.string()).status().code(), StatusCode::kNotFound);  // a folder
}

TEST_F(FramePosesTest, ThePoseOfAFrameComesFromAListOrAVispPoseFile) {
  const std::string list = Write("poses.txt", "3 " + std::string(kIdentity) + " 0 0 0.5\n");
  auto pose = ReadPoseOfFrame(list, "rec/images/color_image_0003.png");
  ASSERT_TRUE(pose.ok()) << pose.status().ToString();
  EXPECT_EQ(pose->t, cv::Vec3d(0, 0, 0.5));
  EXPECT_EQ(ReadPoseOfFrame(list, "rec/images/color_image_0004.png").status().code(),
            StatusCode::kNotFound);
  EXPECT_EQ(ReadPoseOfFrame(list, "rec/images/first.png").status().code(),
            StatusCode::kInvalidArgument);
  // A ViSP .pos file (tx ty tz thetaux thetauy thetauz) is the pose whatever the frame.
  const std::string visp = Write("first.pos", "0.1 0.2 0.7 0 0 1.5707963267948966\n");
  pose = ReadPoseOfFrame(visp, "rec/images/first.png");
  ASSERT_TRUE(pose.ok()) << pose.status().ToString();
  EXPECT_EQ(pose->t, cv::Vec3d(0.1, 0.2, 0.7));
  EXPECT_LT(cv::norm(pose->R - cv::Matx33d(0, -1, 0, 1, 0, 0, 0, 0, 1)), 1e-9);
}

TEST_F(FramePosesTest, FramesAreMatchedByNumberAndScored) {
  RigidTransform truth;
  truth.t = {0, 0, 0.5};
  const std::map<int, RigidTransform> poses = {{2, truth}, {10, truth}};
  Detection cube, other;
  cube.name = "cube";
  cube.inliers = 42;
  cube.camera_from_object = truth;
  cv::Rodrigues(cv::Vec3d(0, 0.1, 0), cube.camera_from_object.R);  // 5.73 degrees
  cube.camera_from_object.t[0] = 0.02;                             // 2 cm of 50: 4 %
  other.name = "lion";
  const SizeRecallOptions limits;  // 10 degrees, 10 % of the distance

  const auto found =
      ScoreFramePose(poses, "seq/color_image_0002.png", "cube", {other, cube}, limits);
  ASSERT_TRUE(found.has_value());
  EXPECT_EQ(found->frame, 2);
  EXPECT_EQ(found->score.image, "color_image_0002.png");
  EXPECT_TRUE(found->score.found);
  EXPECT_TRUE(found->score.correct_pose);
  EXPECT_EQ(found->inliers, 42u);
  EXPECT_NEAR(found->score.rotation_error_deg, 0.1 * 180 / CV_PI, 1e-9);
  EXPECT_NEAR(found->score.translation_error_m, 0.02, 1e-12);
  EXPECT_EQ(found->score.other_objects, 1u);

  SizeRecallOptions strict = limits;
  strict.max_rotation_error_deg = 5;
  const auto wrong_pose = ScoreFramePose(poses, "0010.png", "cube", {cube}, strict);
  ASSERT_TRUE(wrong_pose.has_value());
  EXPECT_TRUE(wrong_pose->score.found);
  EXPECT_FALSE(wrong_pose->score.correct_pose);

  const auto missed = ScoreFramePose(poses, "image10.png", "cube", {other, other}, limits);
  ASSERT_TRUE(missed.has_value());
  EXPECT_FALSE(missed->score.found);
  EXPECT_EQ(missed->inliers, 0u);
  EXPECT_EQ(missed->score.other_objects, 2u);

  EXPECT_FALSE(ScoreFramePose(poses, "color_image_0003.png", "cube", {cube}, limits));
  EXPECT_FALSE(ScoreFramePose(poses, "first.png", "cube", {cube}, limits));

  const PoseErrorSummary summary = SummarisePoseErrors({*found, *wrong_pose, *missed});
  EXPECT_EQ(summary.frames_with_pose, 3u);
  EXPECT_EQ(summary.found, 2u);
  EXPECT_NEAR(summary.recall, 2.0 / 3, 1e-12);
  EXPECT_EQ(summary.correct_pose, 1u);  // as each frame was scored
  EXPECT_EQ(summary.wrong_objects, 3u);
  EXPECT_NEAR(summary.median_rotation_error_deg, 0.1 * 180 / CV_PI, 1e-9);
  EXPECT_NEAR(summary.median_translation_error_m, 0.02, 1e-12);
  EXPECT_EQ(SummarisePoseErrors({}).recall, 0);

  const std::string csv = (dir_ / "errors.csv").string(), png = (dir_ / "errors.png").string();
  ASSERT_TRUE(WritePoseErrorCsv({*found, *missed}, csv).ok());
  ASSERT_TRUE(WritePoseErrorPlot({*found, *missed}, "errors", png).ok());
  EXPECT_GT(fs::file_size(png), 1000u);
  std::ifstream in(csv);  // the plot leaves the CSV beside it alone
  std::stringstream text;
  text << in.rdbuf();
  EXPECT_EQ(text.str(),
            "frame,found,inliers,rotation_error_deg,translation_error_m,wrong_objects\n"
            "2,1,42,5.729577951,0.02,1\n"
            "10,0,0,,,2\n");
  ASSERT_TRUE(WritePoseErrorPlot({}, "no frame", png).ok());
  EXPECT_EQ(WritePoseErrorCsv({*found}, "/nonexistent/dir/x.csv").code(), StatusCode::kInternal);
  EXPECT_EQ(WritePoseErrorPlot({*found}, "x", "/nonexistent/dir/x.png").code(),
            StatusCode::kInternal);
}

}  // namespace
}  // namespace recog::cli
