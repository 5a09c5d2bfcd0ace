// The object's pose in every frame of a real recording (the poses.txt of visp-rbt-cube), and how
// `recog eval sequence --poses` scores recognition against it.
//
// A pose list is a text file: '#' starts a comment, blank lines are skipped, and every other line
// is
//   NNNN r11 r12 r13 r21 r22 r23 r31 r32 r33 tx ty tz
// a frame number (digits) and the pose T_camera<-object (X_camera = R X_object + t, metres). A
// frame of a sequence is matched to its line by the number at the end of its image file's stem:
// color_image_0007.png, image7.png and 000007.png are all frame 7.
//
// Scoring a frame with a pose is ScoreTruthFrame's (object_evaluation.h): found when the expected
// object is among the detections, its first detection's rotation and translation errors, a
// correct pose within the limits of SizeRecallOptions, and the detections of other objects.
#pragma once

#include <map>
#include <optional>
#include <string>
#include <vector>

#include "core/common/status.h"
#include "core/object/model/object_model.h"
#include "core/object/recognition/object_recognizer.h"
#include "tools/evaluation/object_evaluation.h"

namespace recog::cli {

// The number at the end of a file's stem ("dir/color_image_0007.png" -> 7); nullopt when the stem
// does not end in a digit or the number does not fit an int.
std::optional<int> FrameNumber(const std::string& path);

// Frame number -> T_camera<-object. NOT_FOUND when the file is missing; INVALID_ARGUMENT naming
// the file and line for a line that is not a frame number and 12 finite numbers, a rotation that
// is not a rotation matrix (IsRotationMatrix) or a frame given twice; INVALID_ARGUMENT for a file
// without a pose.
StatusOr<std::map<int, RigidTransform>> ReadFramePoses(const std::string& path);

// The object's pose in the frame of `image_path` (e.g. the first frame of a recording): the pose
// of a ViSP .pos file (ReadVispPose) when `pose_path` ends in .pos, else the line of that frame's
// number in a pose list (ReadFramePoses's errors; INVALID_ARGUMENT when the image's name has no
// number, NOT_FOUND when the list has no line for it).
StatusOr<RigidTransform> ReadPoseOfFrame(const std::string& pose_path,
                                         const std::string& image_path);

struct FramePoseScore {
  int frame = 0;          // the image's number
  size_t inliers = 0;     // of the expected object's detection, when found
  TruthFrameScore score;  // image (file name), found, correct_pose, errors, other_objects
};

// The score of the frame of `image_path`; nullopt when `poses` has no pose for it (a frame
// without ground truth).
std::optional<FramePoseScore> ScoreFramePose(const std::map<int, RigidTransform>& poses,
                                             const std::string& image_path,
                                             const std::string& expect,
                                             const std::vector<Detection>& detections,
                                             const SizeRecallOptions& options);

struct PoseErrorSummary {
  size_t frames_with_pose = 0, found = 0, correct_pose = 0;
  size_t wrong_objects = 0;  // detections of other objects in those frames
  double recall = 0;         // found / frames_with_pose (0 without frames)
  double median_rotation_error_deg = 0, median_translation_error_m = 0;  // of the found frames
};

PoseErrorSummary SummarisePoseErrors(const std::vector<FramePoseScore>& frames);

// CSV with the header frame,found,inliers,rotation_error_deg,translation_error_m,wrong_objects
// and a line per frame (found 0/1; the errors empty when not found). PNG: the rotation error
// (degrees) and the translation error (centimetres) against the frame number, at the frames
// where the object was found. INTERNAL when a file cannot be written.
Status WritePoseErrorCsv(const std::vector<FramePoseScore>& frames, const std::string& path);
Status WritePoseErrorPlot(const std::vector<FramePoseScore>& frames, const std::string& title,
                          const std::string& path);

}  // namespace recog::cli
