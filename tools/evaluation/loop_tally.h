// LoopTally: what an evaluation of a loop detector counts over a sequence with ground truth —
// frames per detector status, the detected loops and how many of them are correct (or of pairs
// listed as ambiguous), precision and recall — with the time each stage of the detector took per
// frame. The single-camera evaluation (place_evaluation.h) and the rig one (rig_evaluation.h) both
// count with it, so they report the same figures worked out the same way.
#pragma once

#include <map>
#include <string>
#include <string_view>
#include <vector>

#include "core/common/median.h"
#include "core/common/status.h"
#include "tools/evaluation/ground_truth.h"

namespace recog::cli {

struct StageStats {
  double mean = 0, median = 0, max = 0;
};
// Mean, median (Median, core/common/median.h) and max of the values (zeros for none).
StageStats StatsOf(const std::vector<double>& values);

// The figures of an evaluation (PlaceEvaluation and RigPlaceEvaluation add their loops).
struct LoopFigures {
  int frames = 0;
  int query_frames_with_truth = 0;  // frames the ground truth matches to an earlier one
  int detections = 0;               // frames whose loop was detected
  int correct = 0;
  int ambiguous = 0;       // detections of ambiguous pairs (in `detections`, not in precision)
  double precision = 1.0;  // correct / (detections - ambiguous); 1 when that is 0
  double recall = 0.0;     // correct / query_frames_with_truth; 0 when that is 0
  std::map<std::string, StageStats> timing_ms;  // per frame, by stage (features, query, ...)
  std::map<std::string, int> statuses;          // frames per status name
};

class LoopTally {
 public:
  // Counts into `figures`, which must outlive the tally; the caller sets its frames and
  // query_frames_with_truth.
  explicit LoopTally(LoopFigures* figures) : figures_(figures) {}

  // One frame's status, by name (LoopStatusName, RigLoopStatusName).
  void CountStatus(std::string_view status);
  // A detected loop: correct or not by the ground truth, or of a pair listed as ambiguous, which
  // precision leaves out.
  void CountDetection(bool correct, bool ambiguous);
  // The time `stage` took on one frame.
  void AddTime(const std::string& stage, double ms);
  // Works out precision, recall and each stage's StageStats from what was counted.
  void Finish();

 private:
  LoopFigures* figures_;
  std::map<std::string, std::vector<double>> times_;  // per stage, one a frame
};

// INVALID_ARGUMENT unless `truth` covers the `frames` frames of the `sequence` (its name in the
// message: "sequence", "rig sequence").
Status CheckTruthCovers(const GroundTruth& truth, size_t frames, std::string_view sequence);

}  // namespace recog::cli
