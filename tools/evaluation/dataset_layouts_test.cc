#include "tools/evaluation/dataset_layouts.h"

#include <filesystem>

#include <gtest/gtest.h>

#include "tools/evaluation/place_evaluation.h"
#include "tools/evaluation/test_folder.h"

namespace recog::cli {
namespace {

namespace fs = std::filesystem;

class Fixture : public testing::TestFolder {
 public:
  explicit Fixture(const std::string& name) : TestFolder("layouts_" + name) {}
};

using testing::ExpectError;

// TUM RGB-D: three colour images; depth images 0.01 s after the first, none within 0.02 s of the
// second (0.026 s before, 0.03 s after), and 0.002 s before, exactly on and 0.015 s after the
// third.
class TumTest : public ::testing::Test {
 protected:
  void SetUp() override {
    for (const char* name : {"rgb/1.png", "rgb/2.png", "rgb/3.png", "depth/1.png", "depth/2.png",
                             "depth/3.png", "depth/4.png"}) {
      dir_.Png(name, 100);
    }
    dir_.Text("rgb.txt",
              "# color images\n# file: 'x.bag'\n# timestamp filename\n"
              "1305031102.175304 rgb/1.png\n1305031102.211214 rgb/2.png\n"
              "1305031102.243211 rgb/3.png\n");
    dir_.Text("depth.txt",
              "# depth maps\n1305031102.185304 depth/1.png\n1305031102.241214 depth/2.png\n"
              "1305031102.243211 depth/3.png\n1305031102.258211 depth/4.png\n");
  }
  Fixture dir_{"tum"};
};

TEST_F(TumTest, ColourFramesGetTheirTimestampsAndTheNearestDepthWithin20Ms) {
  EXPECT_EQ(DetectDatasetLayout(dir_.path()), DatasetLayout::kTum);
  auto frames = ReadDatasetFrames(dir_.path(), DatasetLayout::kTum);
  ASSERT_TRUE(frames.ok()) << frames.status().ToString();
  ASSERT_EQ(frames->size(), 3u);
  EXPECT_DOUBLE_EQ((*frames)[0].timestamp, 1305031102.175304);
  EXPECT_DOUBLE_EQ((*frames)[2].timestamp, 1305031102.243211);
  EXPECT_EQ((*frames)[0].image, dir_ / "rgb/1.png");
  EXPECT_EQ((*frames)[0].depth, dir_ / "depth/1.png");
  EXPECT_EQ((*frames)[1].depth, "");
  EXPECT_EQ((*frames)[2].depth, dir_ / "depth/3.png");
  for (const DatasetFrame& f : *frames) EXPECT_EQ(f.right, "");
}

TEST_F(TumTest, FrameSourceReadsTheLayoutWithTimestamps) {
  auto source = FrameSource::Open(dir_.path());
  ASSERT_TRUE(source.ok()) << source.status().ToString();
  EXPECT_EQ(source->layout(), DatasetLayout::kTum);
  EXPECT_EQ(source->size(), 3u);
  cv::Mat gray;
  std::string name;
  std::vector<std::optional<double>> timestamps;
  for (;;) {
    auto more = source->Next(&gray, &name);
    ASSERT_TRUE(more.ok()) << more.status().ToString();
    if (!*more) break;
    EXPECT_EQ(gray.size(), cv::Size(16, 16));
    timestamps.push_back(source->timestamp());
  }
  EXPECT_EQ(timestamps, (std::vector<std::optional<double>>{1305031102.175304, 1305031102.211214,
                                                            1305031102.243211}));
  // A plain folder of images has no timestamps.
  auto folder = FrameSource::Open(dir_ / "rgb", DatasetLayout::kFolder);
  ASSERT_TRUE(folder.ok()) << folder.status().ToString();
  EXPECT_EQ(folder->layout(), DatasetLayout::kFolder);
  ASSERT_TRUE(folder->Next(&gray, &name).value());
  EXPECT_EQ(folder->timestamp(), std::nullopt);
}

TEST_F(TumTest, BadListsAreClearErrors) {
  dir_.Text("rgb.txt", "1305031102.175304 rgb/1.png\n1305031102.211214 rgb/missing.png\n");
  ExpectError(ReadDatasetFrames(dir_.path(), DatasetLayout::kTum), StatusCode::kNotFound,
              "missing.png");
  dir_.Text("rgb.txt", "1305031102.175304 rgb/1.png\n1305031102.2x rgb/2.png\n");
  ExpectError(ReadDatasetFrames(dir_.path(), DatasetLayout::kTum), StatusCode::kInvalidArgument,
              "line 2");
  dir_.Text("rgb.txt", "1305031102.175304 rgb/1.png extra\n");
  ExpectError(ReadDatasetFrames(dir_.path(), DatasetLayout::kTum), StatusCode::kInvalidArgument,
              "line 1");
  dir_.Text("rgb.txt", "1305031102.211214 rgb/1.png\n1305031102.175304 rgb/2.png\n");
  ExpectError(ReadDatasetFrames(dir_.path(), DatasetLayout::kTum), StatusCode::kInvalidArgument,
              "increase");
  dir_.Text("rgb.txt", "# nothing\n");
  ExpectError(ReadDatasetFrames(dir_.path(), DatasetLayout::kTum), StatusCode::kInvalidArgument,
              "no frames");
  // A bad depth list fails the whole dataset too.
  dir_.Text("rgb.txt", "1305031102.175304 rgb/1.png\n");
  dir_.Text("depth.txt", "1305031102.185304\n");
  ExpectError(ReadDatasetFrames(dir_.path(), DatasetLayout::kTum), StatusCode::kInvalidArgument,
              "depth.txt");
  fs::remove(dir_ / "rgb.txt");
  ExpectError(ReadDatasetFrames(dir_.path(), DatasetLayout::kTum), StatusCode::kNotFound,
              "rgb.txt");
}

TEST(EurocTest, LeftFramesInSecondsWithTheRightImageOfTheSameTimestamp) {
  Fixture dir("euroc");
  for (const char* ns : {"1403636579763555584", "1403636579813555456", "1403636579863555584"}) {
    dir.Png(std::string("mav0/cam0/data/") + ns + ".png", 50);
  }
  for (const char* ns : {"1403636579763555584", "1403636579863555584"}) {
    dir.Png(std::string("mav0/cam1/data/") + ns + ".png", 60);
  }
  dir.Text("mav0/cam0/data.csv",
           "#timestamp [ns],filename\r\n1403636579763555584,1403636579763555584.png\r\n"
           "1403636579813555456,1403636579813555456.png\r\n"
           "1403636579863555584,1403636579863555584.png\r\n");
  dir.Text("mav0/cam1/data.csv",
           "#timestamp [ns],filename\n1403636579763555584,1403636579763555584.png\n"
           "1403636579863555584,1403636579863555584.png\n");
  EXPECT_EQ(DetectDatasetLayout(dir.path()), DatasetLayout::kEuroc);
  auto frames = ReadDatasetFrames(dir.path(), DatasetLayout::kEuroc);
  ASSERT_TRUE(frames.ok()) << frames.status().ToString();
  ASSERT_EQ(frames->size(), 3u);
  EXPECT_NEAR((*frames)[1].timestamp, 1403636579.813555456, 1e-6);
  EXPECT_EQ((*frames)[1].image, dir / "mav0/cam0/data/1403636579813555456.png");
  EXPECT_EQ((*frames)[0].right, dir / "mav0/cam1/data/1403636579763555584.png");
  EXPECT_EQ((*frames)[1].right, "");  // cam1 has no such row
  EXPECT_EQ((*frames)[2].right, dir / "mav0/cam1/data/1403636579863555584.png");
  // mav0 itself is a EuRoC folder too.
  auto mav0 = ReadDatasetFrames(dir / "mav0", DetectDatasetLayout(dir / "mav0"));
  ASSERT_TRUE(mav0.ok()) << mav0.status().ToString();
  EXPECT_EQ(mav0->size(), 3u);

  dir.Text("mav0/cam0/data.csv", "1403636579763555584;1403636579763555584.png\n");
  ExpectError(ReadDatasetFrames(dir.path(), DatasetLayout::kEuroc), StatusCode::kInvalidArgument,
              "line 1");
  dir.Text("mav0/cam0/data.csv",
           "1403636579813555456,1403636579813555456.png\n"
           "1403636579763555584,1403636579763555584.png\n");
  ExpectError(ReadDatasetFrames(dir.path(), DatasetLayout::kEuroc), StatusCode::kInvalidArgument,
              "increase");
  dir.Text("mav0/cam0/data.csv", "1403636579763555584,missing.png\n");
  ExpectError(ReadDatasetFrames(dir.path(), DatasetLayout::kEuroc), StatusCode::kNotFound,
              "missing.png");
}

TEST(KittiTest, TimesInSecondsWithLeftAndRightImages) {
  Fixture dir("kitti");
  for (const char* name : {"000000.png", "000001.png", "000002.png"}) {
    dir.Png(std::string("image_0/") + name, 10);
    dir.Png(std::string("image_1/") + name, 20);
  }
  dir.Text("times.txt", "0.000000e+00\n1.036400e-01\n2.072800e-01\n");
  EXPECT_EQ(DetectDatasetLayout(dir.path()), DatasetLayout::kKitti);
  auto frames = ReadDatasetFrames(dir.path(), DatasetLayout::kKitti);
  ASSERT_TRUE(frames.ok()) << frames.status().ToString();
  ASSERT_EQ(frames->size(), 3u);
  EXPECT_DOUBLE_EQ((*frames)[1].timestamp, 0.10364);
  EXPECT_EQ((*frames)[2].image, dir / "image_0/000002.png");
  EXPECT_EQ((*frames)[2].right, dir / "image_1/000002.png");

  dir.Text("times.txt", "0.0\n0.1\n0.2\n0.3\n");  // no image for frame 3
  ExpectError(ReadDatasetFrames(dir.path(), DatasetLayout::kKitti), StatusCode::kNotFound,
              "000003.png");
  dir.Text("times.txt", "0.0\n0.2\n0.1\n");
  ExpectError(ReadDatasetFrames(dir.path(), DatasetLayout::kKitti), StatusCode::kInvalidArgument,
              "increase");
  dir.Text("times.txt", "0.0\n-0.1\n");
  ExpectError(ReadDatasetFrames(dir.path(), DatasetLayout::kKitti), StatusCode::kInvalidArgument,
              "line 2");
  dir.Text("times.txt", "0.0\nnan\n");
  ExpectError(ReadDatasetFrames(dir.path(), DatasetLayout::kKitti), StatusCode::kInvalidArgument,
              "line 2");
}

// One KITTI rule for every reader: times.txt beside a camera folder image_N/, with or without
// calib.txt and whichever cameras the sequence has.
TEST(KittiTest, DetectedByItsTimesBesideACameraFolder) {
  Fixture dir("kitti_rule");
  dir.Text("times.txt", "0.0\n0.1\n");
  EXPECT_EQ(DetectDatasetLayout(dir.path()), DatasetLayout::kFolder) << "times.txt alone";
  dir.Png("image_2/000000.png");
  dir.Png("image_2/000001.png");
  EXPECT_EQ(DetectDatasetLayout(dir.path()), DatasetLayout::kKitti) << "a colour sequence";
  // The single-camera reader takes image_0/ and names it when the sequence has none.
  ExpectError(ReadDatasetFrames(dir.path(), DatasetLayout::kKitti), StatusCode::kNotFound,
              "image_0/000000.png");
  dir.Text("calib.txt", "P0: 1 0 0 0 0 1 0 0 0 0 1 0\n");
  EXPECT_EQ(DetectDatasetLayout(dir.path()), DatasetLayout::kKitti);

  Fixture images_only("kitti_no_times");
  images_only.Png("image_0/000000.png");
  images_only.Text("calib.txt", "P0: 1 0 0 0 0 1 0 0 0 0 1 0\n");
  EXPECT_EQ(DetectDatasetLayout(images_only.path()), DatasetLayout::kFolder);
}

TEST(DatasetLayoutTest, NamesParseAndAPlainFolderHasNoTimestamps) {
  for (const DatasetLayout layout : {DatasetLayout::kFolder, DatasetLayout::kTum,
                                     DatasetLayout::kEuroc, DatasetLayout::kKitti}) {
    auto parsed = ParseDatasetLayout(DatasetLayoutName(layout));
    ASSERT_TRUE(parsed.ok());
    EXPECT_EQ(*parsed, layout);
  }
  EXPECT_EQ(ParseDatasetLayout("tum-rgbd").status().code(), StatusCode::kInvalidArgument);

  Fixture dir("folder");
  dir.Png("1.png", 0);
  EXPECT_EQ(DetectDatasetLayout(dir.path()), DatasetLayout::kFolder);
  ExpectError(ReadDatasetFrames(dir.path(), DatasetLayout::kFolder), StatusCode::kInvalidArgument,
              "no timestamps");
  // A layout forced on a folder that does not have it: the missing list file.
  ExpectError(ReadDatasetFrames(dir.path(), DatasetLayout::kKitti), StatusCode::kNotFound,
              "times.txt");
  // A layout is for folders only.
  auto file = FrameSource::Open(dir / "1.png", DatasetLayout::kTum);
  EXPECT_EQ(file.status().code(), StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace recog::cli
