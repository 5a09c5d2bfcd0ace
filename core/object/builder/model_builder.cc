#include "core/object/builder/model_builder.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/object/builder/builder_internal.h"

namespace recog {
namespace builder_internal {

std::vector<uint8_t> EncodePng(const cv::Mat& image) {
  std::vector<uint8_t> png;
  cv::imencode(".png", image, png);
  return png;
}

cv::Vec3d PixelRay(const CameraIntrinsics& camera, const cv::Point2f& pixel) {
  cv::Point2f pinhole = pixel;
  ToPinhole(camera, std::span<cv::Point2f>(&pinhole, 1));
  return {(pinhole.x - camera.cx) / camera.fx, (pinhole.y - camera.cy) / camera.fy, 1.0};
}

bool FillProjectedHull(const std::vector<cv::Point3d>& corners, const CameraIntrinsics& camera,
                       const RigidTransform& camera_from_object, cv::Mat* region) {
  std::vector<cv::Point> pixels;
  for (const cv::Point3d& x : corners) {
    cv::Point2d uv;
    if (!ProjectPoint(camera, camera_from_object, x, &uv)) return false;
    // Far outside the image: clamp so that the integer polygon stays well-defined.
    pixels.emplace_back(int(std::lround(std::clamp(uv.x, -1e5, 1e5))),
                        int(std::lround(std::clamp(uv.y, -1e5, 1e5))));
  }
  std::vector<cv::Point> hull;
  cv::convexHull(pixels, hull);
  cv::fillConvexPoly(*region, hull, cv::Scalar(255));
  return true;
}

}  // namespace builder_internal

ModelBuilder::ModelBuilder(std::shared_ptr<const Vocabulary> vocabulary, ModelBuildOptions options)
    : vocabulary_(std::move(vocabulary)), options_(std::move(options)) {}

Status ModelBuilder::Extract(const cv::Mat& image, FeatureSet* features) {
  if (!extractor_) {
    FeatureOptions feature_options;
    feature_options.orb = options_.orb;
    RECOG_ASSIGN_OR_RETURN(extractor_, CreateFeatureExtractor(feature_options));
  }
  return extractor_->Extract(image, features);
}

Status ModelBuilder::ExtractInRegion(const cv::Mat& image, const cv::Mat& region,
                                     FeatureSet* features) {
  features->keypoints.clear();
  features->descriptors = cv::Mat();
  const cv::Rect box = cv::boundingRect(region);
  if (box.empty()) return Status::Ok();
  // ORB keeps edge_threshold pixels of every pyramid level free: the crop keeps that much
  // context around the region at the coarsest level of the view's own pyramid.
  const double context = options_.orb.edge_threshold *
                         std::pow(double(options_.orb.scale_factor), options_.orb.levels - 1);
  const int margin =
      int(std::ceil(std::max(context, options_.crop_margin * std::max(box.width, box.height))));
  const cv::Rect crop =
      cv::Rect(box.x - margin, box.y - margin, box.width + 2 * margin, box.height + 2 * margin) &
      cv::Rect(0, 0, image.cols, image.rows);
  const double scale = std::clamp(double(options_.working_size) / std::max(crop.width, crop.height),
                                  1.0, std::max(1.0, options_.max_enlarge));
  cv::Mat patch = image(crop);
  if (scale > 1.0) cv::resize(patch, patch, cv::Size(), scale, scale, cv::INTER_CUBIC);
  // The pyramid gets the levels the enlargement added, so that it still reaches down as far as
  // it does on the view itself (recognition sees the object at the view's scale).
  const int levels =
      options_.orb.levels +
      int(std::ceil(std::log(scale) / std::log(double(options_.orb.scale_factor)) - 1e-9));
  // The grid's cells outside the region leave their share unused: the budget grows with the
  // crop's area over the region's (at most 8 times), so that the region gets about max_features.
  const int budget = int(std::lround(
      options_.orb.max_features *
      std::min(8.0, double(crop.area()) / std::max(1, cv::countNonZero(region(crop))))));
  if (!region_extractor_ || region_levels_ != levels || region_budget_ != budget) {
    FeatureOptions feature_options;
    feature_options.orb = options_.orb;
    feature_options.orb.levels = levels;
    feature_options.orb.max_features = budget;
    feature_options.orb.grid_rows = feature_options.orb.grid_cols = options_.region_grid;
    RECOG_ASSIGN_OR_RETURN(region_extractor_, CreateFeatureExtractor(feature_options));
    region_levels_ = levels;
    region_budget_ = budget;
  }
  FeatureSet found;
  RECOG_RETURN_IF_ERROR(region_extractor_->Extract(patch, &found));
  std::vector<int> rows;
  for (size_t i = 0; i < found.size(); ++i) {
    cv::KeyPoint keypoint = found.keypoints[i];
    // resize maps pixel centres: crop pixel x = (patch pixel x + 0.5) / scale - 0.5.
    keypoint.pt = {float((keypoint.pt.x + 0.5) / scale - 0.5 + crop.x),
                   float((keypoint.pt.y + 0.5) / scale - 0.5 + crop.y)};
    keypoint.size = float(keypoint.size / scale);
    const int u = std::clamp(int(std::lround(keypoint.pt.x)), 0, image.cols - 1);
    const int v = std::clamp(int(std::lround(keypoint.pt.y)), 0, image.rows - 1);
    if (region.at<uint8_t>(v, u) == 0) continue;
    features->keypoints.push_back(keypoint);
    rows.push_back(int(i));
  }
  features->descriptors =
      cv::Mat(int(rows.size()), found.descriptors.cols, found.descriptors.type());
  for (size_t k = 0; k < rows.size(); ++k)
    found.descriptors.row(rows[k]).copyTo(features->descriptors.row(int(k)));
  return Status::Ok();
}

}  // namespace recog
