// Per-keypoint 3D points of a frame (thesis §3.3.3: metric loops need the structure of the frame):
// from an aligned depth image or from a rectified stereo pair.
//
// The points are in the frame's camera frame (x right, y down, z forward), in metres, one per
// keypoint in keypoint order; a keypoint without a depth gets NaN in x, y and z. The keypoints are
// pinhole pixels (lens distortion removed, or rectified for stereo) of the camera with matrix K.
//
//  - PointsFromDepth: the depth image is aligned with the image (same size, same pixels; see
//    RegisterDepth in depth_registration.h for a sensor whose depth camera is separate). The
//    depth of a keypoint is the one at its pixel; where that pixel has none (0, NaN), the nearest
//    depth among its 8 neighbours (the foreground: a keypoint on an edge belongs to the object in
//    front). X = (u - cx) Z / fx, Y = (v - cy) Z / fy.
//  - PointsFromStereo: the left image is the frame; the right image is the same camera moved by
//    the baseline B along +x, both rectified (epipolar lines are rows). The ORB features of the
//    right image, from the same extractor as the left ones, are matched to the left keypoints
//    along their row: same row within max_row_offset_px times the left keypoint's pyramid scale
//    (its size over ORB's 31-pixel patch), pyramid octaves at most one apart, disparity
//    d = u_left - u_right in (0, max_disparity_px], Hamming distance and ratio test of `matching`,
//    one-to-one (a right feature claimed twice goes to the closer descriptor). The disparity is
//    then refined to a sub-pixel value by block matching (sum of absolute differences of a window
//    around the left keypoint, ±2 px around the ORB disparity, parabola through the best three);
//    Z = fx B / d.
// Errors are INVALID_ARGUMENT for input that cannot be right: a depth image of another size than
// the image or of a type other than CV_16U / CV_32F, a non-positive depth scale, a missing or
// non-positive baseline, a right image of another size or type than the left one, non-ORB
// descriptors, a K without positive focal lengths.
#pragma once

#include <vector>

#include <opencv2/core.hpp>

#include "core/common/feature_set.h"
#include "core/common/status.h"
#include "core/geometry/camera_model.h"
#include "core/geometry/correspondences.h"

namespace recog {

// `depth`: CV_16U in units of `depth_scale` metres (0.001: millimetres, the usual RGB-D format)
// or CV_32F in metres (`depth_scale` is then ignored); 0 or NaN = no depth. `image_size`: the size
// of the image the keypoints come from.
Status PointsFromDepth(const std::vector<cv::KeyPoint>& keypoints, cv::Size image_size,
                       const cv::Matx33d& K, const cv::Mat& depth, double depth_scale,
                       std::vector<cv::Point3f>* points);
// The same for the keypoints of a camera with a lens (as detected, distortion in them; the depth
// image aligned with that image): a keypoint's point lies along its bearing (UnprojectPixel) at
// the depth's z. Move the keypoints into the pinhole image of K (ToPinhole) after, not before.
Status PointsFromDepth(const std::vector<cv::KeyPoint>& keypoints, cv::Size image_size,
                       const CameraIntrinsics& camera, const cv::Mat& depth, double depth_scale,
                       std::vector<cv::Point3f>* points);

struct StereoOptions {
  double max_row_offset_px = 1.0;  // |v_left - v_right|, times the left keypoint's pyramid scale
  double max_disparity_px = 0;     // 0 = a quarter of the image width
  MatchOptions matching{.ratio = 0.8, .max_distance = 50};
  int window = 11;  // side of the block-matching window of the sub-pixel refinement (odd, >= 3)
};

// `left` are the ORB features of `left_image`, `right` those of `right_image` (the rectified right
// image: same size and type as the left, 8-bit grey or BGR), both from one extractor;
// `baseline_m` > 0.
Status PointsFromStereo(const FeatureSet& left, const cv::Mat& left_image, const FeatureSet& right,
                        const cv::Mat& right_image, const cv::Matx33d& K, double baseline_m,
                        const StereoOptions& options, std::vector<cv::Point3f>* points);

}  // namespace recog
