#include "core/geometry/camera_model.h"

#include <cmath>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/calib3d.hpp>

namespace recog {
namespace {

constexpr double kDegree = CV_PI / 180.0;

// EuRoC's cam0 (Kalibr radtan, 752 x 480).
CameraIntrinsics EurocRadtan() {
  return {
      458.654, 457.296, 367.215, 248.375, {-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05}};
}

// A TUM-VI / T265-like fisheye (512 x 512).
CameraIntrinsics TumViEquidistant() {
  return {190.97,
          190.97,
          254.93,
          256.90,
          {0.00348, 0.000715, -0.00205, 0.000203},
          LensModel::kEquidistant};
}

// Kalibr's double sphere calibration of the same kind of camera (512 x 512).
CameraIntrinsics KalibrDoubleSphere() {
  return {156.05, 155.76, 254.62, 256.39, {-0.2392, 0.5755}, LensModel::kDoubleSphere};
}

// The unit direction `theta` off the optical axis at azimuth `phi` (radians).
cv::Vec3d Direction(double theta, double phi) {
  return {std::sin(theta) * std::cos(phi), std::sin(theta) * std::sin(phi), std::cos(theta)};
}

// Directions from the axis to `max_theta` off it, all round.
std::vector<cv::Vec3d> DirectionGrid(double max_theta) {
  std::vector<cv::Vec3d> directions;
  for (int i = 0; i <= 20; ++i) {
    for (int j = 0; j < 24; ++j)
      directions.push_back(Direction(max_theta * i / 20, CV_PI * j / 12));
  }
  return directions;
}

// The pixels of a width x height image every `step` pixels, its borders included.
std::vector<cv::Point2d> PixelGrid(int width, int height, int step) {
  std::vector<cv::Point2d> pixels;
  for (int y = 0; y <= height - 1; y += step) {
    for (int x = 0; x <= width - 1; x += step) pixels.emplace_back(x, y);
    pixels.emplace_back(width - 1, y);
  }
  for (int x = 0; x <= width - 1; x += step) pixels.emplace_back(x, height - 1);
  return pixels;
}

// Where K puts the normalised point of `bearing`.
cv::Point2d PinholePixel(const CameraIntrinsics& camera, const cv::Vec3d& bearing) {
  return {camera.fx * bearing[0] / bearing[2] + camera.cx,
          camera.fy * bearing[1] / bearing[2] + camera.cy};
}

// The largest pixel distance between ProjectDirection and OpenCV's projection of `directions`.
template <class OpenCvProjection>
double MaxProjectionError(const CameraIntrinsics& camera, const std::vector<cv::Vec3d>& directions,
                          OpenCvProjection opencv_project) {
  std::vector<cv::Point3d> points(directions.begin(), directions.end());
  std::vector<cv::Point2d> expected;
  opencv_project(points, &expected);
  double max_error = 0;
  for (size_t i = 0; i < directions.size(); ++i) {
    cv::Point2d pixel;
    EXPECT_TRUE(ProjectDirection(camera, directions[i], &pixel)) << directions[i];
    max_error = std::max(max_error, cv::norm(pixel - expected[i]));
  }
  return max_error;
}

// Checks that every pixel unprojects to a unit bearing that projects back onto it.
void ExpectRoundTrips(const CameraIntrinsics& camera, const std::vector<cv::Point2d>& pixels) {
  double max_error = 0;
  for (const cv::Point2d& pixel : pixels) {
    cv::Vec3d bearing;
    cv::Point2d back;
    ASSERT_TRUE(UnprojectPixel(camera, pixel, &bearing)) << pixel;
    EXPECT_NEAR(cv::norm(bearing), 1.0, 1e-12);
    ASSERT_TRUE(ProjectDirection(camera, bearing, &back)) << pixel << " " << bearing;
    max_error = std::max(max_error, cv::norm(back - pixel));
  }
  EXPECT_LT(max_error, 1e-6) << camera.Describe();
}

TEST(LensModelTest, NamesAndCalibrationFileNamesParse) {
  for (LensModel lens :
       {LensModel::kRadialTangential, LensModel::kEquidistant, LensModel::kDoubleSphere}) {
    const StatusOr<LensModel> parsed = ParseLensModel(LensModelName(lens));
    ASSERT_TRUE(parsed.ok()) << LensModelName(lens);
    EXPECT_EQ(*parsed, lens);
  }
  EXPECT_EQ(LensModelName(LensModel::kRadialTangential), "radtan");
  EXPECT_EQ(LensModelName(LensModel::kEquidistant), "equidistant");
  EXPECT_EQ(LensModelName(LensModel::kDoubleSphere), "double_sphere");
  for (const char* name : {"plumb_bob", "rational_polynomial", "radial-tangential"}) {
    EXPECT_EQ(ParseLensModel(name).value(), LensModel::kRadialTangential) << name;
  }
  for (const char* name : {"equi", "fisheye", "kannala_brandt"}) {
    EXPECT_EQ(ParseLensModel(name).value(), LensModel::kEquidistant) << name;
  }
  EXPECT_EQ(ParseLensModel("ds").value(), LensModel::kDoubleSphere);
}

TEST(LensModelTest, AnUnknownNameListsTheKnownOnes) {
  const StatusOr<LensModel> parsed = ParseLensModel("mei");
  ASSERT_EQ(parsed.status().code(), StatusCode::kInvalidArgument);
  const std::string message = parsed.status().message();
  EXPECT_NE(message.find("'mei'"), std::string::npos) << message;
  for (const char* name :
       {"radtan", "plumb_bob", "equidistant", "kannala_brandt", "double_sphere", "ds"}) {
    EXPECT_NE(message.find(name), std::string::npos) << message;
  }
  EXPECT_FALSE(ParseLensModel("").ok());
  EXPECT_FALSE(ParseLensModel("Radtan").ok());
}

TEST(CameraIntrinsicsTest, PinholeMeansNoDistortion) {
  EXPECT_TRUE((CameraIntrinsics{500, 500, 320, 240, {}}).IsPinhole());
  EXPECT_TRUE((CameraIntrinsics{500, 500, 320, 240, {0, 0, 0, 0, 0}}).IsPinhole());
  EXPECT_TRUE((CameraIntrinsics{500, 500, 320, 240, {}, LensModel::kEquidistant}).IsPinhole());
  EXPECT_FALSE(EurocRadtan().IsPinhole());
  // θd = θ is a fisheye, not a pinhole.
  EXPECT_FALSE(
      (CameraIntrinsics{500, 500, 320, 240, {0, 0, 0, 0}, LensModel::kEquidistant}).IsPinhole());
  EXPECT_FALSE(KalibrDoubleSphere().IsPinhole());
}

TEST(CameraIntrinsicsTest, ValidAcceptsEachLensCoefficientCount) {
  CameraIntrinsics camera{500, 500, 320, 240, {}};
  for (size_t n : {0, 4, 5, 8, 12, 14}) {
    camera.distortion.assign(n, 0.01);
    EXPECT_TRUE(camera.Validate().ok()) << n << ": " << camera.Validate().message();
  }
  EXPECT_TRUE(TumViEquidistant().Validate().ok());
  EXPECT_TRUE(KalibrDoubleSphere().Validate().ok());
  for (double alpha : {0.0, 1.0}) {
    EXPECT_TRUE((CameraIntrinsics{500, 500, 320, 240, {0.5, alpha}, LensModel::kDoubleSphere})
                    .Validate()
                    .ok());
  }
}

TEST(CameraIntrinsicsTest, ValidateNamesTheFault) {
  struct Case {
    CameraIntrinsics camera;
    std::string message;
  };
  const std::vector<Case> cases = {
      {{0, 500, 320, 240, {}}, "camera intrinsics need finite fx, fy > 0 and finite cx, cy"},
      {{500, -1, 320, 240, {}}, "camera intrinsics need finite fx, fy > 0 and finite cx, cy"},
      {{500, 500, NAN, 240, {}}, "camera intrinsics need finite fx, fy > 0 and finite cx, cy"},
      {{500, 500, 320, INFINITY, {}}, "camera intrinsics need finite fx, fy > 0 and finite cx, cy"},
      {{500, 500, 320, 240, {0.1, NAN, 0, 0}}, "camera distortion is not finite"},
      {{500, 500, 320, 240, {0.1, 0.2, 0.3}},
       "camera distortion needs 4, 5, 8, 12 or 14 coefficients, got 3"},
      {{500, 500, 320, 240, std::vector<double>(6, 0.1)},
       "camera distortion needs 4, 5, 8, 12 or 14 coefficients, got 6"},
      {{500, 500, 320, 240, std::vector<double>(13, 0.1)},
       "camera distortion needs 4, 5, 8, 12 or 14 coefficients, got 13"},
      {{500, 500, 320, 240, {0.1, 0.2, 0.3, 0.4, 0.5}, LensModel::kEquidistant},
       "equidistant camera distortion needs 4 coefficients (k1 k2 k3 k4), got 5"},
      {{500, 500, 320, 240, {0.1, INFINITY, 0, 0}, LensModel::kEquidistant},
       "equidistant camera distortion is not finite"},
      {{500, 500, 320, 240, {0.1}, LensModel::kDoubleSphere},
       "double_sphere camera distortion needs 2 coefficients (xi alpha), got 1"},
      {{500, 500, 320, 240, {0.1, 1.5}, LensModel::kDoubleSphere},
       "double_sphere camera needs alpha in [0, 1], got 1.5"},
      {{500, 500, 320, 240, {0.1, -0.25}, LensModel::kDoubleSphere},
       "double_sphere camera needs alpha in [0, 1], got -0.25"},
      {{500, 500, 320, 240, {NAN, 0.5}, LensModel::kDoubleSphere},
       "double_sphere camera distortion is not finite"},
      {{500, 500, 320, 240, {}, static_cast<LensModel>(7)}, "camera lens model 7 is unknown"},
  };
  for (const Case& test : cases) {
    const Status status = test.camera.Validate();
    EXPECT_EQ(status.code(), StatusCode::kInvalidArgument) << test.message;
    EXPECT_EQ(status.message(), test.message);
  }
}

TEST(CameraIntrinsicsTest, DescribeNamesTheLensAndEveryNumber) {
  EXPECT_EQ(TumViEquidistant().Describe(),
            "equidistant fx=190.97 fy=190.97 cx=254.93 cy=256.9 [0.00348 0.000715 -0.00205 "
            "0.000203]");
  EXPECT_EQ(KalibrDoubleSphere().Describe(),
            "double_sphere fx=156.05 fy=155.76 cx=254.62 cy=256.39 [-0.2392 0.5755]");
  EXPECT_EQ((CameraIntrinsics{500, 501, 319.5, 239.5, {}}).Describe(),
            "pinhole fx=500 fy=501 cx=319.5 cy=239.5");
  EXPECT_EQ((CameraIntrinsics{500, 501, 319.5, 239.5, {0.1, -0.2, 0, 0}}).Describe(),
            "radtan fx=500 fy=501 cx=319.5 cy=239.5 [0.1 -0.2 0 0]");
}

TEST(PinholeTest, ProjectsInFrontAndUnprojectsEverywhere) {
  const CameraIntrinsics camera{500, 400, 320, 240, {}};
  cv::Point2d pixel;
  ASSERT_TRUE(ProjectDirection(camera, {0.2, -0.1, 2}, &pixel));
  EXPECT_NEAR(pixel.x, 370, 1e-12);
  EXPECT_NEAR(pixel.y, 220, 1e-12);
  EXPECT_FALSE(ProjectDirection(camera, {0.2, -0.1, 0}, &pixel));
  EXPECT_FALSE(ProjectDirection(camera, {0.2, -0.1, -1}, &pixel));
  EXPECT_FALSE(ProjectDirection(camera, {0, 0, 0}, &pixel));
  cv::Vec3d bearing;
  ASSERT_TRUE(UnprojectPixel(camera, {370, 220}, &bearing));
  EXPECT_LT(cv::norm(bearing - cv::normalize(cv::Vec3d(0.1, -0.05, 1))), 1e-12);
  ASSERT_TRUE(UnprojectPixel(camera, {-1e5, 3e5}, &bearing));
  EXPECT_NEAR(cv::norm(bearing), 1, 1e-12);
}

// Coefficient sets of each length OpenCV takes, with a tilted sensor for 14.
std::vector<std::vector<double>> RadtanCoefficientSets() {
  return {
      {-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05},
      {-0.25, 0.08, 0.001, -0.0005, 0.01},
      {0.2, -0.05, 0.0004, -0.0003, 0.01, 0.5, -0.02, 0.01},
      {-0.3, 0.1, 0.001, -0.0005, 0.01, 0.05, 0.01, 0.002, 0.001, -0.0005, 0.0008, 0.0002},
      {-0.3, 0.1, 0.001, -0.0005, 0.01, 0.05, 0.01, 0.002, 0.001, -0.0005, 0.0008, 0.0002, 0.01,
       -0.02},
  };
}

TEST(RadtanTest, ProjectMatchesOpenCv) {
  for (const std::vector<double>& coefficients : RadtanCoefficientSets()) {
    CameraIntrinsics camera = EurocRadtan();
    camera.distortion = coefficients;
    const double error = MaxProjectionError(
        camera, DirectionGrid(40 * kDegree),
        [&](const std::vector<cv::Point3d>& points, std::vector<cv::Point2d>* out) {
          cv::projectPoints(points, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), camera.K(),
                            camera.distortion, *out);
        });
    EXPECT_LT(error, 1e-6) << coefficients.size() << " coefficients";
  }
  cv::Point2d pixel;
  EXPECT_FALSE(ProjectDirection(EurocRadtan(), {0.1, 0.1, 0}, &pixel));
  EXPECT_FALSE(ProjectDirection(EurocRadtan(), {0.1, 0.1, -1}, &pixel));
}

TEST(RadtanTest, UnprojectMatchesOpenCvAndRoundTrips) {
  const std::vector<cv::Point2d> pixels = PixelGrid(752, 480, 16);
  for (const std::vector<double>& coefficients : RadtanCoefficientSets()) {
    CameraIntrinsics camera = EurocRadtan();
    camera.distortion = coefficients;
    std::vector<cv::Point2d> undistorted;
    cv::undistortPoints(
        pixels, undistorted, camera.K(), camera.distortion, cv::noArray(), cv::noArray(),
        cv::TermCriteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 200, 1e-10));
    double max_error = 0;
    for (size_t i = 0; i < pixels.size(); ++i) {
      cv::Vec3d bearing;
      ASSERT_TRUE(UnprojectPixel(camera, pixels[i], &bearing)) << pixels[i];
      const cv::Point2d expected = PinholePixel(camera, {undistorted[i].x, undistorted[i].y, 1});
      max_error = std::max(max_error, cv::norm(PinholePixel(camera, bearing) - expected));
    }
    EXPECT_LT(max_error, 0.01) << coefficients.size() << " coefficients";
    ExpectRoundTrips(camera, pixels);
  }
}

// With k3 = -0.02 the lens folds about 1.4 off the axis on the normalised plane (u = 794 px on
// the x axis): the image's corners are beyond anything it shows, and a pixel that two directions
// project to is the one's on the lens's side of the fold.
TEST(RadtanTest, UnprojectStaysOnTheLensSideOfAFold) {
  CameraIntrinsics camera = EurocRadtan();
  camera.distortion = {-0.25, 0.08, 0.001, -0.0005, -0.02};
  cv::Vec3d bearing;
  EXPECT_FALSE(UnprojectPixel(camera, {0, 0}, &bearing));
  EXPECT_FALSE(UnprojectPixel(camera, {800, camera.cy}, &bearing));
  cv::Point2d pixel;
  ASSERT_TRUE(ProjectDirection(camera, {1.6, 0, 1}, &pixel));  // beyond the fold
  ASSERT_TRUE(UnprojectPixel(camera, pixel, &bearing));
  EXPECT_LT(bearing[0] / bearing[2], 1.4);
  cv::Point2d back;
  ASSERT_TRUE(ProjectDirection(camera, bearing, &back));
  EXPECT_LT(cv::norm(back - pixel), 1e-6);
}

TEST(EquidistantTest, ProjectMatchesOpenCvFisheye) {
  const CameraIntrinsics camera = TumViEquidistant();
  // cv::fisheye projects points in front of the camera only.
  const double error = MaxProjectionError(
      camera, DirectionGrid(89 * kDegree),
      [&](const std::vector<cv::Point3d>& points, std::vector<cv::Point2d>* out) {
        cv::fisheye::projectPoints(points, *out, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), camera.K(),
                                   camera.distortion);
      });
  EXPECT_LT(error, 1e-6);
}

TEST(EquidistantTest, UnprojectMatchesOpenCvFisheyeAndRoundTrips) {
  const CameraIntrinsics camera = TumViEquidistant();
  const std::vector<cv::Point2d> pixels = PixelGrid(512, 512, 8);
  std::vector<cv::Point2d> undistorted;
  cv::fisheye::undistortPoints(
      pixels, undistorted, camera.K(), camera.distortion, cv::noArray(), cv::noArray(),
      cv::TermCriteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 200, 1e-12));
  double max_error = 0;
  int compared = 0;
  for (size_t i = 0; i < pixels.size(); ++i) {
    cv::Vec3d bearing;
    ASSERT_TRUE(UnprojectPixel(camera, pixels[i], &bearing)) << pixels[i];
    if (bearing[2] < std::cos(80 * kDegree)) continue;  // OpenCV's result is x/z
    const cv::Point2d expected = PinholePixel(camera, {undistorted[i].x, undistorted[i].y, 1});
    max_error = std::max(max_error, cv::norm(PinholePixel(camera, bearing) - expected));
    ++compared;
  }
  EXPECT_GT(compared, int(pixels.size()) / 2);
  EXPECT_LT(max_error, 0.01);
  // The image's corners are more than 90° off the axis.
  cv::Vec3d corner;
  ASSERT_TRUE(UnprojectPixel(camera, {0, 0}, &corner));
  EXPECT_LT(corner[2], 0);
  ExpectRoundTrips(camera, pixels);
}

TEST(EquidistantTest, TheAxisMapsToThePrincipalPoint) {
  const CameraIntrinsics camera = TumViEquidistant();
  cv::Point2d pixel;
  ASSERT_TRUE(ProjectDirection(camera, {0, 0, 3}, &pixel));
  EXPECT_EQ(pixel, cv::Point2d(camera.cx, camera.cy));
  ASSERT_TRUE(ProjectDirection(camera, {1e-14, -2e-14, 1}, &pixel));
  EXPECT_NEAR(pixel.x, camera.cx + camera.fx * 1e-14, 1e-12);
  EXPECT_NEAR(pixel.y, camera.cy - camera.fy * 2e-14, 1e-12);
  cv::Vec3d bearing;
  ASSERT_TRUE(UnprojectPixel(camera, {camera.cx, camera.cy}, &bearing));
  EXPECT_EQ(bearing, cv::Vec3d(0, 0, 1));
  ASSERT_TRUE(UnprojectPixel(camera, {camera.cx + 1e-9, camera.cy}, &bearing));
  EXPECT_NEAR(bearing[0], 1e-9 / camera.fx, 1e-14);
  // Straight behind: θ = π, beyond any lens.
  EXPECT_FALSE(ProjectDirection(camera, {0, 0, -1}, &pixel));
}

// With k1 = -0.1, θd = θ - 0.1 θ³ grows until θ = 1/√0.3 (104.6°), where it reaches 1.2172.
TEST(EquidistantTest, TheModelStopsWhereTheLensFolds) {
  const CameraIntrinsics camera{200, 200, 300, 300, {-0.1, 0, 0, 0}, LensModel::kEquidistant};
  const double fold = 1 / std::sqrt(0.3);
  cv::Point2d pixel;
  EXPECT_TRUE(ProjectDirection(camera, Direction(fold - 0.01, 1.0), &pixel));
  EXPECT_FALSE(ProjectDirection(camera, Direction(fold + 0.01, 1.0), &pixel));
  EXPECT_FALSE(ProjectDirection(camera, Direction(170 * kDegree, 1.0), &pixel));
  const double max_radius = fold * (1 - 0.1 * fold * fold);
  cv::Vec3d bearing;
  EXPECT_FALSE(UnprojectPixel(camera, {300 + 200 * (max_radius + 1e-4), 300}, &bearing));
  ASSERT_TRUE(UnprojectPixel(camera, {300, 300 + 200 * (max_radius - 1e-4)}, &bearing));
  EXPECT_NEAR(std::acos(bearing[2]), fold, 0.02);
  EXPECT_GT(bearing[1], 0);
  std::vector<cv::Point2d> inside;  // the image circle's radius is 243 px
  for (const cv::Point2d& p : PixelGrid(600, 600, 10)) {
    if (std::hypot(p.x - 300, p.y - 300) < 240) inside.push_back(p);
  }
  ExpectRoundTrips(camera, inside);
}

TEST(DoubleSphereTest, SpecialCasesAreKnownProjections) {
  const double theta = 50 * kDegree;
  cv::Point2d pixel;
  // xi = 0, alpha = 0: a pinhole, r = tan θ.
  ASSERT_TRUE(ProjectDirection({100, 100, 0, 0, {0, 0}, LensModel::kDoubleSphere},
                               Direction(theta, 0), &pixel));
  EXPECT_NEAR(pixel.x, 100 * std::tan(theta), 1e-9);
  // xi = 1, alpha = 0: the stereographic projection, r = tan(θ/2).
  ASSERT_TRUE(ProjectDirection({100, 100, 0, 0, {1, 0}, LensModel::kDoubleSphere},
                               Direction(theta, CV_PI / 2), &pixel));
  EXPECT_NEAR(pixel.y, 100 * std::tan(theta / 2), 1e-9);
  // xi = 0, alpha = 0.5: r = 2 tan(θ/2).
  ASSERT_TRUE(ProjectDirection({100, 100, 0, 0, {0, 0.5}, LensModel::kDoubleSphere},
                               Direction(theta, CV_PI), &pixel));
  EXPECT_NEAR(pixel.x, -200 * std::tan(theta / 2), 1e-9);
  EXPECT_NEAR(pixel.y, 0, 1e-9);
}

TEST(DoubleSphereTest, RoundTripsAcrossTheImageAndBehindTheCameraPlane) {
  const CameraIntrinsics camera = KalibrDoubleSphere();
  ExpectRoundTrips(camera, PixelGrid(512, 512, 8));
  for (const cv::Vec3d& direction : DirectionGrid(120 * kDegree)) {
    cv::Point2d pixel;
    cv::Vec3d bearing;
    ASSERT_TRUE(ProjectDirection(camera, direction, &pixel)) << direction;
    ASSERT_TRUE(UnprojectPixel(camera, pixel, &bearing)) << pixel;
    EXPECT_LT(cv::norm(bearing - direction), 1e-9) << direction;
  }
  // 100° off the axis (behind the camera's plane), at any distance.
  const cv::Vec3d behind = Direction(100 * kDegree, 0.7);
  cv::Point2d pixel;
  ASSERT_TRUE(ProjectDirection(camera, 4.0 * behind, &pixel));
  cv::Vec3d bearing;
  ASSERT_TRUE(UnprojectPixel(camera, pixel, &bearing));
  EXPECT_LT(bearing[2], 0);
  EXPECT_LT(cv::norm(bearing - behind), 1e-9);
}

// With these parameters the valid region ends 126.4° off the axis and the image circle at
// r² = 1 / (2 alpha - 1) on the normalised plane.
TEST(DoubleSphereTest, BeyondTheValidRegionIsRefused) {
  const CameraIntrinsics camera = KalibrDoubleSphere();
  cv::Point2d pixel;
  EXPECT_TRUE(ProjectDirection(camera, Direction(125 * kDegree, 2.0), &pixel));
  EXPECT_FALSE(ProjectDirection(camera, Direction(128 * kDegree, 2.0), &pixel));
  EXPECT_FALSE(ProjectDirection(camera, Direction(140 * kDegree, 2.0), &pixel));
  EXPECT_FALSE(ProjectDirection(camera, {0, 0, -1}, &pixel));
  const double rim = 1 / std::sqrt(2 * 0.5755 - 1);
  cv::Vec3d bearing;
  EXPECT_FALSE(UnprojectPixel(camera, {camera.cx + camera.fx * rim * 1.01, camera.cy}, &bearing));
  EXPECT_FALSE(UnprojectPixel(camera, {camera.cx, camera.cy - camera.fy * rim * 1.5}, &bearing));
  EXPECT_TRUE(UnprojectPixel(camera, {camera.cx, camera.cy - camera.fy * rim * 0.99}, &bearing));
}

TEST(ToPinholeTest, BearingsNearTheAxisLandWhereKPutsThem) {
  for (const CameraIntrinsics& camera : {TumViEquidistant(), KalibrDoubleSphere(), EurocRadtan()}) {
    std::vector<cv::Vec3d> directions;
    std::vector<cv::Point2f> pixels;
    std::vector<cv::KeyPoint> keypoints;
    for (const cv::Vec3d& direction : DirectionGrid(30 * kDegree)) {
      cv::Point2d pixel;
      ASSERT_TRUE(ProjectDirection(camera, direction, &pixel));
      directions.push_back(direction);
      pixels.emplace_back(pixel);
      keypoints.emplace_back(cv::Point2f(pixel), 7.0f, 45.0f, 1.0f, 2);
    }
    ToPinhole(camera, pixels);
    ToPinhole(camera, keypoints);
    for (size_t i = 0; i < directions.size(); ++i) {
      const cv::Point2d expected = PinholePixel(camera, directions[i]);
      EXPECT_LT(cv::norm(cv::Point2d(pixels[i]) - expected), 2e-3) << camera.Describe();
      EXPECT_EQ(keypoints[i].pt, pixels[i]);
      EXPECT_EQ(keypoints[i].size, 7.0f);
      EXPECT_EQ(keypoints[i].octave, 2);
    }
  }
}

TEST(ToPinholeTest, RimBearingsGoToTheMaximumAngleInTheirDirection) {
  const double max_tangent = std::tan(kMaxPinholeAngleDeg * kDegree);
  for (const CameraIntrinsics& camera : {TumViEquidistant(), KalibrDoubleSphere()}) {
    for (double theta : {85.0, 100.0, 115.0}) {
      const double phi = 2.5;
      cv::Point2d pixel;
      ASSERT_TRUE(ProjectDirection(camera, Direction(theta * kDegree, phi), &pixel));
      std::vector<cv::Point2f> pixels = {cv::Point2f(pixel)};
      ToPinhole(camera, pixels);
      const cv::Point2d expected(camera.cx + camera.fx * max_tangent * std::cos(phi),
                                 camera.cy + camera.fy * max_tangent * std::sin(phi));
      EXPECT_LT(cv::norm(cv::Point2d(pixels[0]) - expected), 2e-3) << theta;
    }
  }
}

TEST(ToPinholeTest, PinholeCamerasAndPixelsWithoutBearingStayPut) {
  const std::vector<cv::Point2f> original = {{-50, 20}, {0, 0}, {320.5f, 240.25f}, {900, 700}};
  for (const CameraIntrinsics& camera : {CameraIntrinsics{500, 500, 320, 240, {}},
                                         CameraIntrinsics{500, 500, 320, 240, {0, 0, 0, 0, 0}}}) {
    std::vector<cv::Point2f> pixels = original;
    ToPinhole(camera, pixels);
    EXPECT_EQ(pixels, original);
  }
  // A distorting lens moves them, except those outside its image circle.
  const CameraIntrinsics camera = KalibrDoubleSphere();
  const double rim = 1 / std::sqrt(2 * 0.5755 - 1);
  const cv::Point2f outside(float(camera.cx + 1.2 * rim * camera.fx), float(camera.cy));
  std::vector<cv::Point2f> pixels = {outside, {100, 100}};
  ToPinhole(camera, pixels);
  EXPECT_EQ(pixels[0], outside);
  EXPECT_GT(cv::norm(pixels[1] - cv::Point2f(100, 100)), 1);
}

TEST(ParseCameraTextTest, ReadsTheDocumentedForms) {
  StatusOr<CameraIntrinsics> camera = ParseCameraText("--camera", "500,501,319.5,239.5");
  ASSERT_TRUE(camera.ok()) << camera.status().message();
  EXPECT_EQ(*camera, (CameraIntrinsics{500, 501, 319.5, 239.5, {}}));

  camera = ParseCameraText("--camera",
                           "458.654, 457.296, 367.215, 248.375, -0.28340811,"
                           "0.07395907,0.00019359 , 1.76187114e-05");
  ASSERT_TRUE(camera.ok()) << camera.status().message();
  EXPECT_EQ(*camera, EurocRadtan());

  camera = ParseCameraText("--camera",
                           "equidistant:190.9,190.9,254.9,256.9,0.0034,0.0007,-0.0029,0.0003");
  ASSERT_TRUE(camera.ok()) << camera.status().message();
  EXPECT_EQ(
      *camera,
      (CameraIntrinsics{
          190.9, 190.9, 254.9, 256.9, {0.0034, 0.0007, -0.0029, 0.0003}, LensModel::kEquidistant}));

  camera = ParseCameraText("--camera", "ds:156.1,155.7,254.6,256.4,-0.24,0.57");
  ASSERT_TRUE(camera.ok()) << camera.status().message();
  EXPECT_EQ(*camera, (CameraIntrinsics{
                         156.1, 155.7, 254.6, 256.4, {-0.24, 0.57}, LensModel::kDoubleSphere}));

  camera = ParseCameraText("--camera", " plumb_bob : 500,500,320,240,0.1,-0.2,0,0,0.01");
  ASSERT_TRUE(camera.ok()) << camera.status().message();
  EXPECT_EQ(*camera, (CameraIntrinsics{500, 500, 320, 240, {0.1, -0.2, 0, 0, 0.01}}));

  camera = ParseCameraText("--camera", "fisheye:500,500,320,240");  // a pinhole, named fisheye
  ASSERT_TRUE(camera.ok()) << camera.status().message();
  EXPECT_TRUE(camera->distortion.empty());
  EXPECT_EQ(camera->lens, LensModel::kEquidistant);
}

TEST(ParseCameraTextTest, NamesWhatIsWrong) {
  struct Case {
    std::string text;
    std::vector<std::string> parts;  // of the message
  };
  const std::vector<Case> cases = {
      {"500,500,320,abc", {"--cam: ", "'abc' is not a number"}},
      {"500,500,320,240,0.1,0.2,0,0x1", {"--cam: ", "'0x1' is not a number"}},
      {"500,500,,240", {"--cam: ", "a number is missing"}},
      {"500,500,320,240,", {"--cam: ", "a number is missing"}},
      {"", {"--cam: ", "a number is missing"}},
      {"500,500,320", {"--cam: ", "takes fx,fy,cx,cy[,k1,k2,p1,p2[,k3", "got 3 numbers"}},
      {"500,500,320,240,0.1", {"--cam: ", "got 5 numbers"}},
      {"equi:500,500,320,240,0.1,0.2",
       {"--cam: equidistant takes fx,fy,cx,cy[,k1,k2,k3,k4], got 6 numbers"}},
      {"ds:500,500,320,240,0.1", {"--cam: double_sphere takes fx,fy,cx,cy[,xi,alpha], got 5"}},
      {"mei:500,500,320,240,0.1", {"--cam: unknown lens model 'mei'", "double_sphere"}},
      {"500,0,320,240", {"--cam: camera intrinsics need finite fx, fy > 0 and finite cx, cy"}},
      {"500,500,320,240,nan,0,0,0", {"--cam: camera distortion is not finite"}},
      {"ds:500,500,320,240,0.1,1.5", {"--cam: double_sphere camera needs alpha in [0, 1]"}},
  };
  for (const Case& test : cases) {
    const StatusOr<CameraIntrinsics> camera = ParseCameraText("--cam", test.text);
    ASSERT_EQ(camera.status().code(), StatusCode::kInvalidArgument) << test.text;
    for (const std::string& part : test.parts) {
      EXPECT_NE(camera.status().message().find(part), std::string::npos)
          << test.text << ": " << camera.status().message();
    }
  }
}

}  // namespace
}  // namespace recog
