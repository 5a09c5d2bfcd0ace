#include "core/geometry/correspondences.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <string>

#include <gtest/gtest.h>

#include "tests/testing/synthetic.h"

namespace recog {
namespace {

FeatureVector AllUnderOneNode(uint32_t n) {
  std::vector<uint32_t> all(n);
  for (uint32_t i = 0; i < n; ++i) all[i] = i;
  FeatureVector fv;
  fv.AppendNode(7, all);
  return fv;
}

TEST(CorrespondencesTest, EveryFeatureMatchesItsOwnCopy) {
  const cv::Mat d = testing::RandomDescriptors(200, 1);
  std::vector<Match> exhaustive, direct;
  ASSERT_TRUE(MatchExhaustive(d, d, {}, &exhaustive).ok());
  ASSERT_TRUE(
      MatchByDirectIndex(AllUnderOneNode(200), d, AllUnderOneNode(200), d, {}, &direct).ok());
  ASSERT_EQ(exhaustive.size(), 200u);
  EXPECT_EQ(direct, exhaustive);
  for (const Match& m : exhaustive) {
    EXPECT_EQ(m.a, m.b);
    EXPECT_EQ(m.distance, 0u);
  }
}

TEST(CorrespondencesTest, DirectIndexComparesOnlyFeaturesUnderTheSameNode) {
  const cv::Mat d = testing::RandomDescriptors(4, 2);
  FeatureVector a, b;
  const uint32_t a0[] = {0, 1}, a1[] = {2, 3};
  a.AppendNode(3, a0);
  a.AppendNode(9, a1);
  const uint32_t b0[] = {0, 1}, b1[] = {2, 3};
  b.AppendNode(3, b0);
  b.AppendNode(12, b1);  // features 2 and 3 of B sit under another node than those of A
  std::vector<Match> matches;
  ASSERT_TRUE(MatchByDirectIndex(a, d, b, d, {}, &matches).ok());
  ASSERT_EQ(matches.size(), 2u);
  EXPECT_EQ(matches[0], (Match{0, 0, 0}));
  EXPECT_EQ(matches[1], (Match{1, 1, 0}));
}

TEST(CorrespondencesTest, AmbiguousAndDistantMatchesAreRejected) {
  cv::Mat a = testing::RandomDescriptors(1, 3);
  cv::Mat b(2, 32, CV_8U);
  a.copyTo(b.row(0));
  a.copyTo(b.row(1));
  b.at<uint8_t>(0, 0) ^= 0x0f;  // 4 bits away
  b.at<uint8_t>(1, 1) ^= 0x1f;  // 5 bits away: 4 is not clearly better than 5
  std::vector<Match> matches;
  ASSERT_TRUE(MatchExhaustive(a, b, {.ratio = 0.6, .max_distance = 50}, &matches).ok());
  EXPECT_TRUE(matches.empty());
  const cv::Mat far = testing::RandomDescriptors(1, 4);  // ~128 bits away
  ASSERT_TRUE(MatchExhaustive(a, far, {.ratio = 1.0, .max_distance = 50}, &matches).ok());
  EXPECT_TRUE(matches.empty());
}

TEST(CorrespondencesTest, MatchesAreOneToOneKeepingTheNearer) {
  cv::Mat b = testing::RandomDescriptors(1, 5);
  cv::Mat a(2, 32, CV_8U);
  b.copyTo(a.row(0));
  b.copyTo(a.row(1));
  a.at<uint8_t>(0, 3) ^= 0x7;  // 3 bits away; row 1 is exact
  std::vector<Match> matches;
  ASSERT_TRUE(MatchExhaustive(a, b, {}, &matches).ok());
  ASSERT_EQ(matches.size(), 1u);
  EXPECT_EQ(matches[0], (Match{1, 0, 0}));
}

// Sets bits [first, last) of row `row`.
void SetBits(cv::Mat* d, int row, int first, int last) {
  for (int bit = first; bit < last; ++bit) d->at<uint8_t>(row, bit / 8) |= uint8_t(1u << (bit % 8));
}

TEST(CorrespondencesTest, TheMutualCheckDropsAMatchWhoseFeatureOfBIsNearerAnotherOfA) {
  // d(a0, b0) = 10, d(a0, b1) = 17: a0's nearest is b0, clearly. d(a1, b1) = 2, d(a1, b0) = 5:
  // a1's nearest is b1. But b0's nearest in A is a1 (5 < 10): one-to-one keeps a0 -> b0 (no other
  // feature of A chose b0), the cross check does not.
  cv::Mat a = cv::Mat::zeros(2, 32, CV_8U), b = cv::Mat::zeros(2, 32, CV_8U);
  SetBits(&b, 0, 0, 10);
  SetBits(&a, 1, 0, 15);
  SetBits(&b, 1, 0, 17);
  const MatchOptions one_to_one{.ratio = 0.8, .max_distance = 50};
  MatchOptions mutual = one_to_one;
  mutual.mutual = true;
  std::vector<Match> exhaustive, direct;
  ASSERT_TRUE(MatchExhaustive(a, b, one_to_one, &exhaustive).ok());
  EXPECT_EQ(exhaustive, (std::vector<Match>{{0, 0, 10}, {1, 1, 2}}));
  ASSERT_TRUE(MatchExhaustive(a, b, mutual, &exhaustive).ok());
  EXPECT_EQ(exhaustive, (std::vector<Match>{{1, 1, 2}}));
  ASSERT_TRUE(
      MatchByDirectIndex(AllUnderOneNode(2), a, AllUnderOneNode(2), b, mutual, &direct).ok());
  EXPECT_EQ(direct, exhaustive);
  // Under two nodes, a1 is never compared with b0: b0's nearest is then a0, and both match.
  FeatureVector split_a, split_b;
  const uint32_t first[] = {0}, second[] = {1};
  split_a.AppendNode(1, first);
  split_a.AppendNode(2, second);
  split_b.AppendNode(1, first);
  split_b.AppendNode(2, second);
  ASSERT_TRUE(MatchByDirectIndex(split_a, a, split_b, b, mutual, &direct).ok());
  EXPECT_EQ(direct, (std::vector<Match>{{0, 0, 10}, {1, 1, 2}}));
}

TEST(CorrespondencesTest, NonBinaryOrMismatchedDescriptorsAreRefused) {
  std::vector<Match> matches;
  EXPECT_EQ(MatchExhaustive(cv::Mat(3, 32, CV_32F), cv::Mat(3, 32, CV_32F), {}, &matches).code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(MatchExhaustive(cv::Mat(3, 32, CV_8U), cv::Mat(3, 64, CV_8U), {}, &matches).code(),
            StatusCode::kInvalidArgument);
}

// A direct index that names features its descriptors lack comes from a damaged record: DATA_LOSS,
// saying which side and by how much (the caller adds which record).
TEST(CorrespondencesTest, ADirectIndexBeyondItsDescriptorsIsDataLoss) {
  const cv::Mat three(3, 32, CV_8U, cv::Scalar(0));
  std::vector<Match> matches;
  const Status a =
      MatchByDirectIndex(AllUnderOneNode(9), three, AllUnderOneNode(3), three, {}, &matches);
  EXPECT_EQ(a.code(), StatusCode::kDataLoss);
  EXPECT_EQ(a.message(), "the direct index of A names feature 8, but A has 3 features");
  const Status b =
      MatchByDirectIndex(AllUnderOneNode(3), three, AllUnderOneNode(4), three, {}, &matches);
  EXPECT_EQ(b.code(), StatusCode::kDataLoss);
  EXPECT_EQ(b.message(), "the direct index of B names feature 3, but B has 3 features");
}

TEST(CorrespondencesTest, MatchOptionsValidateTheRatio) {
  EXPECT_TRUE(MatchOptions{}.Validate().ok());
  EXPECT_TRUE((MatchOptions{.ratio = 1.0}).Validate().ok());
  for (const double ratio :
       {0.0, -0.5, 1.5, std::nan(""), std::numeric_limits<double>::infinity()}) {
    const Status s = MatchOptions{.ratio = ratio}.Validate("RecognitionOptions.match");
    EXPECT_EQ(s.code(), StatusCode::kInvalidArgument) << ratio;
    EXPECT_EQ(s.message().rfind("RecognitionOptions.match.ratio = ", 0), 0u) << s.message();
    EXPECT_NE(s.message().find("must be in (0, 1]"), std::string::npos) << s.message();
  }
}

// B holds a noisy copy of each of A's descriptors among random ones, its nodes listing their
// features out of order of the rows: the in-order variant must give exactly MatchByDirectIndex's
// matches.
TEST(CorrespondencesTest, MatchingAgainstDescriptorsInDirectOrderGivesTheSameMatches) {
  const cv::Mat a = testing::RandomDescriptors(300, 8);
  cv::Mat b;
  cv::vconcat(a, testing::RandomDescriptors(600, 9), b);
  for (int r = 0; r < 300; r += 2) b.at<uint8_t>(r, r % 32) ^= 0x5;  // 2 bits off
  auto by_node = [](uint32_t rows, uint32_t nodes) {
    std::vector<std::pair<NodeId, uint32_t>> pairs;
    for (uint32_t f = 0; f < rows; ++f) pairs.push_back({(f * 7919u) % nodes, f});
    std::sort(pairs.begin(), pairs.end());
    FeatureVector fv;
    fv.AssignSorted(pairs);
    return fv;
  };
  const FeatureVector a_direct = by_node(300, 5), b_direct = by_node(900, 5);
  auto ordered = DescriptorsInDirectOrder(b_direct, b);
  ASSERT_TRUE(ordered.ok()) << ordered.status().ToString();
  ASSERT_EQ(ordered->rows, b.rows);
  EXPECT_EQ(cv::countNonZero(ordered->row(0) != b.row(int(b_direct.features(0)[0]))), 0);
  const MatchOptions options{.ratio = 0.8, .max_distance = 64};
  std::vector<Match> plain, in_order;
  ASSERT_TRUE(MatchByDirectIndex(a_direct, a, b_direct, b, options, &plain).ok());
  ASSERT_TRUE(MatchByDirectIndexInOrder(a_direct, a, b_direct, *ordered, options, &in_order).ok());
  EXPECT_EQ(plain.size(), 300u);  // every copy, under the node of its original
  EXPECT_EQ(in_order, plain);
}

TEST(CorrespondencesTest, DescriptorsInDirectOrderMustMatchTheirDirectIndex) {
  const cv::Mat d = testing::RandomDescriptors(3, 2);
  const Status beyond = DescriptorsInDirectOrder(AllUnderOneNode(9), d).status();
  EXPECT_EQ(beyond.code(), StatusCode::kDataLoss);
  EXPECT_EQ(beyond.message(), "the direct index of B names feature 8, but B has 3 features");
  std::vector<Match> matches;
  const Status rows =
      MatchByDirectIndexInOrder(AllUnderOneNode(3), d, AllUnderOneNode(4), d, {}, &matches);
  EXPECT_EQ(rows.code(), StatusCode::kDataLoss);
  EXPECT_NE(rows.message().find("3 rows for the 4 features"), std::string::npos) << rows.message();
}

// Two views of random 3D points: camera A at the origin, camera B moved sideways and turned; both
// with fx = fy = 500 and the principal point (320, 240), or camera B with `b_camera`.
void TwoViews(int n, uint64_t seed, std::vector<cv::KeyPoint>* ka, std::vector<cv::KeyPoint>* kb,
              const cv::Matx33d& b_camera = {500, 0, 320, 0, 500, 240, 0, 0, 1}) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> xy(-2, 2), z(4, 8);
  const cv::Matx33d rotation(std::cos(0.1), 0, std::sin(0.1), 0, 1, 0, -std::sin(0.1), 0,
                             std::cos(0.1));
  const cv::Vec3d translation(0.5, 0.05, 0.1);
  for (int i = 0; i < n; ++i) {
    const cv::Vec3d p(xy(rng), xy(rng), z(rng));
    const cv::Vec3d q = rotation * p + translation;
    ka->emplace_back(float(500 * p[0] / p[2] + 320), float(500 * p[1] / p[2] + 240), 31.f);
    kb->emplace_back(float(b_camera(0, 0) * q[0] / q[2] + b_camera(0, 2)),
                     float(b_camera(1, 1) * q[1] / q[2] + b_camera(1, 2)), 31.f);
  }
}

TEST(EpipolarTest, MatchesOfARigidSceneAreVerifiedWithEveryInlier) {
  std::vector<cv::KeyPoint> ka, kb;
  TwoViews(60, 1, &ka, &kb);
  std::vector<Match> matches;
  for (uint32_t i = 0; i < 60; ++i) matches.push_back({i, i, 0});
  const EpipolarResult r = VerifyEpipolar(ka, kb, matches, {});
  EXPECT_TRUE(r.verified);
  EXPECT_EQ(r.inliers.size(), 60u);
  // x_b^T F x_a = 0 for a correspondence
  const cv::Vec3d xa(ka[5].pt.x, ka[5].pt.y, 1), xb(kb[5].pt.x, kb[5].pt.y, 1);
  EXPECT_NEAR((xb.t() * r.fundamental * xa)(0), 0.0, 1e-2);
}

TEST(EpipolarTest, RandomMatchesAndTooFewMatchesAreNotVerified) {
  std::vector<cv::KeyPoint> ka, kb;
  TwoViews(60, 2, &ka, &kb);
  std::vector<Match> shuffled;
  for (uint32_t i = 0; i < 60; ++i) shuffled.push_back({i, (i * 37 + 11) % 60, 0});
  EXPECT_FALSE(VerifyEpipolar(ka, kb, shuffled, {.min_inliers = 30}).verified);
  std::vector<Match> few = {{0, 0, 0}, {1, 1, 0}, {2, 2, 0}};
  const EpipolarResult r = VerifyEpipolar(ka, kb, few, {});
  EXPECT_FALSE(r.verified);
  EXPECT_TRUE(r.inliers.empty());
  std::vector<Match> out_of_range = {{0, 500, 0}};
  EXPECT_FALSE(VerifyEpipolar(ka, kb, out_of_range, {}).verified);
}

TEST(RelativePoseTest, TheMotionBetweenTwoViewsIsRecoveredUpToScale) {
  std::vector<cv::KeyPoint> ka, kb;
  TwoViews(80, 3, &ka, &kb);
  std::vector<Match> matches;
  for (uint32_t i = 0; i < 80; ++i) matches.push_back({i, i, 0});
  const EpipolarResult r = VerifyEpipolar(ka, kb, matches, {});
  ASSERT_TRUE(r.verified);
  const cv::Matx33d K(500, 0, 320, 0, 500, 240, 0, 0, 1);
  cv::Matx33d R;
  cv::Vec3d t;
  ASSERT_TRUE(RelativePoseFromFundamental(r.fundamental, K, K, ka, kb, r.inliers, &R, &t));
  const cv::Matx33d expected(std::cos(0.1), 0, std::sin(0.1), 0, 1, 0, -std::sin(0.1), 0,
                             std::cos(0.1));
  EXPECT_LT(cv::norm(R - expected), 0.02);
  const cv::Vec3d direction = cv::normalize(cv::Vec3d(0.5, 0.05, 0.1));
  EXPECT_NEAR(cv::norm(t), 1.0, 1e-6);
  EXPECT_GT(t.dot(direction), 0.995);
}

// Two cameras with other intrinsics (two robots, or two cameras of a rig): each view's pixels are
// normalised with its own camera matrix. Taking A's for both gives a wrong motion.
TEST(RelativePoseTest, TwoCamerasWithTheirOwnIntrinsicsGiveTheMotion) {
  const cv::Matx33d Ka(500, 0, 320, 0, 500, 240, 0, 0, 1), Kb(760, 0, 300, 0, 740, 260, 0, 0, 1);
  std::vector<cv::KeyPoint> ka, kb;
  TwoViews(80, 3, &ka, &kb, Kb);
  std::vector<Match> matches;
  for (uint32_t i = 0; i < 80; ++i) matches.push_back({i, i, 0});
  const EpipolarResult r = VerifyEpipolar(ka, kb, matches, {});
  ASSERT_TRUE(r.verified);
  const cv::Matx33d expected(std::cos(0.1), 0, std::sin(0.1), 0, 1, 0, -std::sin(0.1), 0,
                             std::cos(0.1));
  const cv::Vec3d direction = cv::normalize(cv::Vec3d(0.5, 0.05, 0.1));
  cv::Matx33d R;
  cv::Vec3d t;
  ASSERT_TRUE(RelativePoseFromFundamental(r.fundamental, Ka, Kb, ka, kb, r.inliers, &R, &t));
  EXPECT_LT(cv::norm(R - expected), 0.02);
  EXPECT_GT(t.dot(direction), 0.995);
  const bool one_camera =
      RelativePoseFromFundamental(r.fundamental, Ka, Ka, ka, kb, r.inliers, &R, &t);
  EXPECT_FALSE(one_camera && cv::norm(R - expected) < 0.02 && t.dot(direction) > 0.995);
}

TEST(RelativePoseTest, AZeroMatrixOrTooFewInliersGiveNoPose) {
  std::vector<cv::KeyPoint> ka, kb;
  TwoViews(10, 4, &ka, &kb);
  const cv::Matx33d K(500, 0, 320, 0, 500, 240, 0, 0, 1);
  cv::Matx33d R;
  cv::Vec3d t;
  std::vector<Match> all;
  for (uint32_t i = 0; i < 10; ++i) all.push_back({i, i, 0});
  EXPECT_FALSE(RelativePoseFromFundamental(cv::Matx33d::zeros(), K, K, ka, kb, all, &R, &t));
  std::vector<Match> few(all.begin(), all.begin() + 4);
  EXPECT_FALSE(RelativePoseFromFundamental(cv::Matx33d::eye(), K, K, ka, kb, few, &R, &t));
  std::vector<Match> out_of_range = all;
  out_of_range[0].b = 99;
  EXPECT_FALSE(RelativePoseFromFundamental(cv::Matx33d::eye(), K, K, ka, kb, out_of_range, &R, &t));
}

// Two views of points on one plane (z = 5 - 0.2 x), with the motion of TwoViews and 0.3 px of
// noise: a homography explains every correspondence.
void PlanarViews(int n, uint64_t seed, std::vector<cv::KeyPoint>* ka,
                 std::vector<cv::KeyPoint>* kb) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> xy(-2, 2);
  std::normal_distribution<double> noise(0.0, 0.3);
  const cv::Matx33d rotation(std::cos(0.1), 0, std::sin(0.1), 0, 1, 0, -std::sin(0.1), 0,
                             std::cos(0.1));
  const cv::Vec3d translation(0.5, 0.05, 0.1);
  for (int i = 0; i < n; ++i) {
    const double x = xy(rng), y = xy(rng);
    const cv::Vec3d p(x, y, 5.0 - 0.2 * x);
    const cv::Vec3d q = rotation * p + translation;
    ka->emplace_back(float(500 * p[0] / p[2] + 320 + noise(rng)),
                     float(500 * p[1] / p[2] + 240 + noise(rng)), 31.f);
    kb->emplace_back(float(500 * q[0] / q[2] + 320 + noise(rng)),
                     float(500 * q[1] / q[2] + 240 + noise(rng)), 31.f);
  }
}

std::vector<Match> Identity(uint32_t n) {
  std::vector<Match> matches;
  for (uint32_t i = 0; i < n; ++i) matches.push_back({i, i, 0});
  return matches;
}

TEST(ModelSelectionTest, APlanarSceneIsExplainedByAHomography) {
  std::vector<cv::KeyPoint> ka, kb;
  PlanarViews(100, 5, &ka, &kb);
  const std::vector<Match> matches = Identity(100);
  const EpipolarResult f = VerifyEpipolar(ka, kb, matches, {});
  ASSERT_TRUE(f.verified) << "F fits a plane too: that is why it proves little there";
  const ModelSelection m = SelectTwoViewModel(ka, kb, f.inliers, f.fundamental, {});
  EXPECT_GT(m.homography_ratio, 0.45);
  EXPECT_GT(m.homography_score, 0.0);
  EXPECT_NE(m.homography, cv::Matx33d::zeros());
}

TEST(ModelSelectionTest, ATranslatedThreeDimensionalSceneIsExplainedByTheFundamentalMatrix) {
  std::vector<cv::KeyPoint> ka, kb;
  TwoViews(100, 6, &ka, &kb);
  const EpipolarResult f = VerifyEpipolar(ka, kb, Identity(100), {});
  ASSERT_TRUE(f.verified);
  const ModelSelection m = SelectTwoViewModel(ka, kb, f.inliers, f.fundamental, {});
  EXPECT_LT(m.homography_ratio, 0.3);
  EXPECT_GT(m.fundamental_score, m.homography_score);
  EXPECT_NEAR(m.homography_ratio, m.homography_score / (m.homography_score + m.fundamental_score),
              1e-12);
}

TEST(ModelSelectionTest, TooFewOrOutOfRangeMatchesScoreNothing) {
  std::vector<cv::KeyPoint> ka, kb;
  TwoViews(10, 7, &ka, &kb);
  const cv::Matx33d f = VerifyEpipolar(ka, kb, Identity(10), {.min_inliers = 8}).fundamental;
  const ModelSelection few = SelectTwoViewModel(ka, kb, Identity(3), f, {});
  EXPECT_EQ(few.homography_ratio, 0.0);
  EXPECT_EQ(few.fundamental_score, 0.0);
  std::vector<Match> out_of_range = Identity(10);
  out_of_range[3].b = 99;
  EXPECT_EQ(SelectTwoViewModel(ka, kb, out_of_range, f, {}).fundamental_score, 0.0);
}

TEST(InlierSpreadTest, MatchesBunchedInACornerCoverLessThanSpreadOnes) {
  std::vector<cv::KeyPoint> ka, kb;
  for (int y = 0; y < 10; ++y) {
    for (int x = 0; x < 10; ++x) {
      ka.emplace_back(float(x * 64), float(y * 48), 31.f);
      kb.emplace_back(float(x * 64 + 5), float(y * 48 + 5), 31.f);
    }
  }
  EXPECT_DOUBLE_EQ(InlierSpread(ka, kb, Identity(100), 4), 1.0);
  const std::vector<Match> corner = {{0, 0, 0}, {1, 1, 0}, {10, 10, 0}, {11, 11, 0}};
  EXPECT_DOUBLE_EQ(InlierSpread(ka, kb, corner, 4), 1.0 / 16.0);
  // The smaller share of the two images: all of B's matched keypoints in one cell.
  const std::vector<Match> one_cell_in_b = {{0, 0, 0}, {99, 1, 0}};
  EXPECT_DOUBLE_EQ(InlierSpread(ka, kb, one_cell_in_b, 4), 1.0 / 16.0);
  EXPECT_EQ(InlierSpread(ka, kb, {}, 4), 0.0);
  EXPECT_EQ(InlierSpread(ka, kb, {{0, 100, 0}}, 4), 0.0);
}

}  // namespace
}  // namespace recog

namespace recog {
namespace {

const cv::Matx33d kCamera(500, 0, 320, 0, 500, 240, 0, 0, 1);

// Views of random points 4-8 m ahead from camera A and from camera B = (R, t) (X_b = R X_a + t).
void PosedViews(const cv::Matx33d& R, const cv::Vec3d& t, int n, uint64_t seed,
                std::vector<cv::KeyPoint>* ka, std::vector<cv::KeyPoint>* kb) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> xy(-2, 2), z(4, 8);
  for (int i = 0; i < n; ++i) {
    const cv::Vec3d p(xy(rng), xy(rng), z(rng));
    const cv::Vec3d q = R * p + t;
    ka->emplace_back(float(500 * p[0] / p[2] + 320), float(500 * p[1] / p[2] + 240), 31.f);
    kb->emplace_back(float(500 * q[0] / q[2] + 320), float(500 * q[1] / q[2] + 240), 31.f);
  }
}

cv::Matx33d Yaw(double radians) {
  return {std::cos(radians),  0, std::sin(radians), 0, 1, 0,
          -std::sin(radians), 0, std::cos(radians)};
}

TEST(EssentialTest, ARigidSceneTriangulatesInFrontWithParallaxAndItsMotion) {
  std::vector<cv::KeyPoint> ka, kb;
  PosedViews(Yaw(0.3), {0.8, 0.0, 0.1}, 80, 5, &ka, &kb);
  const EssentialResult r = VerifyEssential(kCamera, kCamera, ka, kb, Identity(80), {});
  ASSERT_TRUE(r.found);
  EXPECT_EQ(r.inliers.size(), 80u);
  EXPECT_EQ(r.in_front, 80u);
  EXPECT_GT(r.parallax_deg, 3.0);
  EXPECT_LT(cv::norm(r.R - Yaw(0.3)), 0.01);
  EXPECT_GT(r.t.dot(cv::normalize(cv::Vec3d(0.8, 0.0, 0.1))), 0.999);
  EXPECT_LT(r.rotation_only, 10u);  // the baseline shows: the rotation alone explains little
}

TEST(EssentialTest, APureRotationHasNoParallaxAndTheRotationExplainsIt) {
  std::vector<cv::KeyPoint> ka, kb;
  PosedViews(Yaw(0.2), {0, 0, 0}, 80, 6, &ka, &kb);
  const EssentialResult r = VerifyEssential(kCamera, kCamera, ka, kb, Identity(80), {});
  ASSERT_TRUE(r.found);
  EXPECT_LT(r.parallax_deg, 0.1);
  EXPECT_GE(r.rotation_only, 76u);
  EXPECT_LT(cv::norm(r.R - Yaw(0.2)), 0.01);
}

// Pairs of unrelated points fit no essential matrix with many inliers; fewer than 5 matches or a
// match out of range give none at all.
TEST(EssentialTest, RandomPairsFewMatchesOrBadIndicesGiveNoEssentialMatrix) {
  std::vector<cv::KeyPoint> ka, kb;
  PosedViews(Yaw(0.3), {0.8, 0.0, 0.1}, 80, 7, &ka, &kb);
  std::vector<cv::KeyPoint> shuffled = kb;
  std::mt19937_64 rng(8);
  std::shuffle(shuffled.begin(), shuffled.end(), rng);
  const EssentialResult r = VerifyEssential(kCamera, kCamera, ka, shuffled, Identity(80), {});
  EXPECT_LT(r.inliers.size(), 40u);  // random pairs: most are not inliers
  EXPECT_FALSE(VerifyEssential(kCamera, kCamera, ka, kb, Identity(4), {}).found);
  std::vector<Match> out_of_range = Identity(10);
  out_of_range[3].b = 500;
  EXPECT_FALSE(VerifyEssential(kCamera, kCamera, ka, kb, out_of_range, {}).found);
}

// A given essential matrix (K^T F K of a fundamental matrix) measured on its inliers: the same
// motion and triangulation as the five-point fit; fewer than 5 inliers or one out of range give
// none.
TEST(EssentialTest, AGivenEssentialMatrixIsMeasuredOnItsInliers) {
  std::vector<cv::KeyPoint> ka, kb;
  PosedViews(Yaw(0.3), {0.8, 0.0, 0.1}, 80, 9, &ka, &kb);
  const EpipolarResult fitted = VerifyEpipolar(ka, kb, Identity(80), {});
  ASSERT_TRUE(fitted.verified);
  const cv::Matx33d essential = kCamera.t() * fitted.fundamental * kCamera;
  const EssentialResult r =
      MeasureEssential(essential, kCamera, kCamera, ka, kb, fitted.inliers, 2.0);
  ASSERT_TRUE(r.found);
  EXPECT_EQ(r.inliers.size(), fitted.inliers.size());
  EXPECT_GE(r.in_front, uint32_t(0.95 * double(fitted.inliers.size())));
  EXPECT_GT(r.parallax_deg, 3.0);
  EXPECT_LT(cv::norm(r.R - Yaw(0.3)), 0.02);
  EXPECT_GT(r.t.dot(cv::normalize(cv::Vec3d(0.8, 0.0, 0.1))), 0.99);
  EXPECT_FALSE(MeasureEssential(essential, kCamera, kCamera, ka, kb, Identity(4), 2.0).found);
  std::vector<Match> out_of_range = Identity(10);
  out_of_range[3].b = 500;
  EXPECT_FALSE(MeasureEssential(essential, kCamera, kCamera, ka, kb, out_of_range, 2.0).found);
}

}  // namespace
}  // namespace recog
