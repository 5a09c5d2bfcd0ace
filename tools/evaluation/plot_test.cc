// WritePlot: the CSV and the JSON beside the image, the PNG gnuplot draws at the requested size,
// thinned point labels, an empty plot, and the refusals.
#include "tools/evaluation/plot.h"

#include <filesystem>
#include <fstream>
#include <sstream>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

namespace recog::cli {
namespace {

namespace fs = std::filesystem;

class PlotTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("recog-plot-test-" + std::to_string(::testing::UnitTest::GetInstance()->random_seed()) +
            "-" + ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  static std::string Read(const fs::path& path) {
    std::ifstream in(path);
    std::stringstream text;
    text << in.rdbuf();
    return text.str();
  }

  fs::path dir_;
};

TEST_F(PlotTest, APrCurveIsDrawnAtItsSizeWithItsNumbersInTheCsvBeside) {
  PlotSeries curve;
  curve.label = "corridor, k = 3";
  for (int i = 0; i <= 10; ++i) {  // alpha 1.0 .. 0.0: the labels crowd near recall 1
    curve.points.push_back({0.9 + 0.01 * i, 1.0 - 0.001 * i});
    char alpha[8];
    std::snprintf(alpha, sizeof(alpha), "%.1f", 1.0 - 0.1 * i);
    curve.point_labels.push_back(alpha);
  }
  PlotOptions options;
  options.title = "Precision-recall \"quoted\" and under_scored";
  options.x_label = "recall";
  options.y_label = "precision";
  options.width = 640;
  options.height = 480;
  const std::string png = (dir_ / "pr.png").string();
  ASSERT_TRUE(WritePlot(png, options, {curve}).ok());
  const cv::Mat image = cv::imread(png);
  ASSERT_FALSE(image.empty());
  EXPECT_EQ(image.cols, 640);
  EXPECT_EQ(image.rows, 480);
  cv::Mat grey;
  cv::cvtColor(image, grey, cv::COLOR_BGR2GRAY);
  EXPECT_GT(cv::countNonZero(grey < 128), 500) << "axes, text and the curve are drawn";

  const std::string csv = Read(dir_ / "pr.csv");
  std::istringstream lines(csv);
  std::string line;
  std::getline(lines, line);
  EXPECT_EQ(line, "series,recall,precision,point_label");
  std::getline(lines, line);
  EXPECT_EQ(line, "\"corridor, k = 3\",0.9,1,1.0") << "every label stays in the CSV";
  int rows = 1;
  while (std::getline(lines, line)) ++rows;
  EXPECT_EQ(rows, 11);

  // The chart for the web console: everything gnuplot drew, labels included.
  const nlohmann::json chart = nlohmann::json::parse(Read(dir_ / "pr.json"));
  EXPECT_EQ(chart["title"], options.title);
  EXPECT_EQ(chart["x_label"], "recall");
  EXPECT_EQ(chart["y_max"], 1.0);
  ASSERT_EQ(chart["series"].size(), 1u);
  const nlohmann::json& series = chart["series"][0];
  EXPECT_EQ(series["label"], "corridor, k = 3");
  EXPECT_EQ(series["color"], "#1450c8");
  ASSERT_EQ(series["points"].size(), 11u);
  EXPECT_DOUBLE_EQ(series["points"][10][0].get<double>(), 1.0);
  EXPECT_EQ(series["point_labels"][0], "1.0");
}

TEST_F(PlotTest, APlotWithoutPointsHasItsAxesAndARichCsvOfTheCallerIsLeftAlone) {
  const std::string png = (dir_ / "empty.png").string();
  { std::ofstream(dir_ / "empty.csv") << "the caller's own\n"; }
  PlotOptions options;
  options.write_csv = false;
  ASSERT_TRUE(WritePlot(png, options, {PlotSeries{}}).ok());
  EXPECT_EQ(cv::imread(png).cols, options.width);
  EXPECT_EQ(Read(dir_ / "empty.csv"), "the caller's own\n");
}

TEST_F(PlotTest, BadRangesPathsAndFoldersAreRefused) {
  PlotOptions options;
  options.x_max = options.x_min;
  EXPECT_EQ(WritePlot((dir_ / "a.png").string(), options, {}).code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(WritePlot((dir_ / "a.csv").string(), PlotOptions{}, {}).code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(WritePlot((dir_ / "a.json").string(), PlotOptions{}, {}).code(),
            StatusCode::kInvalidArgument);
  const Status missing = WritePlot((dir_ / "no-such-folder" / "a.png").string(), PlotOptions{}, {});
  EXPECT_EQ(missing.code(), StatusCode::kInternal);
  EXPECT_NE(missing.message().find("no-such-folder"), std::string::npos) << missing.ToString();
  EXPECT_FALSE(fs::exists(dir_ / "a.png"));
  EXPECT_FALSE(fs::exists(dir_ / "a.json"));
  PlotOptions no_csv;
  no_csv.write_csv = false;  // gnuplot itself cannot write the image there
  const Status refused = WritePlot((dir_ / "no-such-folder" / "b.png").string(), no_csv, {});
  EXPECT_EQ(refused.code(), StatusCode::kInternal);
  EXPECT_NE(refused.message().find("gnuplot"), std::string::npos) << refused.ToString();
}

}  // namespace
}  // namespace recog::cli
