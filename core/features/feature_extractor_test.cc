#include "core/features/feature_extractor.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <unistd.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/common/descriptor.h"
#include "tests/testing/test_data.h"

namespace recog {
namespace {

using ::testing::HasSubstr;

cv::Mat LoadGray(const std::string& name) {
  StatusOr<cv::Mat> image = ReadGrayImage(testing::ProjectTestData("corridor/" + name));
  EXPECT_TRUE(image.ok()) << image.status().ToString();
  return image.ok() ? *image : cv::Mat();
}

FeatureOptions OptionsFor(FeatureType type) {
  FeatureOptions options;
  options.type = type;
  return options;
}

std::unique_ptr<FeatureExtractor> MakeExtractor(const FeatureOptions& options) {
  auto extractor = CreateFeatureExtractor(options);
  EXPECT_TRUE(extractor.ok()) << extractor.status().ToString();
  return extractor.ok() ? std::move(*extractor) : nullptr;
}

FeatureSet ExtractOrDie(FeatureExtractor& extractor, const cv::Mat& image) {
  FeatureSet features;
  const Status status = extractor.Extract(image, &features);
  EXPECT_TRUE(status.ok()) << status.ToString();
  return features;
}

FeatureSet ExtractOrDie(const FeatureOptions& options, const cv::Mat& image) {
  auto extractor = MakeExtractor(options);
  if (extractor == nullptr) return {};
  return ExtractOrDie(*extractor, image);
}

// True when both sets hold the same keypoints in the same order with byte-identical descriptors.
bool SameFeatures(const FeatureSet& a, const FeatureSet& b) {
  if (a.size() != b.size()) return false;
  for (size_t i = 0; i < a.size(); ++i) {
    const cv::KeyPoint& p = a.keypoints[i];
    const cv::KeyPoint& q = b.keypoints[i];
    if (p.pt != q.pt || p.response != q.response || p.size != q.size || p.angle != q.angle ||
        p.octave != q.octave) {
      return false;
    }
  }
  if (a.descriptors.size() != b.descriptors.size() ||
      a.descriptors.type() != b.descriptors.type()) {
    return false;
  }
  if (a.descriptors.empty()) return true;
  return std::equal(a.descriptors.datastart, a.descriptors.dataend, b.descriptors.datastart);
}

bool SortedByDecreasingResponse(const FeatureSet& features) {
  for (size_t i = 1; i < features.size(); ++i) {
    if (features.keypoints[i - 1].response < features.keypoints[i].response) return false;
  }
  return true;
}

// Features per cell of a rows x cols grid over an image of `size`, row-major.
std::vector<int> CellCounts(const FeatureSet& features, cv::Size size, int rows, int cols) {
  std::vector<int> counts(size_t(rows * cols), 0);
  for (const cv::KeyPoint& kp : features.keypoints) {
    const int r = std::clamp(int(double(kp.pt.y) * rows / size.height), 0, rows - 1);
    const int c = std::clamp(int(double(kp.pt.x) * cols / size.width), 0, cols - 1);
    ++counts[size_t(r * cols + c)];
  }
  return counts;
}

int OccupiedCells(const std::vector<int>& counts) {
  return int(std::count_if(counts.begin(), counts.end(), [](int n) { return n > 0; }));
}

// Mean Hamming distance between the descriptors of row i in `a` and row i in `b`.
double MeanRowDistance(const cv::Mat& a, const cv::Mat& b) {
  EXPECT_EQ(a.rows, b.rows);
  const int rows = std::min(a.rows, b.rows);
  if (rows == 0) return 0;
  double sum = 0;
  for (int i = 0; i < rows; ++i) sum += Hamming256(a.ptr<uint8_t>(i), b.ptr<uint8_t>(i));
  return sum / rows;
}

// ---------------------------------------------------------------------------------------------
// Names and options

TEST(FeatureTypeTest, NamesRoundTripThroughParse) {
  for (FeatureType type : {FeatureType::kOrb, FeatureType::kFastBrief, FeatureType::kSift}) {
    StatusOr<FeatureType> parsed = ParseFeatureType(FeatureTypeName(type));
    ASSERT_TRUE(parsed.ok()) << parsed.status().ToString();
    EXPECT_EQ(*parsed, type);
  }
  EXPECT_EQ(FeatureTypeName(FeatureType::kOrb), "orb");
  EXPECT_EQ(FeatureTypeName(FeatureType::kFastBrief), "brief");
  EXPECT_EQ(FeatureTypeName(FeatureType::kSift), "sift");
}

TEST(FeatureTypeTest, ParseRejectsUnknownNames) {
  for (const char* name : {"", "surf", "ORB", "orb "}) {
    StatusOr<FeatureType> parsed = ParseFeatureType(name);
    ASSERT_FALSE(parsed.ok()) << "'" << name << "' was accepted";
    EXPECT_EQ(parsed.status().code(), StatusCode::kInvalidArgument);
    EXPECT_THAT(parsed.status().message(), HasSubstr("'orb', 'brief' or 'sift'"));
  }
}

TEST(FeatureOptionsTest, DefaultOptionsAreValid) {
  for (FeatureType type : {FeatureType::kOrb, FeatureType::kFastBrief, FeatureType::kSift}) {
    EXPECT_TRUE(OptionsFor(type).Validate().ok()) << FeatureTypeName(type);
  }
}

TEST(FeatureOptionsTest, ValidateRejectsEachOutOfRangeValueNamingTheField) {
  struct Case {
    std::string field;  // expected in the message
    std::function<void(FeatureOptions&)> break_it;
  };
  const std::vector<Case> cases = {
      {"orb.max_features", [](FeatureOptions& o) { o.orb.max_features = 0; }},
      {"orb.max_features", [](FeatureOptions& o) { o.orb.max_features = -5; }},
      {"orb.scale_factor", [](FeatureOptions& o) { o.orb.scale_factor = 1.f; }},
      {"orb.scale_factor", [](FeatureOptions& o) { o.orb.scale_factor = 0.5f; }},
      {"orb.scale_factor", [](FeatureOptions& o) { o.orb.scale_factor = std::nanf(""); }},
      {"orb.levels", [](FeatureOptions& o) { o.orb.levels = 0; }},
      {"orb.levels", [](FeatureOptions& o) { o.orb.levels = 33; }},
      {"orb.fast_threshold", [](FeatureOptions& o) { o.orb.fast_threshold = 0; }},
      {"orb.fast_threshold", [](FeatureOptions& o) { o.orb.fast_threshold = 256; }},
      {"orb.edge_threshold", [](FeatureOptions& o) { o.orb.edge_threshold = -1; }},
      {"orb.grid_rows",
       [](FeatureOptions& o) {
         o.orb.grid_rows = -1;
         o.orb.grid_cols = -1;
       }},
      {"orb.grid_rows",
       [](FeatureOptions& o) {
         o.orb.grid_rows = 4;
         o.orb.grid_cols = 0;
       }},
      {"orb.grid_cols",
       [](FeatureOptions& o) {
         o.orb.grid_rows = 0;
         o.orb.grid_cols = 3;
       }},
      {"orb.grid_cols",
       [](FeatureOptions& o) {
         o.orb.grid_rows = 4;
         o.orb.grid_cols = 257;
       }},
      {"orb.min_short_side", [](FeatureOptions& o) { o.orb.min_short_side = -1; }},
      {"orb.min_short_side", [](FeatureOptions& o) { o.orb.min_short_side = 5000; }},
      {"orb.grid_fill_cap", [](FeatureOptions& o) { o.orb.grid_fill_cap = -1; }},
      {"orb.grid_fill_cap", [](FeatureOptions& o) { o.orb.grid_fill_cap = std::nan(""); }},
      {"orb.max_features", [](FeatureOptions& o) { o.orb.max_features = 2'000'000; }},
      {"brief.max_features", [](FeatureOptions& o) { o.brief.max_features = 0; }},
      {"brief.fast_threshold", [](FeatureOptions& o) { o.brief.fast_threshold = 0; }},
      {"brief.fast_threshold", [](FeatureOptions& o) { o.brief.fast_threshold = 300; }},
      {"brief.patch_size", [](FeatureOptions& o) { o.brief.patch_size = 14; }},
      {"brief.patch_size", [](FeatureOptions& o) { o.brief.patch_size = 66; }},
      {"brief.patch_size", [](FeatureOptions& o) { o.brief.patch_size = 47; }},
      {"brief.smoothing_sigma", [](FeatureOptions& o) { o.brief.smoothing_sigma = -0.5; }},
      {"brief.smoothing_sigma", [](FeatureOptions& o) { o.brief.smoothing_sigma = std::nan(""); }},
      {"sift.max_features", [](FeatureOptions& o) { o.sift.max_features = 0; }},
  };
  for (const Case& c : cases) {
    FeatureOptions options;
    c.break_it(options);
    const Status status = options.Validate();
    ASSERT_FALSE(status.ok()) << c.field << " case was accepted";
    EXPECT_EQ(status.code(), StatusCode::kInvalidArgument) << status.ToString();
    EXPECT_THAT(status.message(), HasSubstr(c.field));
  }
}

TEST(FeatureOptionsTest, ValidateAcceptsBoundaryValues) {
  FeatureOptions options;
  options.orb.max_features = 1;
  options.orb.levels = 32;
  options.orb.fast_threshold = 255;
  options.orb.edge_threshold = 0;
  options.orb.grid_rows = 1;
  options.orb.grid_cols = 7;
  options.brief.patch_size = 16;
  options.brief.smoothing_sigma = 0;
  options.brief.fast_threshold = 1;
  EXPECT_TRUE(options.Validate().ok()) << options.Validate().ToString();
  options.brief.patch_size = 64;
  EXPECT_TRUE(options.Validate().ok()) << options.Validate().ToString();
}

TEST(FeatureOptionsTest, CreateFeatureExtractorRejectsInvalidOptions) {
  FeatureOptions options;
  options.type = FeatureType::kFastBrief;
  options.brief.patch_size = 15;
  auto extractor = CreateFeatureExtractor(options);
  ASSERT_FALSE(extractor.ok());
  EXPECT_EQ(extractor.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(extractor.status().message(), HasSubstr("brief.patch_size"));
}

TEST(FeatureOptionsTest, EachTypeBuildsAnExtractorOfItsFormat) {
  EXPECT_EQ(MakeExtractor(OptionsFor(FeatureType::kOrb))->format(), DescriptorFormat::Orb());
  EXPECT_EQ(MakeExtractor(OptionsFor(FeatureType::kFastBrief))->format(),
            DescriptorFormat::Brief256());
  EXPECT_EQ(MakeExtractor(OptionsFor(FeatureType::kSift))->format(), DescriptorFormat::Sift());
}

// ---------------------------------------------------------------------------------------------
// ReadGrayImage

TEST(ReadGrayImageTest, ReadsAJpegAsEightBitGrey) {
  StatusOr<cv::Mat> image = ReadGrayImage(testing::ProjectTestData("corridor/1.jpg"));
  ASSERT_TRUE(image.ok()) << image.status().ToString();
  EXPECT_EQ(image->type(), CV_8UC1);
  EXPECT_EQ(image->cols, 512);
  EXPECT_EQ(image->rows, 384);
}

TEST(ReadGrayImageTest, MissingFileIsNotFound) {
  StatusOr<cv::Mat> image = ReadGrayImage(testing::ProjectTestData("corridor/no_such_image.jpg"));
  ASSERT_FALSE(image.ok());
  EXPECT_EQ(image.status().code(), StatusCode::kNotFound);
  EXPECT_THAT(image.status().message(), HasSubstr("no_such_image.jpg"));
}

TEST(ReadGrayImageTest, UndecodableFileIsInvalidArgument) {
  const std::filesystem::path dir =
      std::filesystem::temp_directory_path() / ("recog_feature_test_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  const std::filesystem::path path = dir / "garbage.jpg";
  {
    std::ofstream file(path, std::ios::binary);
    file << "this is not a JPEG file, just some text pretending to be one\n";
  }
  StatusOr<cv::Mat> image = ReadGrayImage(path.string());
  std::filesystem::remove_all(dir);
  ASSERT_FALSE(image.ok());
  EXPECT_EQ(image.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(image.status().message(), HasSubstr("garbage.jpg"));
}

// ---------------------------------------------------------------------------------------------
// Behaviour every extractor shares

class EveryExtractorTest : public ::testing::TestWithParam<FeatureType> {
 protected:
  FeatureOptions Options() const { return OptionsFor(GetParam()); }

  // Extract() on `image` must fail with INVALID_ARGUMENT and leave no features behind.
  void ExpectRejected(const cv::Mat& image) {
    auto extractor = MakeExtractor(Options());
    ASSERT_NE(extractor, nullptr);
    FeatureSet features;
    features.keypoints.resize(3);
    const Status status = extractor->Extract(image, &features);
    EXPECT_EQ(status.code(), StatusCode::kInvalidArgument) << status.ToString();
    EXPECT_EQ(features.size(), 0u);
  }
};

TEST_P(EveryExtractorTest, RejectsAnEmptyImage) { ExpectRejected(cv::Mat()); }

TEST_P(EveryExtractorTest, RejectsAFloatImage) { ExpectRejected(cv::Mat(64, 64, CV_32F, 0.5)); }

TEST_P(EveryExtractorTest, RejectsASixteenBitImage) {
  ExpectRejected(cv::Mat(64, 64, CV_16UC1, cv::Scalar(1000)));
}

TEST_P(EveryExtractorTest, RejectsAFourChannelImage) {
  ExpectRejected(cv::Mat(64, 64, CV_8UC4, cv::Scalar(1, 2, 3, 4)));
}

TEST_P(EveryExtractorTest, RejectionMessageNamesThePixelType) {
  auto extractor = MakeExtractor(Options());
  FeatureSet features;
  const Status status = extractor->Extract(cv::Mat(8, 8, CV_32FC1, 0.f), &features);
  EXPECT_THAT(status.message(), HasSubstr("CV_32FC1"));
}

TEST_P(EveryExtractorTest, ReturnsConsistentSortedFeaturesOnARealImage) {
  const cv::Mat image = LoadGray("1.jpg");
  const FeatureOptions options = Options();
  auto extractor = MakeExtractor(options);
  const FeatureSet features = ExtractOrDie(*extractor, image);
  const DescriptorFormat format = extractor->format();

  ASSERT_GT(features.size(), 50u);
  EXPECT_LE(features.size(), 1000u);
  EXPECT_EQ(features.descriptors.rows, int(features.size()));
  EXPECT_EQ(features.descriptors.cols, format.cols());
  EXPECT_EQ(features.descriptors.type(), format.cv_type());
  EXPECT_TRUE(features.descriptors.isContinuous());
  EXPECT_TRUE(CheckDescriptorMatrix(features.descriptors, format).ok());
  EXPECT_TRUE(SortedByDecreasingResponse(features));
  for (const cv::KeyPoint& kp : features.keypoints) {
    EXPECT_GE(kp.pt.x, 0.f);
    EXPECT_GE(kp.pt.y, 0.f);
    EXPECT_LT(kp.pt.x, float(image.cols));
    EXPECT_LT(kp.pt.y, float(image.rows));
  }
}

TEST_P(EveryExtractorTest, IsDeterministicAcrossCallsAndInstances) {
  const cv::Mat image = LoadGray("20.jpg");
  auto extractor = MakeExtractor(Options());
  const FeatureSet first = ExtractOrDie(*extractor, image);
  const FeatureSet again = ExtractOrDie(*extractor, image);
  const FeatureSet fresh = ExtractOrDie(Options(), image);
  ASSERT_GT(first.size(), 0u);
  EXPECT_TRUE(SameFeatures(first, again));
  EXPECT_TRUE(SameFeatures(first, fresh));
}

TEST_P(EveryExtractorTest, ColourImageGivesTheSameFeaturesAsItsGreyConversion) {
  const cv::Mat colour = cv::imread(testing::ProjectTestData("corridor/41.jpg"), cv::IMREAD_COLOR);
  ASSERT_EQ(colour.type(), CV_8UC3);
  cv::Mat grey;
  cv::cvtColor(colour, grey, cv::COLOR_BGR2GRAY);
  const FeatureSet from_colour = ExtractOrDie(Options(), colour);
  const FeatureSet from_grey = ExtractOrDie(Options(), grey);
  ASSERT_GT(from_grey.size(), 0u);
  EXPECT_TRUE(SameFeatures(from_colour, from_grey));
}

TEST_P(EveryExtractorTest, ImageViewGivesTheSameFeaturesAsACompactCopy) {
  const cv::Mat image = LoadGray("60.jpg");
  const cv::Mat view = image(cv::Rect(30, 20, 400, 300));  // not continuous
  ASSERT_FALSE(view.isContinuous());
  const FeatureSet from_view = ExtractOrDie(Options(), view);
  const FeatureSet from_copy = ExtractOrDie(Options(), view.clone());
  ASSERT_GT(from_copy.size(), 0u);
  EXPECT_TRUE(SameFeatures(from_view, from_copy));
}

TEST_P(EveryExtractorTest, ClearsPreviousContentsOfTheOutput) {
  auto extractor = MakeExtractor(Options());
  FeatureSet features = ExtractOrDie(*extractor, LoadGray("1.jpg"));
  ASSERT_GT(features.size(), 0u);
  ASSERT_TRUE(extractor->Extract(cv::Mat(100, 100, CV_8UC1, cv::Scalar(90)), &features).ok());
  EXPECT_EQ(features.size(), 0u);
  EXPECT_EQ(features.descriptors.rows, 0);
}

TEST_P(EveryExtractorTest, BlankImageYieldsNoFeaturesWithoutError) {
  auto extractor = MakeExtractor(Options());
  for (const cv::Mat& blank : {cv::Mat(384, 512, CV_8UC1, cv::Scalar(128)),
                               cv::Mat(200, 300, CV_8UC3, cv::Scalar::all(0))}) {
    FeatureSet features;
    const Status status = extractor->Extract(blank, &features);
    ASSERT_TRUE(status.ok()) << status.ToString();
    EXPECT_EQ(features.size(), 0u);
    EXPECT_EQ(features.descriptors.rows, 0);
    EXPECT_TRUE(CheckDescriptorMatrix(features.descriptors, extractor->format()).ok());
  }
}

TEST_P(EveryExtractorTest, TinyImagesSucceed) {
  auto extractor = MakeExtractor(Options());
  cv::RNG rng(7);
  for (int side : {1, 2, 3, 5, 9, 17, 33}) {
    cv::Mat noise(side, side, CV_8UC1);
    rng.fill(noise, cv::RNG::UNIFORM, 0, 256);
    FeatureSet features;
    const Status status = extractor->Extract(noise, &features);
    ASSERT_TRUE(status.ok()) << side << "x" << side << ": " << status.ToString();
    EXPECT_EQ(features.descriptors.rows, int(features.size()));
    if (side <= 5) {
      EXPECT_EQ(features.size(), 0u) << side << "x" << side;
    }
  }
}

INSTANTIATE_TEST_SUITE_P(AllTypes, EveryExtractorTest,
                         ::testing::Values(FeatureType::kOrb, FeatureType::kFastBrief,
                                           FeatureType::kSift),
                         [](const ::testing::TestParamInfo<FeatureType>& info) {
                           return std::string(FeatureTypeName(info.param));
                         });

// ---------------------------------------------------------------------------------------------
// ORB

TEST(OrbTest, ReturnsAtMostMaxFeatures) {
  const cv::Mat image = LoadGray("1.jpg");
  for (int max_features : {1, 37, 100, 300}) {
    FeatureOptions options = OptionsFor(FeatureType::kOrb);
    options.orb.max_features = max_features;
    const FeatureSet features = ExtractOrDie(options, image);
    EXPECT_LE(features.size(), size_t(max_features));
    // The corridor image has several hundred ORB corners, so small budgets are filled.
    EXPECT_GE(features.size(), size_t(max_features) * 9 / 10) << max_features;
    EXPECT_EQ(features.descriptors.rows, int(features.size()));
  }
}

TEST(OrbTest, ManyPyramidLevelsOnASmallImageDoNotFail) {
  // 32 levels at scale 2 shrink a 512x384 image below one pixel; those levels must be skipped.
  FeatureOptions options = OptionsFor(FeatureType::kOrb);
  options.orb.levels = 32;
  options.orb.scale_factor = 2.f;
  const FeatureSet features = ExtractOrDie(options, LoadGray("1.jpg"));
  EXPECT_GT(features.size(), 0u);
}

TEST(OrbTest, ASmallFrameIsDescribedOnItsEnlargementWithKeypointsInItsOwnPixels) {
  cv::Mat small;
  cv::resize(LoadGray("1.jpg"), small, cv::Size(128, 96), 0, 0, cv::INTER_AREA);
  FeatureOptions plain = OptionsFor(FeatureType::kOrb);
  const FeatureSet unenlarged = ExtractOrDie(plain, small);
  const FeatureSet features = ExtractOrDie(PlaceFeatureOptions(), small);
  EXPECT_GT(features.size(), 4 * unenlarged.size() + 100) << "ORB's border leaves little of 128x96";

  // The same features as ORB on the frame enlarged by hand to a 352-pixel short side, with
  // positions and sizes divided by the enlargement (pixel centres: (x + 0.5) / s - 0.5).
  cv::Mat enlarged;
  cv::resize(small, enlarged, cv::Size(469, 352), 0, 0, cv::INTER_LINEAR);
  const FeatureSet reference = ExtractOrDie(plain, enlarged);
  ASSERT_EQ(features.size(), reference.size());
  EXPECT_EQ(cv::norm(features.descriptors, reference.descriptors, cv::NORM_HAMMING), 0);
  for (size_t i = 0; i < features.size(); ++i) {
    const cv::KeyPoint& a = features.keypoints[i];
    const cv::KeyPoint& b = reference.keypoints[i];
    EXPECT_NEAR(a.pt.x, (b.pt.x + 0.5f) * 128.f / 469.f - 0.5f, 1e-3) << i;
    EXPECT_NEAR(a.pt.y, (b.pt.y + 0.5f) * 96.f / 352.f - 0.5f, 1e-3) << i;
    EXPECT_NEAR(a.size, b.size * 128.f / 469.f, 1e-3) << i;
    EXPECT_EQ(a.octave, b.octave);
    ASSERT_TRUE(a.pt.x >= 0 && a.pt.x <= 127 && a.pt.y >= 0 && a.pt.y <= 95) << a.pt;
  }
}

TEST(OrbTest, AFrameAsLargeAsTheMinimumShortSideIsNotEnlarged) {
  const cv::Mat image = LoadGray("1.jpg");  // 512x384: its short side is over 352
  const FeatureSet place = ExtractOrDie(PlaceFeatureOptions(), image);
  const FeatureSet plain = ExtractOrDie(OptionsFor(FeatureType::kOrb), image);
  ASSERT_EQ(place.size(), plain.size());
  EXPECT_EQ(cv::norm(place.descriptors, plain.descriptors, cv::NORM_HAMMING), 0);
  for (size_t i = 0; i < place.size(); ++i) EXPECT_EQ(place.keypoints[i].pt, plain.keypoints[i].pt);
}

TEST(OrbTest, GridKeepsEveryCellWithinItsShare) {
  const cv::Mat image = LoadGray("1.jpg");
  FeatureOptions options = OptionsFor(FeatureType::kOrb);
  options.orb.max_features = 200;
  options.orb.grid_rows = 4;
  options.orb.grid_cols = 4;
  const FeatureSet features = ExtractOrDie(options, image);
  const int share = (200 + 15) / 16;  // 13: the remainder of 200 / 16 goes one per cell at most
  EXPECT_LE(features.size(), 200u);
  EXPECT_GT(features.size(), 100u);
  EXPECT_TRUE(SortedByDecreasingResponse(features));
  EXPECT_EQ(features.descriptors.rows, int(features.size()));
  for (int count : CellCounts(features, image.size(), 4, 4)) EXPECT_LE(count, share);
}

TEST(OrbTest, GridSpreadsFeaturesOverMoreOfTheImage) {
  const cv::Mat image = LoadGray("1.jpg");
  FeatureOptions plain = OptionsFor(FeatureType::kOrb);
  plain.orb.max_features = 200;
  FeatureOptions gridded = plain;
  gridded.orb.grid_rows = 4;
  gridded.orb.grid_cols = 4;
  const FeatureSet without_grid = ExtractOrDie(plain, image);
  const FeatureSet with_grid = ExtractOrDie(gridded, image);

  const std::vector<int> cells_plain = CellCounts(without_grid, image.size(), 4, 4);
  const std::vector<int> cells_grid = CellCounts(with_grid, image.size(), 4, 4);
  const int busiest_plain = *std::max_element(cells_plain.begin(), cells_plain.end());
  const int busiest_grid = *std::max_element(cells_grid.begin(), cells_grid.end());
  // Without the grid the textured middle of the corridor takes far more than a fair share...
  EXPECT_GT(busiest_plain, 2 * 13);
  // ...with it, the busiest cell is capped, holds a smaller fraction of all features, and
  // features reach cells that had none.
  EXPECT_LE(busiest_grid, 13);
  ASSERT_GT(with_grid.size(), 0u);
  EXPECT_LT(double(busiest_grid) / double(with_grid.size()),
            double(busiest_plain) / double(without_grid.size()));
  EXPECT_GT(OccupiedCells(cells_grid), OccupiedCells(cells_plain));
}

TEST(OrbTest, GridFillGivesTheShareOfPlainCellsToTexturedOnesUpToTheCap) {
  // The corridor frame with its left half blanked: the plain cells find no corner, so a plain
  // grid leaves their share unused; the fill hands it to the textured cells, none beyond the cap.
  cv::Mat image = LoadGray("1.jpg").clone();
  image(cv::Rect(0, 0, image.cols / 2, image.rows)).setTo(128);
  FeatureOptions plain = OptionsFor(FeatureType::kOrb);
  plain.orb.max_features = 320;
  plain.orb.grid_rows = plain.orb.grid_cols = 4;  // a share of 20 a cell
  FeatureOptions filled = plain;
  filled.orb.grid_fill_cap = 2;
  const FeatureSet without_fill = ExtractOrDie(plain, image);
  const FeatureSet with_fill = ExtractOrDie(filled, image);
  EXPECT_LE(without_fill.size(), 160u);  // the 8 textured cells, 20 each at most
  EXPECT_GT(with_fill.size(), without_fill.size() + 40);
  EXPECT_LE(with_fill.size(), 320u);
  EXPECT_TRUE(SortedByDecreasingResponse(with_fill));
  EXPECT_EQ(with_fill.descriptors.rows, int(with_fill.size()));
  const std::vector<int> cells = CellCounts(with_fill, image.size(), 4, 4);
  for (int count : cells) EXPECT_LE(count, 40);  // 2 shares
  // Every feature the plain grid kept is kept with the fill (it only adds).
  for (const cv::KeyPoint& kept : without_fill.keypoints) {
    EXPECT_TRUE(std::any_of(with_fill.keypoints.begin(), with_fill.keypoints.end(),
                            [&](const cv::KeyPoint& k) { return k.pt == kept.pt; }))
        << kept.pt;
  }
}

TEST(OrbTest, GridWithMoreCellsThanFeaturesGivesTheStrongestCellsOneEach) {
  const cv::Mat image = LoadGray("1.jpg");
  FeatureOptions options = OptionsFor(FeatureType::kOrb);
  options.orb.max_features = 5;
  options.orb.grid_rows = 4;
  options.orb.grid_cols = 4;
  const FeatureSet features = ExtractOrDie(options, image);
  EXPECT_EQ(features.size(), 5u);
  for (int count : CellCounts(features, image.size(), 4, 4)) EXPECT_LE(count, 1);
}

// ---------------------------------------------------------------------------------------------
// FAST + BRIEF

FeatureOptions BriefOptionsWith(const std::function<void(BriefOptions&)>& change) {
  FeatureOptions options = OptionsFor(FeatureType::kFastBrief);
  change(options.brief);
  return options;
}

TEST(BriefTest, KeepsTheStrongestCornersAwayFromTheBorder) {
  const cv::Mat image = LoadGray("1.jpg");
  const FeatureSet all = ExtractOrDie(OptionsFor(FeatureType::kFastBrief), image);
  const FeatureSet few =
      ExtractOrDie(BriefOptionsWith([](BriefOptions& b) { b.max_features = 40; }), image);
  ASSERT_GT(all.size(), 40u);
  ASSERT_EQ(few.size(), 40u);
  // The 40 kept are exactly the first 40 of the full, sorted list.
  for (size_t i = 0; i < few.size(); ++i) {
    EXPECT_EQ(few.keypoints[i].pt, all.keypoints[i].pt) << i;
    EXPECT_EQ(0, std::memcmp(few.descriptors.ptr(int(i)), all.descriptors.ptr(int(i)), 32)) << i;
  }
  for (const cv::KeyPoint& kp : all.keypoints) {
    EXPECT_GE(kp.pt.x, 24.f);
    EXPECT_GE(kp.pt.y, 24.f);
    EXPECT_LE(kp.pt.x, float(image.cols - 1 - 24));
    EXPECT_LE(kp.pt.y, float(image.rows - 1 - 24));
    EXPECT_EQ(kp.size, 48.f);
  }
}

TEST(BriefTest, TranslatedImageGivesNearIdenticalDescriptors) {
  const cv::Mat image = LoadGray("1.jpg");
  const int dx = 11;
  const int dy = 6;
  const cv::Mat shifted = image(cv::Rect(dx, dy, image.cols - dx, image.rows - dy)).clone();
  auto extractor = MakeExtractor(OptionsFor(FeatureType::kFastBrief));
  const FeatureSet original = ExtractOrDie(*extractor, image);
  const FeatureSet moved = ExtractOrDie(*extractor, shifted);
  ASSERT_GT(moved.size(), 100u);

  std::map<std::pair<int, int>, int> original_row;
  for (size_t i = 0; i < original.size(); ++i) {
    original_row[{cvRound(original.keypoints[i].pt.x), cvRound(original.keypoints[i].pt.y)}] =
        int(i);
  }
  int matched = 0;
  int identical = 0;
  double distance_sum = 0;
  for (size_t i = 0; i < moved.size(); ++i) {
    const auto it = original_row.find(
        {cvRound(moved.keypoints[i].pt.x) + dx, cvRound(moved.keypoints[i].pt.y) + dy});
    if (it == original_row.end()) continue;
    ++matched;
    const uint32_t distance = Hamming256(moved.descriptors.ptr<uint8_t>(int(i)),
                                         original.descriptors.ptr<uint8_t>(it->second));
    distance_sum += distance;
    identical += distance == 0 ? 1 : 0;
  }
  // FAST finds the same corners in the shifted image except next to the new borders.
  EXPECT_GE(matched, int(moved.size()) * 9 / 10);
  ASSERT_GT(matched, 0);
  // Corresponding keypoints test the same smoothed pixels (the border margin keeps the blur's
  // edge extrapolation out of every patch), so their descriptors agree: well under 10% of the
  // bits differ, and in fact none do.
  EXPECT_LT(distance_sum / matched, 0.1 * 256);
  EXPECT_EQ(identical, matched);

  // Unrelated keypoints, in contrast, disagree on a large part of the bits.
  double unrelated_sum = 0;
  const size_t n = original.size();
  for (size_t i = 0; i < n; ++i) {
    unrelated_sum += Hamming256(original.descriptors.ptr<uint8_t>(int(i)),
                                original.descriptors.ptr<uint8_t>(int((i + n / 2) % n)));
  }
  EXPECT_GT(unrelated_sum / double(n), 100.0);
  EXPECT_LT(unrelated_sum / double(n), 156.0);
}

TEST(BriefTest, InvertedImageFlipsMostBits) {
  // I(a) < I(b) becomes I(a) > I(b) on the negative image; only equal pairs keep their bit.
  const cv::Mat image = LoadGray("1.jpg");
  cv::Mat negative;
  cv::bitwise_not(image, negative);
  auto extractor = MakeExtractor(OptionsFor(FeatureType::kFastBrief));
  const FeatureSet positive_features = ExtractOrDie(*extractor, image);
  const FeatureSet negative_features = ExtractOrDie(*extractor, negative);
  std::map<std::pair<int, int>, int> row;
  for (size_t i = 0; i < negative_features.size(); ++i) {
    row[{cvRound(negative_features.keypoints[i].pt.x),
         cvRound(negative_features.keypoints[i].pt.y)}] = int(i);
  }
  int matched = 0;
  double distance_sum = 0;
  for (size_t i = 0; i < positive_features.size(); ++i) {
    const auto it = row.find({cvRound(positive_features.keypoints[i].pt.x),
                              cvRound(positive_features.keypoints[i].pt.y)});
    if (it == row.end()) continue;
    ++matched;
    distance_sum += Hamming256(positive_features.descriptors.ptr<uint8_t>(int(i)),
                               negative_features.descriptors.ptr<uint8_t>(it->second));
  }
  ASSERT_GT(matched, 50);
  EXPECT_GT(distance_sum / matched, 0.75 * 256);
}

TEST(BriefTest, PatternSeedChangesTheDescriptorsButNotTheKeypoints) {
  const cv::Mat image = LoadGray("1.jpg");
  const FeatureSet a = ExtractOrDie(OptionsFor(FeatureType::kFastBrief), image);
  const FeatureSet b =
      ExtractOrDie(BriefOptionsWith([](BriefOptions& o) { o.pattern_seed = 12345; }), image);
  ASSERT_EQ(a.size(), b.size());
  ASSERT_GT(a.size(), 0u);
  for (size_t i = 0; i < a.size(); ++i) EXPECT_EQ(a.keypoints[i].pt, b.keypoints[i].pt);
  // Different tests on the same patch: roughly independent bits, about half of them differ.
  EXPECT_GT(MeanRowDistance(a.descriptors, b.descriptors), 100.0);
}

TEST(BriefTest, OriginalBriefPatternWorksAndDiffersFromClosePairs) {
  const cv::Mat image = LoadGray("1.jpg");
  const FeatureOptions original_options =
      BriefOptionsWith([](BriefOptions& o) { o.close_pairs = false; });
  auto extractor = MakeExtractor(original_options);
  const FeatureSet original = ExtractOrDie(*extractor, image);
  const FeatureSet again = ExtractOrDie(*extractor, image);
  const FeatureSet close = ExtractOrDie(OptionsFor(FeatureType::kFastBrief), image);
  ASSERT_GT(original.size(), 0u);
  EXPECT_EQ(original.descriptors.cols, 32);
  EXPECT_EQ(original.descriptors.type(), CV_8U);
  EXPECT_TRUE(SameFeatures(original, again));
  ASSERT_EQ(original.size(), close.size());
  EXPECT_GT(MeanRowDistance(original.descriptors, close.descriptors), 100.0);
}

TEST(BriefTest, SmallerPatchAndNoSmoothingWork) {
  const cv::Mat image = LoadGray("60.jpg");
  const FeatureOptions options = BriefOptionsWith([](BriefOptions& o) {
    o.patch_size = 16;
    o.smoothing_sigma = 0;
  });
  const FeatureSet features = ExtractOrDie(options, image);
  ASSERT_GT(features.size(), 0u);
  for (const cv::KeyPoint& kp : features.keypoints) {
    EXPECT_GE(kp.pt.x, 8.f);
    EXPECT_GE(kp.pt.y, 8.f);
  }
  EXPECT_EQ(features.descriptors.rows, int(features.size()));
}

// ---------------------------------------------------------------------------------------------
// SIFT

TEST(SiftTest, DescribesFeaturesWith128Floats) {
  FeatureOptions options = OptionsFor(FeatureType::kSift);
  options.sift.max_features = 100;
  const FeatureSet features = ExtractOrDie(options, LoadGray("1.jpg"));
  ASSERT_GT(features.size(), 0u);
  EXPECT_LE(features.size(), 100u);
  EXPECT_EQ(features.descriptors.cols, 128);
  EXPECT_EQ(features.descriptors.type(), CV_32F);
  EXPECT_EQ(features.descriptors.rows, int(features.size()));
  EXPECT_TRUE(SortedByDecreasingResponse(features));
  // SIFT descriptors are non-negative and not all zero.
  double min_value = 0, max_value = 0;
  cv::minMaxLoc(features.descriptors, &min_value, &max_value);
  EXPECT_GE(min_value, 0.0);
  EXPECT_GT(max_value, 0.0);
}

}  // namespace
}  // namespace recog
