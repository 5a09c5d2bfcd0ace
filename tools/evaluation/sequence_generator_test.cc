#include "tools/evaluation/sequence_generator.h"

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <set>
#include <thread>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "tests/testing/data_paths.h"

namespace recog::cli {
namespace {

namespace fs = std::filesystem;

std::vector<std::string> CorridorPhotos() {
  std::vector<std::string> photos;
  for (const char* name :
       {"corridor/1.jpg", "corridor/20.jpg", "corridor/41.jpg", "corridor/60.jpg"})
    photos.push_back(testing::ProjectTestData(name));
  return photos;
}

// Small frames keep the tests fast. The corridor frames show one corridor (distinct places would
// keep only two of them), so these tests use them as they are, cycled when there are more places.
SequenceOptions SmallOptions() {
  SequenceOptions o;
  o.distinct_places = false;
  o.places = 4;
  o.frames_per_place = 3;
  o.revisit_fraction = 0.5;
  o.width = 160;
  o.height = 120;
  o.max_shift_px = 4;
  o.seed = 11;
  return o;
}

SequenceGenerator MustCreate(const SequenceOptions& options) {
  auto generator = SequenceGenerator::Create(CorridorPhotos(), options);
  EXPECT_TRUE(generator.ok()) << generator.status().ToString();
  return std::move(generator).value();
}

cv::Mat MustFrame(const SequenceGenerator& generator, int i) {
  auto frame = generator.Frame(i);
  EXPECT_TRUE(frame.ok()) << frame.status().ToString();
  return frame.ok() ? frame->image : cv::Mat();
}

bool Identical(const cv::Mat& a, const cv::Mat& b) {
  return a.size() == b.size() && a.type() == b.type() && cv::norm(a, b, cv::NORM_INF) == 0;
}

double MeanAbsDifference(const cv::Mat& a, const cv::Mat& b) {
  cv::Mat diff;
  cv::absdiff(a, b, diff);
  const cv::Scalar mean = cv::mean(diff);
  double sum = 0;
  for (int c = 0; c < a.channels(); ++c) sum += mean[c];
  return sum / a.channels();
}

// A fresh folder under the temp directory, removed at the end of the test.
class TempDir {
 public:
  explicit TempDir(const std::string& name)
      : path_(fs::temp_directory_path() /
              ("recog_seqgen_" + name + "_" + std::to_string(::getpid()))) {
    fs::remove_all(path_);
  }
  ~TempDir() { fs::remove_all(path_); }
  std::string path() const { return path_.string(); }
  std::string operator/(const std::string& child) const { return (path_ / child).string(); }

 private:
  fs::path path_;
};

TEST(SequenceOptionsTest, DefaultsAreValid) {
  EXPECT_TRUE(SequenceOptions().Validate().ok());
  EXPECT_TRUE(SequenceOptions().distinct_places);
}

TEST(SequenceOptionsTest, OutOfRangeValuesAreInvalidArguments) {
  const auto invalid = [](auto change) {
    SequenceOptions o;
    change(o);
    return o.Validate().code() == StatusCode::kInvalidArgument;
  };
  EXPECT_TRUE(invalid([](SequenceOptions& o) { o.places = 0; }));
  EXPECT_TRUE(invalid([](SequenceOptions& o) { o.frames_per_place = 0; }));
  EXPECT_TRUE(invalid([](SequenceOptions& o) { o.revisit_fraction = 1.5; }));
  EXPECT_TRUE(invalid([](SequenceOptions& o) { o.revisit_fraction = -0.1; }));
  EXPECT_TRUE(invalid(
      [](SequenceOptions& o) { o.revisit_fraction = std::numeric_limits<double>::quiet_NaN(); }));
  EXPECT_TRUE(invalid([](SequenceOptions& o) { o.width = 0; }));
  EXPECT_TRUE(invalid([](SequenceOptions& o) { o.height = 100000; }));
  EXPECT_TRUE(invalid([](SequenceOptions& o) { o.max_shift_px = -1; }));
  EXPECT_TRUE(invalid([](SequenceOptions& o) { o.max_rotation_deg = 90; }));
  EXPECT_TRUE(invalid([](SequenceOptions& o) { o.max_scale = 0.5; }));
  EXPECT_TRUE(invalid([](SequenceOptions& o) { o.noise_sigma = -3; }));
  EXPECT_TRUE(invalid([](SequenceOptions& o) { o.illumination_max = 2; }));
  EXPECT_TRUE(invalid([](SequenceOptions& o) {
    o.places = 40'000'000;
    o.frames_per_place = 2;
  }));
}

TEST(SequenceGeneratorTest, CreateRejectsNoPhotosBadOptionsAndMissingPhotos) {
  EXPECT_EQ(SequenceGenerator::Create({}, SmallOptions()).status().code(),
            StatusCode::kInvalidArgument);
  SequenceOptions bad = SmallOptions();
  bad.frames_per_place = -2;
  EXPECT_EQ(SequenceGenerator::Create(CorridorPhotos(), bad).status().code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(SequenceGenerator::Create({"/nonexistent/photo.jpg"}, SmallOptions()).status().code(),
            StatusCode::kNotFound);
  SequenceOptions distinct = SmallOptions();
  distinct.distinct_places = true;
  distinct.places = 1;
  EXPECT_EQ(SequenceGenerator::Create({"/nonexistent/photo.jpg"}, distinct).status().code(),
            StatusCode::kNotFound);
}

TEST(SequenceGeneratorTest, UndecodablePhotoFailsWhenItsFrameIsGenerated) {
  TempDir dir("undecodable");
  fs::create_directories(dir.path());
  std::ofstream(dir / "bad.jpg") << "not an image";
  std::vector<std::string> photos = CorridorPhotos();
  photos[1] = dir / "bad.jpg";
  auto generator = SequenceGenerator::Create(photos, SmallOptions());
  ASSERT_TRUE(generator.ok()) << generator.status().ToString();
  EXPECT_TRUE(generator->Frame(0).ok());
  const int frame_of_place_1 = SmallOptions().frames_per_place;
  EXPECT_EQ(generator->Frame(frame_of_place_1).status().code(), StatusCode::kInvalidArgument);
  // Distinct places decode the photos in Create().
  SequenceOptions distinct = SmallOptions();
  distinct.distinct_places = true;
  distinct.places = 2;
  const Status status = SequenceGenerator::Create(photos, distinct).status();
  EXPECT_EQ(status.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(status.message().find("bad.jpg"), std::string::npos) << status.ToString();
}

TEST(SequenceGeneratorTest, FramesOutsideTheSequenceAreInvalidArguments) {
  const SequenceGenerator generator = MustCreate(SmallOptions());
  EXPECT_EQ(generator.Frame(-1).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(generator.Frame(generator.num_frames()).status().code(), StatusCode::kInvalidArgument);
  EXPECT_FALSE(generator.SamePlace(generator.num_frames(), 0));
  EXPECT_TRUE(generator.Matches(-1).empty());
}

TEST(SequenceGeneratorTest, FrameCountIsFirstVisitsPlusRevisitsTimesFramesPerPlace) {
  SequenceOptions o = SmallOptions();
  o.places = 10;
  o.frames_per_place = 3;
  o.revisit_fraction = 0.5;
  const SequenceGenerator generator = MustCreate(o);
  EXPECT_EQ(generator.num_revisits(), 5);
  EXPECT_EQ(generator.num_frames(), 10 * 3 + 5 * 3);
  o.revisit_fraction = 1;
  EXPECT_EQ(MustCreate(o).num_frames(), 10 * 3 * 2);
  o.revisit_fraction = 0;
  EXPECT_EQ(MustCreate(o).num_frames(), 10 * 3);
}

TEST(SequenceGeneratorTest, TourVisitsEveryPlaceInOrderThenDistinctRevisits) {
  SequenceOptions o = SmallOptions();
  o.places = 20;
  o.revisit_fraction = 0.4;
  const SequenceGenerator generator = MustCreate(o);
  ASSERT_EQ(generator.num_visits(), 28);
  for (int v = 0; v < 20; ++v) EXPECT_EQ(generator.VisitPlace(v), v);
  std::set<int> revisited;
  for (int v = 20; v < 28; ++v) revisited.insert(generator.VisitPlace(v));
  EXPECT_EQ(revisited.size(), 8u);
  EXPECT_GE(*revisited.begin(), 0);
  EXPECT_LT(*revisited.rbegin(), 20);
  EXPECT_EQ(generator.VisitPlace(28), -1);
}

TEST(SequenceGeneratorTest, TheTourDependsOnTheSeedOnly) {
  SequenceOptions o = SmallOptions();
  o.places = 30;
  o.revisit_fraction = 0.5;
  const auto tour = [](const SequenceGenerator& g) {
    std::vector<int> places;
    for (int v = 0; v < g.num_visits(); ++v) places.push_back(g.VisitPlace(v));
    return places;
  };
  const std::vector<int> first = tour(MustCreate(o));
  EXPECT_EQ(tour(MustCreate(o)), first);
  o.seed += 1;
  EXPECT_NE(tour(MustCreate(o)), first);
}

TEST(SequenceGeneratorTest, NoRevisitsMeansNoMatchesAtAll) {
  SequenceOptions o = SmallOptions();
  o.places = 12;
  o.revisit_fraction = 0;
  const SequenceGenerator generator = MustCreate(o);
  for (int a = 0; a < generator.num_frames(); ++a) {
    EXPECT_TRUE(generator.Matches(a).empty()) << a;
    for (int b = 0; b < generator.num_frames(); ++b) EXPECT_FALSE(generator.SamePlace(a, b));
  }
  EXPECT_EQ(generator.BuildGroundTruth().QueriesWithMatches(), 0);
}

TEST(SequenceGeneratorTest, EveryMatchIsTheSamePlaceEarlierAndOnAnotherVisit) {
  SequenceOptions o = SmallOptions();
  o.places = 9;
  o.frames_per_place = 4;
  o.revisit_fraction = 0.67;  // round(6.03) = 6 revisits
  const SequenceGenerator generator = MustCreate(o);
  const int f = o.frames_per_place;
  int queries = 0;
  for (int a = 0; a < generator.num_frames(); ++a) {
    const std::vector<int> matches = generator.Matches(a);
    EXPECT_TRUE(std::is_sorted(matches.begin(), matches.end()));
    if (!matches.empty()) ++queries;
    for (int b : matches) {
      EXPECT_LT(b, a);
      EXPECT_EQ(generator.FramePlace(b), generator.FramePlace(a));
      EXPECT_NE(b / f, a / f) << "frames of one visit are not loops";
    }
    for (int b = 0; b < generator.num_frames(); ++b) {
      const bool listed = std::binary_search(matches.begin(), matches.end(), b);
      EXPECT_EQ(generator.SamePlace(a, b), listed) << a << " " << b;
    }
    // A revisit frame matches exactly the frames of the place's first visit.
    if (a >= o.places * f) {
      EXPECT_EQ(matches.size(), size_t(f));
      EXPECT_EQ(matches.front(), generator.FramePlace(a) * f);
    }
  }
  EXPECT_EQ(queries, 6 * f);
  const GroundTruth truth = generator.BuildGroundTruth();
  EXPECT_TRUE(truth.Validate().ok());
  EXPECT_EQ(truth.frames, generator.num_frames());
  EXPECT_EQ(truth.QueriesWithMatches(), queries);
}

TEST(SequenceGeneratorTest, FramesHaveTheRequestedSizeTypeAndMetadata) {
  SequenceOptions o = SmallOptions();
  o.width = 200;
  o.height = 90;
  const SequenceGenerator generator = MustCreate(o);
  const cv::Mat photo = cv::imread(CorridorPhotos()[0], cv::IMREAD_ANYCOLOR);
  for (int i : {0, 5, generator.num_frames() - 1}) {
    auto frame = generator.Frame(i);
    ASSERT_TRUE(frame.ok()) << frame.status().ToString();
    EXPECT_EQ(frame->index, i);
    EXPECT_EQ(frame->image.cols, 200);
    EXPECT_EQ(frame->image.rows, 90);
    EXPECT_EQ(frame->image.type(), photo.type());
    EXPECT_EQ(frame->place, generator.FramePlace(i));
    EXPECT_EQ(frame->frame_in_visit, i % o.frames_per_place);
    EXPECT_EQ(frame->visit, i >= o.places * o.frames_per_place ? 1 : 0);
  }
}

TEST(SequenceGeneratorTest, TheSameSeedGivesBitIdenticalFrames) {
  const SequenceGenerator a = MustCreate(SmallOptions());
  const SequenceGenerator b = MustCreate(SmallOptions());
  for (int i = 0; i < a.num_frames(); ++i) {
    EXPECT_TRUE(Identical(MustFrame(a, i), MustFrame(b, i))) << "frame " << i;
  }
}

TEST(SequenceGeneratorTest, AFrameDoesNotDependOnCallOrder) {
  const SequenceGenerator forward = MustCreate(SmallOptions());
  const SequenceGenerator backward = MustCreate(SmallOptions());
  const int n = forward.num_frames();
  std::vector<cv::Mat> in_order, reversed(static_cast<size_t>(n));
  for (int i = 0; i < n; ++i) in_order.push_back(MustFrame(forward, i));
  for (int i = n - 1; i >= 0; --i) reversed[size_t(i)] = MustFrame(backward, i);
  for (int i = 0; i < n; ++i) EXPECT_TRUE(Identical(in_order[size_t(i)], reversed[size_t(i)])) << i;
  // Asking again, after other frames, gives the same picture.
  EXPECT_TRUE(Identical(MustFrame(forward, 2), in_order[2]));
}

TEST(SequenceGeneratorTest, ADifferentSeedGivesDifferentFrames) {
  SequenceOptions o = SmallOptions();
  const SequenceGenerator a = MustCreate(o);
  o.seed += 1;
  const SequenceGenerator b = MustCreate(o);
  for (int i : {0, 4, 7}) EXPECT_FALSE(Identical(MustFrame(a, i), MustFrame(b, i))) << i;
}

TEST(SequenceGeneratorTest, ConsecutiveFramesOfAVisitLookAlikeButDiffer) {
  SequenceOptions o = SmallOptions();
  o.width = 320;
  o.height = 240;
  o.frames_per_place = 4;
  const SequenceGenerator generator = MustCreate(o);
  const int f = o.frames_per_place;
  double largest_within = 0, smallest_across = 1e9;
  for (int place = 0; place < o.places; ++place) {
    for (int k = 0; k + 1 < f; ++k) {
      const double d = MeanAbsDifference(MustFrame(generator, place * f + k),
                                         MustFrame(generator, place * f + k + 1));
      EXPECT_GT(d, 0.5) << "place " << place << " frames " << k << ", " << k + 1;
      largest_within = std::max(largest_within, d);
    }
    for (int other = place + 1; other < o.places; ++other) {
      smallest_across = std::min(
          smallest_across,
          MeanAbsDifference(MustFrame(generator, place * f), MustFrame(generator, other * f)));
    }
  }
  EXPECT_LT(largest_within, smallest_across);
}

TEST(SequenceGeneratorTest, WithoutMotionOrAppearanceChangeAFirstVisitIsOneStillPicture) {
  SequenceOptions o = SmallOptions();
  o.max_shift_px = o.max_rotation_deg = o.max_scale = 0;
  o.blur_sigma_max = o.noise_sigma = o.illumination_max = 0;
  const SequenceGenerator generator = MustCreate(o);
  const cv::Mat first = MustFrame(generator, 0);
  for (int k = 1; k < o.frames_per_place; ++k)
    EXPECT_TRUE(Identical(MustFrame(generator, k), first));
  // The default knobs do change consecutive frames.
  const SequenceGenerator moving = MustCreate(SmallOptions());
  EXPECT_FALSE(Identical(MustFrame(moving, 0), MustFrame(moving, 1)));
}

TEST(SequenceGeneratorTest, PhotosAreCycledAndMirroredWhenThereAreFewerThanPlaces) {
  SequenceOptions o = SmallOptions();
  o.places = 6;
  o.max_shift_px = o.max_rotation_deg = o.max_scale = 0;
  o.blur_sigma_max = o.noise_sigma = o.illumination_max = 0;
  const SequenceGenerator generator = MustCreate(o);
  EXPECT_EQ(generator.PlacePhoto(4), CorridorPhotos()[0]);
  EXPECT_EQ(generator.PlacePhoto(5), CorridorPhotos()[1]);
  EXPECT_FALSE(generator.PlaceMirrored(1));
  EXPECT_TRUE(generator.PlaceMirrored(4));
  const int f = o.frames_per_place;
  cv::Mat mirrored;
  cv::flip(MustFrame(generator, 0), mirrored, 1);
  // Place 4 is photo 0 flipped; the crop is centred, so up to a pixel of interpolation.
  EXPECT_LT(MeanAbsDifference(MustFrame(generator, 4 * f), mirrored), 3.0);
  EXPECT_GT(MeanAbsDifference(MustFrame(generator, 4 * f), MustFrame(generator, 0)), 5.0);
}

// A picture of random grey triangles: a scene unlike any other (seeded).
cv::Mat RandomScene(uint64_t seed) {
  cv::Mat scene(360, 480, CV_8UC1, cv::Scalar(128));
  cv::RNG rng(seed);
  for (int k = 0; k < 120; ++k) {
    std::vector<cv::Point> triangle;
    for (int v = 0; v < 3; ++v) triangle.emplace_back(rng.uniform(0, 480), rng.uniform(0, 360));
    cv::fillConvexPoly(scene, triangle, cv::Scalar(rng.uniform(0, 256)), cv::LINE_AA);
  }
  return scene;
}

// 1.png corridor frame 20, 2.png random triangles, 3.png the middle 80 % of frame 20 rotated by
// 10 degrees, shrunk to 70 % and blurred, 4.png corridor frame 1.
class DistinctPlacesTest : public ::testing::Test {
 protected:
  void SetUp() override {
    fs::create_directories(dir_.path());
    const cv::Mat photo = cv::imread(testing::ProjectTestData("corridor/20.jpg"));
    ASSERT_FALSE(photo.empty());
    const cv::Rect middle(photo.cols / 10, photo.rows / 10, photo.cols * 8 / 10,
                          photo.rows * 8 / 10);
    const cv::Mat crop = photo(middle).clone();
    const cv::Size size(crop.cols * 7 / 10, crop.rows * 7 / 10);
    cv::Mat rotation =
        cv::getRotationMatrix2D(cv::Point2f(crop.cols / 2.0f, crop.rows / 2.0f), 10, 0.7);
    rotation.at<double>(0, 2) += (size.width - crop.cols) / 2.0;  // centre to centre
    rotation.at<double>(1, 2) += (size.height - crop.rows) / 2.0;
    cv::Mat copy;
    cv::warpAffine(crop, copy, rotation, size, cv::INTER_AREA, cv::BORDER_REFLECT);
    cv::GaussianBlur(copy, copy, cv::Size(), 1.0);
    ASSERT_TRUE(cv::imwrite(dir_ / "1.png", photo));
    ASSERT_TRUE(cv::imwrite(dir_ / "2.png", RandomScene(5)));
    ASSERT_TRUE(cv::imwrite(dir_ / "3.png", copy));
    ASSERT_TRUE(
        cv::imwrite(dir_ / "4.png", cv::imread(testing::ProjectTestData("corridor/1.jpg"))));
    for (const char* name : {"1.png", "2.png", "3.png", "4.png"}) photos_.push_back(dir_ / name);
  }

  static SequenceOptions Options(int places) {
    SequenceOptions o = SmallOptions();
    o.places = places;
    o.distinct_places = true;
    return o;
  }

  TempDir dir_{"distinct"};
  std::vector<std::string> photos_;
};

TEST_F(DistinctPlacesTest, ACroppedRotatedRescaledCopyIsSkippedUnrelatedPhotosAreNot) {
  auto generator = SequenceGenerator::Create(photos_, Options(3));
  ASSERT_TRUE(generator.ok()) << generator.status().ToString();
  EXPECT_EQ(generator->photos(), (std::vector<std::string>{photos_[0], photos_[1], photos_[3]}));
  EXPECT_EQ(generator->PlacePhoto(2), photos_[3]);
  ASSERT_EQ(generator->skipped_duplicates(), 1);
  EXPECT_EQ(generator->skipped()[0].photo, photos_[2]);
  EXPECT_EQ(generator->skipped()[0].same_as_place, 0);
  EXPECT_GE(generator->skipped()[0].inliers, 20);
  for (int p = 0; p < 3; ++p) EXPECT_FALSE(generator->PlaceMirrored(p));
}

// Among more places than either candidate search returns, unrelated scenes are all kept and a copy
// of the first one, rotated by 30 degrees and darkened, is found and dropped.
TEST(DistinctPlacesManyTest, ARotatedDarkenedCopyAmongManyScenesIsSkipped) {
  TempDir dir("many");
  fs::create_directories(dir.path());
  constexpr int kScenes = 40;
  std::vector<std::string> photos;
  cv::Mat first;
  for (int k = 0; k < kScenes; ++k) {
    cv::Mat scene;
    cv::resize(RandomScene(100 + uint64_t(k)), scene, cv::Size(240, 180), 0, 0, cv::INTER_AREA);
    if (k == 0) first = scene;
    photos.push_back(dir / (std::to_string(k) + ".png"));
    ASSERT_TRUE(cv::imwrite(photos.back(), scene));
  }
  const cv::Mat rotation = cv::getRotationMatrix2D(cv::Point2f(120, 90), 30, 0.9);
  cv::Mat copy;
  cv::warpAffine(first, copy, rotation, first.size());
  copy.convertTo(copy, -1, 0.7, 10);
  photos.push_back(dir / "copy.png");
  ASSERT_TRUE(cv::imwrite(photos.back(), copy));
  cv::Mat last;
  cv::resize(RandomScene(999), last, cv::Size(240, 180), 0, 0, cv::INTER_AREA);
  photos.push_back(dir / "last.png");
  ASSERT_TRUE(cv::imwrite(photos.back(), last));

  SequenceOptions o = SmallOptions();
  o.distinct_places = true;
  o.places = kScenes + 1;
  auto generator = SequenceGenerator::Create(photos, o);
  ASSERT_TRUE(generator.ok()) << generator.status().ToString();
  ASSERT_EQ(generator->skipped_duplicates(), 1);
  EXPECT_EQ(generator->skipped()[0].photo, dir / "copy.png");
  EXPECT_EQ(generator->skipped()[0].same_as_place, 0);
  EXPECT_EQ(generator->PlacePhoto(kScenes), dir / "last.png");
}

TEST_F(DistinctPlacesTest, WithoutDistinctPlacesTheCopyIsKept) {
  SequenceOptions o = Options(3);
  o.distinct_places = false;
  auto generator = SequenceGenerator::Create(photos_, o);
  ASSERT_TRUE(generator.ok()) << generator.status().ToString();
  EXPECT_EQ(generator->PlacePhoto(2), photos_[2]);
  EXPECT_EQ(generator->skipped_duplicates(), 0);
}

TEST_F(DistinctPlacesTest, TheChosenPhotosAreFixedAndGiveTheSameFramesAsTheirList) {
  auto chosen = SequenceGenerator::Create(photos_, Options(3));
  ASSERT_TRUE(chosen.ok()) << chosen.status().ToString();
  auto again = SequenceGenerator::Create(photos_, Options(3));
  ASSERT_TRUE(again.ok()) << again.status().ToString();
  EXPECT_EQ(again->photos(), chosen->photos());
  SequenceOptions o = Options(3);
  o.distinct_places = false;
  auto listed = SequenceGenerator::Create(chosen->photos(), o);
  ASSERT_TRUE(listed.ok()) << listed.status().ToString();
  ASSERT_EQ(listed->num_frames(), chosen->num_frames());
  for (int i = chosen->num_frames() - 1; i >= 0; --i) {
    EXPECT_TRUE(Identical(MustFrame(*chosen, i), MustFrame(*listed, i))) << i;
  }
}

TEST_F(DistinctPlacesTest, RunningOutOfDistinctPhotosIsAnInvalidArgument) {
  // Four photos, three scenes.
  auto four = SequenceGenerator::Create(photos_, Options(4));
  EXPECT_EQ(four.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(four.status().message().find("distinct"), std::string::npos)
      << four.status().ToString();
  // Fewer photos than places: no cycling with distinct places ...
  auto five = SequenceGenerator::Create(photos_, Options(5));
  EXPECT_EQ(five.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(five.status().message().find("distinct"), std::string::npos)
      << five.status().ToString();
  // ... but without them.
  SequenceOptions o = Options(5);
  o.distinct_places = false;
  EXPECT_TRUE(SequenceGenerator::Create(photos_, o).ok());
}

TEST(SequenceGeneratorTest, FramesCanBeGeneratedFromSeveralThreads) {
  const SequenceGenerator generator = MustCreate(SmallOptions());
  const int n = generator.num_frames();
  std::vector<cv::Mat> serial;
  for (int i = 0; i < n; ++i) serial.push_back(MustFrame(generator, i));
  const SequenceGenerator fresh = MustCreate(SmallOptions());
  std::vector<cv::Mat> parallel(static_cast<size_t>(n));
  std::vector<std::thread> threads;
  for (int t = 0; t < 2; ++t) {
    threads.emplace_back([&, t] {
      for (int i = t; i < n; i += 2) parallel[size_t(i)] = fresh.Frame(i)->image;
    });
  }
  for (std::thread& t : threads) t.join();
  for (int i = 0; i < n; ++i) EXPECT_TRUE(Identical(serial[size_t(i)], parallel[size_t(i)])) << i;
}

TEST(WriteSequenceTest, WritesNumberedPngsAndADenseGroundTruth) {
  TempDir dir("dense");
  const SequenceGenerator generator = MustCreate(SmallOptions());
  std::vector<uint64_t> reported;
  auto result = WriteSequence(generator, dir.path(), /*sparse_truth=*/false,
                              SequenceImageFormat::kPng, [&](uint64_t done, uint64_t total) {
                                EXPECT_EQ(total, uint64_t(generator.num_frames()));
                                reported.push_back(done);
                              });
  ASSERT_TRUE(result.ok()) << result.status().ToString();
  EXPECT_EQ(reported.size(), size_t(generator.num_frames()));
  EXPECT_FALSE(result->sparse_truth);
  EXPECT_EQ(result->ground_truth_path, dir / "ground_truth.txt");
  EXPECT_EQ(result->frames, generator.num_frames());
  EXPECT_EQ(result->queries_with_matches, 2 * 3);
  int files = 0;
  for (const auto& entry : fs::directory_iterator(result->images_dir)) {
    (void)entry;
    ++files;
  }
  EXPECT_EQ(files, generator.num_frames());
  // PNG is lossless: the file holds exactly the generated frame.
  const cv::Mat first = cv::imread(dir / "images/000001.png", cv::IMREAD_UNCHANGED);
  EXPECT_TRUE(Identical(first, MustFrame(generator, 0)));
  char last[32];
  std::snprintf(last, sizeof(last), "images/%06d.png", generator.num_frames());
  EXPECT_TRUE(fs::exists(dir / last));

  auto truth = ReadGroundTruth(result->ground_truth_path);
  ASSERT_TRUE(truth.ok()) << truth.status().ToString();
  EXPECT_EQ(truth->frames, generator.num_frames());
  EXPECT_EQ(truth->matches, generator.BuildGroundTruth().matches);
}

TEST(WriteSequenceTest, WritesJpegsAndASparseGroundTruthOnRequest) {
  TempDir dir("sparse");
  const SequenceGenerator generator = MustCreate(SmallOptions());
  auto result =
      WriteSequence(generator, dir.path(), /*sparse_truth=*/true, SequenceImageFormat::kJpeg);
  ASSERT_TRUE(result.ok()) << result.status().ToString();
  EXPECT_TRUE(result->sparse_truth);
  EXPECT_EQ(result->ground_truth_path, dir / "ground_truth.sparse.txt");
  EXPECT_FALSE(fs::exists(dir / "ground_truth.txt"));
  const cv::Mat first = cv::imread(dir / "images/000001.jpg", cv::IMREAD_UNCHANGED);
  ASSERT_FALSE(first.empty());
  EXPECT_LT(MeanAbsDifference(first, MustFrame(generator, 0)), 3.0);  // quality 95
  auto truth = ReadGroundTruth(result->ground_truth_path);
  ASSERT_TRUE(truth.ok()) << truth.status().ToString();
  EXPECT_EQ(truth->matches, generator.BuildGroundTruth().matches);
}

TEST(WriteSequenceTest, ManyFramesForceTheSparseGroundTruth) {
  TempDir dir("forced");
  SequenceOptions o = SmallOptions();
  o.places = 2600;  // 2600 + 1300 revisits = 3900 visits of 2 frames: 7800 frames
  o.frames_per_place = 2;
  o.width = o.height = 16;
  o.noise_sigma = 0;
  // One tiny photo, so that decoding it again for every place costs nothing.
  fs::create_directories(dir.path());
  cv::Mat tiny(24, 32, CV_8UC1);
  cv::randu(tiny, 0, 255);
  const std::string photo = dir / "tiny.png";
  ASSERT_TRUE(cv::imwrite(photo, tiny));
  auto created = SequenceGenerator::Create({photo}, o);
  ASSERT_TRUE(created.ok()) << created.status().ToString();
  const SequenceGenerator& generator = *created;
  ASSERT_GT(generator.num_frames(), kMaxDenseGroundTruthFrames);
  auto result = WriteSequence(generator, dir / "out", /*sparse_truth=*/false);
  ASSERT_TRUE(result.ok()) << result.status().ToString();
  EXPECT_TRUE(result->sparse_truth);
  EXPECT_EQ(result->ground_truth_path, dir / "out/ground_truth.sparse.txt");
  auto truth = ReadGroundTruth(result->ground_truth_path);
  ASSERT_TRUE(truth.ok()) << truth.status().ToString();
  EXPECT_EQ(truth->frames, 7800);
  EXPECT_EQ(truth->QueriesWithMatches(), 1300 * 2);
}

TEST(WriteSequenceTest, RefusesANonEmptyOutputFolderOrAFile) {
  TempDir dir("refuse");
  fs::create_directories(dir.path());
  std::ofstream(dir / "keep.txt") << "precious";
  const SequenceGenerator generator = MustCreate(SmallOptions());
  EXPECT_EQ(WriteSequence(generator, dir.path(), false).status().code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(WriteSequence(generator, dir / "keep.txt", false).status().code(),
            StatusCode::kInvalidArgument);
  EXPECT_FALSE(fs::exists(dir / "images"));
  // An existing empty folder is fine.
  fs::create_directories(dir / "empty");
  EXPECT_TRUE(WriteSequence(generator, dir / "empty", false).ok());
}

TEST(WriteSequenceTest, ImageFormatNamesParse) {
  EXPECT_EQ(*ParseSequenceImageFormat("png"), SequenceImageFormat::kPng);
  EXPECT_EQ(*ParseSequenceImageFormat("jpg"), SequenceImageFormat::kJpeg);
  EXPECT_EQ(*ParseSequenceImageFormat("jpeg"), SequenceImageFormat::kJpeg);
  EXPECT_EQ(ParseSequenceImageFormat("gif").status().code(), StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace recog::cli
