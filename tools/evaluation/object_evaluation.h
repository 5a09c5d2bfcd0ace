// Leave-one-view-out evaluation of object recognition on RoboEarth model folders (`recog eval
// objects`), and the pieces the object subcommands share (camera strings, model sources, the
// object vocabulary, drawing a detection).
//
// Two ways to put the RoboEarth folders under the root into the database (ObjectEvaluationMethod):
//  - merged (thesis §5.4, the system's own): every folder becomes one model built from all its
//    views (descriptors merged per 3D point and word, eq. 5.3);
//  - independent views (thesis §5.3, the baseline it compares with): every training view becomes
//    its own entry, a model built from that view alone (its ORB features and the 3D points they
//    see), named "<folder>.face_NNN" with the folder as its class.
// Then, for every 3D object with at least `min_views` views and every view v, v is left out of
// its object (merged: the object's model is rebuilt without v and replaces the full one;
// independent views: v's entry is removed), and face_v.png is recognised with v's camera, as is
// and through each image transform (half size, rotated 90 and 180 degrees, with the camera and the
// ground-truth pose transformed alike); then v is put back. The held-out camera is the
// ground-truth pose. A query counts as detected when an entry of the held-out object is among the
// detections; every other object (folder) detected is a wrong detection.
#pragma once

#include <functional>
#include <map>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include <opencv2/core.hpp>

#include "core/common/status.h"
#include "core/object/builder/model_builder.h"
#include "core/object/recognition/object_recognizer.h"
#include "tools/evaluation/object_sequence_generator.h"

namespace recog::cli {

enum class ImageTransform { kNone, kHalfScale, kRotate90, kRotate180 };
std::string_view ImageTransformName(ImageTransform transform);  // "none", "scale0.5", ...
StatusOr<ImageTransform> ParseImageTransform(std::string_view name);

// Applies `transform` to an image, its camera and the pose of an object in that camera.
void TransformView(ImageTransform transform, cv::Mat* image, CameraIntrinsics* camera,
                   RigidTransform* camera_from_object);

// Whether R is a rotation matrix: R^T R = I within 1e-3 (norm of the difference) and det R > 0,
// as a matrix written to a text file with a few decimals still is.
bool IsRotationMatrix(const cv::Matx33d& R);

enum class ObjectEvaluationMethod { kMerged, kIndependentViews };
std::string_view ObjectEvaluationMethodName(ObjectEvaluationMethod method);  // "merged", ...
StatusOr<ObjectEvaluationMethod> ParseObjectEvaluationMethod(std::string_view name);

struct ObjectEvaluationOptions {
  std::string roboearth_dir;  // a folder of RoboEarth model folders
  ObjectEvaluationMethod method = ObjectEvaluationMethod::kMerged;
  std::string vocabulary_path;
  ModelBuildOptions build;
  RecognitionOptions recognition;
  std::vector<ImageTransform> transforms = {ImageTransform::kNone, ImageTransform::kHalfScale,
                                            ImageTransform::kRotate90, ImageTransform::kRotate180};
  int min_views = 5;
  std::string draw_dir;  // a PNG per query when not empty
  // Called after each query with (done, total).
  std::function<void(size_t, size_t)> progress;
};

struct ObjectQuery {
  std::string object;
  int view = 0;
  ImageTransform transform = ImageTransform::kNone;
  bool detected = false;
  std::string matched;             // when detected: the entry that found it (object or view)
  std::vector<std::string> wrong;  // other objects reported (folder names, each once)
  double rotation_error_deg = 0;   // when detected
  double translation_error_ratio = 0;
  size_t inliers = 0;
  RecognitionTiming timing;
};

struct ObjectEvaluationSummary {
  ImageTransform transform = ImageTransform::kNone;
  size_t queries = 0, detections = 0, wrong_detections = 0;
  double detection_rate = 0;
  double median_rotation_error_deg = 0;
  double median_translation_error_ratio = 0;
  RecognitionTiming median_timing;  // per stage
};

struct ObjectEvaluation {
  ObjectEvaluationMethod method = ObjectEvaluationMethod::kMerged;
  std::vector<std::string> database;           // entry names
  std::map<std::string, std::string> objects;  // entry name -> its object (folder name)
  // Independent views: the views that gave no entry (no feature with a 3D point), by entry name,
  // with the builder's message.
  std::vector<std::pair<std::string, std::string>> skipped_views;
  std::vector<ObjectQuery> queries;
  std::vector<ObjectEvaluationSummary> summaries;  // one per transform
};

StatusOr<ObjectEvaluation> EvaluateObjects(const ObjectEvaluationOptions& options);

// The vocabulary at `path`, or the bundled object vocabulary when `path` is empty.
StatusOr<std::shared_ptr<const Vocabulary>> LoadObjectVocabulary(const std::string& path);

// One object model named on the command line.
struct ModelSource {
  std::string path;
  bool roboearth = false;  // a RoboEarth model folder (with meta.xml); else a model file (.robj)
};

// The models `path` names: a RoboEarth model folder, a model file (any name), or a folder of
// those (one level: its RoboEarth folders and .robj files, by name; other entries are skipped).
// An empty list when the folder holds none.
std::vector<ModelSource> FindModelSources(const std::string& path);

// Draws a detection over an image: outline, model axes, inlier points; writes nothing.
void DrawDetection(const Detection& detection, const CameraIntrinsics& camera,
                   const cv::Scalar& colour, cv::Mat* canvas);

// ---- Recall against object size (recog eval sequence --truth) ----
//
// Given the ground truth of an object sequence (ObjectSequenceTruth), each frame is scored: was
// the expected object found, and with the right pose (rotation and translation errors within the
// limits)? Frames where the object is visible (at least half in view) are binned by the fraction
// of the frame it covers; recall per bin = frames with the right pose / frames in the bin.

struct SizeRecallOptions {
  // Upper edges of the size bins (fractions of the frame, increasing); the first bin starts at 0,
  // a last bin takes everything from the last edge up.
  std::vector<double> bin_edges = {0.005, 0.01, 0.02, 0.04, 0.08, 0.16};
  double max_rotation_error_deg = 10;
  double max_translation_error = 0.1;  // fraction of the true distance
};

struct TruthFrameScore {
  std::string image;
  bool visible = false;
  double area_fraction = 0;
  bool found = false;         // the expected object is among the detections
  bool correct_pose = false;  // and its pose is within the limits
  double rotation_error_deg = 0, translation_error_m = 0;  // when found
  size_t other_objects = 0;                                // detections of other objects
};

// The truth of the frame whose file name is that of `image_path`; NOT_FOUND when there is none.
StatusOr<ObjectTruthFrame> FindTruthFrame(const ObjectSequenceTruth& truth,
                                          const std::string& image_path);

TruthFrameScore ScoreTruthFrame(const ObjectTruthFrame& truth, const std::string& expect,
                                const std::vector<Detection>& detections,
                                const SizeRecallOptions& options);

struct SizeBin {
  double lo = 0, hi = 0;  // area fraction range [lo, hi); hi = 1 for the last bin
  size_t frames = 0, found = 0, correct = 0;
  double recall = 0;       // correct / frames (0 without frames)
  double found_rate = 0;   // found / frames
  double median_area = 0;  // of the bin's frames
  double median_rotation_error_deg = 0, median_translation_error_m = 0;  // found frames
};

struct SizeRecall {
  std::vector<SizeBin> bins;
  size_t visible_frames = 0, found = 0, correct = 0;
  double recall = 0;             // correct / visible frames
  size_t found_not_visible = 0;  // frames with less than half in view where it was reported
  size_t other_objects = 0;      // detections of other objects, all frames
};

SizeRecall SummariseSizeRecall(const std::vector<TruthFrameScore>& frames,
                               const SizeRecallOptions& options);

// CSV with the header
//   area_lo,area_hi,median_area,frames,found,correct,recall,found_rate,median_rotation_deg,
//   median_translation_m
// one line per bin. PNG: recall and found rate against the area in % of the frame (log scale).
// INTERNAL when a file cannot be written.
Status WriteSizeRecallCsv(const SizeRecall& recall, const std::string& path);
Status WriteSizeRecallPlot(const SizeRecall& recall, const std::string& title,
                           const std::string& path);

}  // namespace recog::cli
