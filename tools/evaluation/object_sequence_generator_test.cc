#include "tools/evaluation/object_sequence_generator.h"

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <sstream>

#include <gtest/gtest.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "core/index/memory_index_store.h"
#include "core/object/recognition/object_recognizer.h"
#include "tests/testing/data_paths.h"
#include "tests/testing/recognizers.h"
#include "tests/testing/vocabularies.h"
#include "tools/evaluation/object_evaluation.h"
#include "tools/evaluation/synthetic_images.h"

namespace recog::cli {
namespace {

namespace fs = std::filesystem;

// Corridor frame 1 is the object's photo (frame 41 too for a box's other faces), frames 20 and
// 60 the background.
std::vector<std::string> ObjectPhotos(int count) {
  std::vector<std::string> photos = {testing::ProjectTestData("corridor/1.jpg"),
                                     testing::ProjectTestData("corridor/41.jpg")};
  while (int(photos.size()) < count) photos.push_back(photos[photos.size() % 2]);
  photos.resize(size_t(count));
  return photos;
}

std::vector<std::string> BackgroundPhotos() {
  return {testing::ProjectTestData("corridor/20.jpg"), testing::ProjectTestData("corridor/60.jpg")};
}

ObjectSequenceOptions SmallOptions(ObjectShape shape) {
  ObjectSequenceOptions o;
  o.shape = shape;
  o.frames = 40;
  o.training_views = 2;
  o.image_width = 320;
  o.image_height = 240;
  o.focal = 260;
  o.seed = 5;
  return o;
}

ObjectSequenceGenerator MustCreate(const ObjectSequenceOptions& o) {
  const int photos = o.shape == ObjectShape::kBox ? 4 : 1;
  auto generator = ObjectSequenceGenerator::Create(ObjectPhotos(photos), BackgroundPhotos(), o);
  EXPECT_TRUE(generator.ok()) << generator.status().ToString();
  return std::move(generator).value();
}

bool Identical(const cv::Mat& a, const cv::Mat& b) {
  return a.size() == b.size() && a.type() == b.type() && cv::norm(a, b, cv::NORM_INF) == 0;
}

std::string FileBytes(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

fs::path TempDir(const std::string& name) {
  const fs::path dir =
      fs::temp_directory_path() / ("recog_objseq_" + name + "_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  return dir;
}

TEST(ObjectSequenceGeneratorTest, SameSeedSameBytesOtherSeedOtherFrames) {
  const ObjectSequenceOptions o = SmallOptions(ObjectShape::kBox);
  const ObjectSequenceGenerator a = MustCreate(o), b = MustCreate(o);
  for (int i : {0, 17, 39}) {
    auto fa = a.Frame(i), fb = b.Frame(i);
    ASSERT_TRUE(fa.ok() && fb.ok());
    EXPECT_TRUE(Identical(fa->image, fb->image)) << i;
    EXPECT_TRUE(Identical(fa->depth, fb->depth)) << i;
    EXPECT_TRUE(Identical(fa->mask, fb->mask)) << i;
  }
  // Frame(i) does not depend on call order.
  auto late = a.Frame(17), early = b.Frame(0);
  ASSERT_TRUE(late.ok() && early.ok());
  ObjectSequenceOptions other = o;
  other.seed = 6;
  auto c = MustCreate(other).Frame(17);
  ASSERT_TRUE(c.ok());
  EXPECT_FALSE(Identical(late->image, c->image));

  // Two written folders hold the same bytes, file for file.
  ObjectSequenceOptions tiny = o;
  tiny.frames = 3;
  const fs::path one = TempDir("one"), two = TempDir("two");
  ASSERT_TRUE(WriteObjectSequence(MustCreate(tiny), one.string()).ok());
  ASSERT_TRUE(WriteObjectSequence(MustCreate(tiny), two.string()).ok());
  size_t files = 0;
  for (const auto& entry : fs::recursive_directory_iterator(one)) {
    if (!entry.is_regular_file()) continue;
    ++files;
    const fs::path twin = two / fs::relative(entry.path(), one);
    ASSERT_TRUE(fs::exists(twin)) << twin;
    if (entry.path().filename() == "README.txt") continue;  // names its own folder
    EXPECT_EQ(FileBytes(entry.path()), FileBytes(twin)) << entry.path();
  }
  // 3 frames x 3 images, 2 training views x 3 images, 4 faces, truth, views, README.
  EXPECT_EQ(files, 3u * 3 + 2 * 3 + 4 + 3);
  const std::string readme = FileBytes(one / "README.txt");
  EXPECT_NE(readme.find("recog model build --face front=faces/front.png"), std::string::npos);
  EXPECT_NE(readme.find("--truth truth.txt"), std::string::npos);
  // Writing again into a non-empty folder is refused.
  auto again = WriteObjectSequence(MustCreate(tiny), one.string());
  EXPECT_EQ(again.status().code(), StatusCode::kInvalidArgument);
  fs::remove_all(one);
  fs::remove_all(two);
}

// Convex hull of the object's corners projected with the truth pose.
std::vector<cv::Point2d> ProjectedHull(const ObjectSequenceOptions& o, const CameraIntrinsics& cam,
                                       const RigidTransform& pose) {
  const double d = o.shape == ObjectShape::kBox ? o.depth / 2 : 0;
  std::vector<cv::Point2f> pixels;
  for (double x : {-o.width / 2, o.width / 2}) {
    for (double y : {-o.height / 2, o.height / 2}) {
      for (double z : {-d, d}) {
        cv::Point2d p;
        EXPECT_TRUE(ProjectPoint(cam, pose, {x, y, z}, &p));
        pixels.emplace_back(p);
      }
    }
  }
  std::vector<cv::Point2f> hull;
  cv::convexHull(pixels, hull);
  return {hull.begin(), hull.end()};
}

void ExpectExactTruth(ObjectShape shape) {
  const ObjectSequenceOptions o = SmallOptions(shape);
  const ObjectSequenceGenerator generator = MustCreate(o);
  const CameraIntrinsics& cam = generator.camera();
  EXPECT_DOUBLE_EQ(cam.cx, 159.5);
  EXPECT_DOUBLE_EQ(cam.fx, 260);
  int corners_checked = 0;
  size_t depth_checked = 0;
  for (int i : {0, 10, 25}) {
    auto frame = generator.Frame(i);
    ASSERT_TRUE(frame.ok()) << frame.status().ToString();
    const RigidTransform& pose = frame->truth.camera_from_object;
    // Silhouette corners land on the mask's boundary: 2 px towards the centroid is object, 2 px
    // away from it is not.
    const std::vector<cv::Point2d> hull = ProjectedHull(o, cam, pose);
    cv::Point2d centroid(0, 0);
    for (const cv::Point2d& p : hull) centroid += p / double(hull.size());
    for (const cv::Point2d& p : hull) {
      const cv::Point2d dir = (centroid - p) / cv::norm(centroid - p);
      const cv::Point in = p + 2.5 * dir, out = p - 2.5 * dir;
      const cv::Rect frame_rect(0, 0, o.image_width, o.image_height);
      if (!frame_rect.contains(in) || !frame_rect.contains(out)) continue;
      EXPECT_EQ(frame->mask.at<uint8_t>(in), 255) << "frame " << i << " corner " << p;
      EXPECT_EQ(frame->mask.at<uint8_t>(out), 0) << "frame " << i << " corner " << p;
      ++corners_checked;
    }
    // Every object pixel's depth back-projects onto the object's surface (within 1 mm).
    const RigidTransform object_from_camera = pose.Inverse();
    const cv::Vec3d half(o.width / 2, o.height / 2, shape == ObjectShape::kBox ? o.depth / 2 : 0);
    for (int v = 0; v < o.image_height; ++v) {
      for (int u = 0; u < o.image_width; ++u) {
        const uint16_t mm = frame->depth.at<uint16_t>(v, u);
        if (frame->mask.at<uint8_t>(v, u) == 0 || mm == 0) continue;
        const double z = mm / 1000.0;
        const cv::Point3d q =
            object_from_camera.Apply({(u - cam.cx) / cam.fx * z, (v - cam.cy) / cam.fy * z, z});
        const cv::Vec3d outside(std::abs(q.x) - half[0], std::abs(q.y) - half[1],
                                std::abs(q.z) - half[2]);
        // Inside the box (within 1 mm) and on one of its faces (within 1 mm).
        ASSERT_LE(std::max({outside[0], outside[1], outside[2]}), 0.001) << u << "," << v;
        ASSERT_GE(std::max({outside[0], outside[1], outside[2]}), -0.001) << u << "," << v;
        ++depth_checked;
      }
    }
    // The wall behind: farther than the object.
    EXPECT_GT(frame->depth.at<uint16_t>(0, 0) + frame->depth.at<uint16_t>(0, 1), 0);
  }
  EXPECT_GE(corners_checked, 8);
  EXPECT_GT(depth_checked, 1000u);
}

TEST(ObjectSequenceGeneratorTest, PosterTruthIsExact) { ExpectExactTruth(ObjectShape::kPoster); }
TEST(ObjectSequenceGeneratorTest, BoxTruthIsExact) { ExpectExactTruth(ObjectShape::kBox); }

TEST(ObjectSequenceGeneratorTest, SizeSweepsTheRequestedRangeAndLeavesTheFrame) {
  ObjectSequenceOptions o = SmallOptions(ObjectShape::kPoster);
  o.max_fraction = 0.25;
  o.min_fraction = 0.02;
  const ObjectSequenceGenerator generator = MustCreate(o);
  int partly = 0, whole = 0;
  double first = 0, last = 0;
  for (int i = 0; i < o.frames; ++i) {
    auto frame = generator.Frame(i);
    ASSERT_TRUE(frame.ok());
    const ObjectTruthFrame& t = frame->truth;
    EXPECT_EQ(t.visible, t.in_view >= 0.5);
    EXPECT_NEAR(t.area_fraction,
                cv::countNonZero(frame->mask) / double(o.image_width * o.image_height), 1e-12);
    if (t.in_view < 0.98) {
      ++partly;
      continue;
    }
    ++whole;
    // Wholly in view: the silhouette's target, up to the pixels along its edge.
    EXPECT_GE(t.area_fraction, 0.02 * 0.85) << i;
    EXPECT_LE(t.area_fraction, 0.25 * 1.1) << i;
    if (i == 0) first = t.area_fraction;
    if (i == o.frames - 1) last = t.area_fraction;
  }
  EXPECT_GT(partly, 0);
  EXPECT_GT(whole, o.frames / 2);
  if (first > 0) {
    EXPECT_NEAR(first, 0.25, 0.03);
  }
  if (last > 0) {
    EXPECT_NEAR(last, 0.02, 0.005);
  }
}

TEST(ObjectSequenceGeneratorTest, BadInputIsAClearError) {
  const ObjectSequenceOptions good = SmallOptions(ObjectShape::kPoster);
  const auto code = [](const std::vector<std::string>& objects,
                       const std::vector<std::string>& backgrounds,
                       const ObjectSequenceOptions& o) {
    return ObjectSequenceGenerator::Create(objects, backgrounds, o).status();
  };
  const Status missing = code({"/nonexistent/photo.jpg"}, BackgroundPhotos(), good);
  EXPECT_EQ(missing.code(), StatusCode::kNotFound);
  EXPECT_NE(missing.message().find("/nonexistent/photo.jpg"), std::string::npos);
  EXPECT_EQ(code(ObjectPhotos(1), {}, good).code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(code(ObjectPhotos(1), ObjectPhotos(1), good).code(), StatusCode::kInvalidArgument);
  ObjectSequenceOptions box = SmallOptions(ObjectShape::kBox);
  const Status few = code(ObjectPhotos(2), BackgroundPhotos(), box);
  EXPECT_EQ(few.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(few.message().find("needs 4 object photos"), std::string::npos);

  ObjectSequenceOptions o = good;
  o.width = 0;
  EXPECT_NE(o.Validate().message().find("object width"), std::string::npos);
  o = good;
  o.min_fraction = 0.5;  // above max_fraction
  EXPECT_NE(o.Validate().message().find("smallest size fraction"), std::string::npos);
  o = good;
  o.frames = 1;
  EXPECT_EQ(o.Validate().code(), StatusCode::kInvalidArgument);
  o = good;
  o.name = "bad name";
  EXPECT_EQ(o.Validate().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(ParseObjectShape("sphere").status().code(), StatusCode::kInvalidArgument);
  EXPECT_TRUE(good.Validate().ok());
  auto frame = MustCreate(good).Frame(good.frames);
  EXPECT_EQ(frame.status().code(), StatusCode::kInvalidArgument);

  EXPECT_EQ(ReadObjectSequenceTruth("/nonexistent/truth.txt").status().code(),
            StatusCode::kNotFound);
  const fs::path bad = TempDir("bad_truth");
  fs::create_directories(bad);
  std::ofstream(bad / "truth.txt") << "object poster\ncamera 1 1 0 0\nframe 000001.png 2 0.1 1\n";
  const Status unreadable = ReadObjectSequenceTruth((bad / "truth.txt").string()).status();
  EXPECT_EQ(unreadable.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(unreadable.message().find("truth.txt:3"), std::string::npos);
  fs::remove_all(bad);
}

// A model built from the written face images finds the large poster with the right pose; the
// size recall and its CSV say so.
TEST(ObjectSequenceGeneratorTest, RecallAgainstSizeWithAModelOfTheFaces) {
  ObjectSequenceOptions o;
  o.frames = 8;
  o.training_views = 1;
  o.max_fraction = 0.3;
  o.min_fraction = 0.05;
  o.seed = 3;
  const ObjectSequenceGenerator generator = MustCreate(o);
  const fs::path dir = TempDir("recall");
  auto written = WriteObjectSequence(generator, dir.string());
  ASSERT_TRUE(written.ok()) << written.status().ToString();
  auto truth = ReadObjectSequenceTruth(written->truth_path);
  ASSERT_TRUE(truth.ok()) << truth.status().ToString();
  EXPECT_EQ(truth->object, "synthetic-poster");
  EXPECT_EQ(truth->camera, generator.camera());
  ASSERT_EQ(truth->frames.size(), 8u);

  const auto vocabulary = testing::BundledObjectVocabulary();
  ModelBuilder builder(vocabulary);
  auto face = ReadPhoto((dir / "faces/front.png").string());
  ASSERT_TRUE(face.ok());
  auto model = builder.FromFaceImages("poster", {{BoxSide::kFront, *face}}, o.width, o.height);
  ASSERT_TRUE(model.ok()) << model.status().ToString();
  MemoryIndexStore store;
  auto database = ObjectDatabase::Open(&store, vocabulary);
  ASSERT_TRUE(database.ok());
  ASSERT_TRUE((*database)->Put(*model).ok());
  ObjectRecognizer recognizer =
      testing::MakeRecognizer(std::shared_ptr<const ObjectDatabase>(std::move(*database)));
  SizeRecallOptions options;
  options.bin_edges = {0.1};
  std::vector<TruthFrameScore> scores;
  for (int i = 0; i < o.frames; ++i) {
    auto frame = generator.Frame(i);
    ASSERT_TRUE(frame.ok());
    auto found = FindTruthFrame(*truth, (dir / "images" / frame->truth.image).string());
    ASSERT_TRUE(found.ok());
    cv::Mat grey;
    cv::cvtColor(frame->image, grey, cv::COLOR_BGR2GRAY);
    std::vector<Detection> detections;
    ASSERT_TRUE(recognizer.Recognize(grey, generator.camera(), &detections).ok());
    scores.push_back(ScoreTruthFrame(*found, "poster", detections, options));
  }
  EXPECT_EQ(FindTruthFrame(*truth, "999999.png").status().code(), StatusCode::kNotFound);
  const SizeRecall recall = SummariseSizeRecall(scores, options);
  ASSERT_EQ(recall.bins.size(), 2u);
  const SizeBin& large = recall.bins[1];
  EXPECT_GT(large.frames, 0u);
  EXPECT_GT(large.recall, 0.0);
  EXPECT_LE(large.median_rotation_error_deg, options.max_rotation_error_deg);
  EXPECT_EQ(recall.bins[0].frames + large.frames, recall.visible_frames);

  const std::string csv = (dir / "recall.csv").string(), png = (dir / "recall.png").string();
  ASSERT_TRUE(WriteSizeRecallCsv(recall, csv).ok());
  ASSERT_TRUE(WriteSizeRecallPlot(recall, "test", png).ok());
  std::istringstream lines(FileBytes(csv));
  std::string header, row;
  std::getline(lines, header);
  EXPECT_EQ(header,
            "area_lo,area_hi,median_area,frames,found,correct,recall,found_rate,"
            "median_rotation_deg,median_translation_m");
  int rows = 0;
  while (std::getline(lines, row)) ++rows;
  EXPECT_EQ(rows, 2);
  EXPECT_GT(fs::file_size(png), 1000u);
  EXPECT_EQ(WriteSizeRecallCsv(recall, "/nonexistent/dir/x.csv").code(), StatusCode::kInternal);
  fs::remove_all(dir);
}

// A detection of the wrong object or with the wrong pose does not count.
TEST(ObjectSequenceGeneratorTest, ScoringNeedsTheRightObjectAndPose) {
  ObjectTruthFrame truth;
  truth.visible = true;
  truth.area_fraction = 0.05;
  truth.camera_from_object.t = {0, 0, 1};
  Detection right, wrong_pose, other;
  right.name = wrong_pose.name = "poster";
  right.camera_from_object = truth.camera_from_object;
  right.camera_from_object.t[0] = 0.05;  // 5 cm of 1 m: within 10 %
  wrong_pose.camera_from_object = truth.camera_from_object;
  cv::Rodrigues(cv::Vec3d(0, 0.5, 0), wrong_pose.camera_from_object.R);  // 28.6 degrees
  other.name = "other";
  const SizeRecallOptions options;
  const TruthFrameScore ok = ScoreTruthFrame(truth, "poster", {other, right}, options);
  EXPECT_TRUE(ok.found && ok.correct_pose);
  EXPECT_EQ(ok.other_objects, 1u);
  EXPECT_NEAR(ok.translation_error_m, 0.05, 1e-12);
  const TruthFrameScore bad = ScoreTruthFrame(truth, "poster", {wrong_pose}, options);
  EXPECT_TRUE(bad.found);
  EXPECT_FALSE(bad.correct_pose);
  EXPECT_NEAR(bad.rotation_error_deg, 0.5 * 180 / CV_PI, 1e-9);
  const TruthFrameScore none = ScoreTruthFrame(truth, "poster", {other}, options);
  EXPECT_FALSE(none.found);
  const SizeRecall r = SummariseSizeRecall({ok, bad, none}, options);
  EXPECT_EQ(r.visible_frames, 3u);
  EXPECT_EQ(r.correct, 1u);
  EXPECT_NEAR(r.recall, 1.0 / 3, 1e-12);
  EXPECT_EQ(r.bins[4].frames, 3u);  // [0.04, 0.08)
}

}  // namespace
}  // namespace recog::cli
