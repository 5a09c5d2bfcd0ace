// LoopTally: what an evaluation of a loop detector counts over a sequence with ground truth —
// frames per detector status, the detected loops and how many of them are correct (or of pairs
// listed as ambiguous), precision and recall, and why each missed revisit was missed — with the
// time each stage of the detector took per frame. The single-camera evaluation (place_evaluation.h)
// and the rig one (rig_evaluation.h) both count with it, so they report the same figures worked out
// the same way.
#pragma once

#include <cstdint>
#include <map>
#include <optional>
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

// Why a revisit was missed: a frame the ground truth matches to an earlier frame of the map that
// got no loop the tally counts correct. One reason a frame, the stage of the detector where the
// true place was lost, from the frame's result (what each reason is made of: ExplainMiss in
// place_evaluation.h, and the rig's in tools/recog/eval_place_command.cc).
enum class MissReason {
  kNotQueried,         // not queried: too few features, or too low a score with the previous frame
  kNoCandidate,        // queried, but no true place among what the query returned (or nothing)
  kLowScore,           // a true place among the candidates, but none kept: all under alpha (or in
                       // no island of the minimum size)
  kWrongTopCandidate,  // the best candidate (the best island's best entry) is not a true place
  kNotConsistent,      // the best candidate is a true place, refused by temporal consistency (or
                       // verified but not yet confirmed by the next keyframes)
  kFailedGeometry,     // the best candidate is a true place and failed the geometric verification
  kWrongLoop,          // a loop was detected but not counted correct: another place (a false
                       // positive), a pair listed as ambiguous, or inliers off the true geometry
};
// Every reason, in the order of the detector's stages.
inline constexpr MissReason kMissReasons[] = {
    MissReason::kNotQueried,        MissReason::kNoCandidate,   MissReason::kLowScore,
    MissReason::kWrongTopCandidate, MissReason::kNotConsistent, MissReason::kFailedGeometry,
    MissReason::kWrongLoop};
std::string_view MissReasonName(MissReason reason);  // "not_queried", "no_candidate", ...

// A missed revisit and what its result says about it. Frames are 0-based indices of the
// sequence; the optional fields are set when the result holds them.
struct MissedRevisit {
  int query = 0;
  MissReason reason = MissReason::kNoCandidate;
  std::string status;  // the detector's status of the frame (LoopStatusName, RigLoopStatusName)
  // The candidate that decided the status: the best island's best entry (the one verified), or
  // the wrong loop's match.
  std::optional<int> candidate;
  // The first true place among the candidates the query returned, and its rank there (1: the best
  // score).
  std::optional<int> true_candidate, true_rank;
  // The verification of `candidate`: its inliers and the putative correspondences RANSAC had.
  std::optional<uint32_t> inliers, correspondences;
  std::optional<uint32_t> consistent_queries;  // kNotConsistent: previous queries it agreed with
  bool failed_metric = false;  // kFailedGeometry: the 2D check passed, the 3D check refused it
};

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
  std::vector<std::string> frame_statuses;      // each frame's status name, in the order counted
  std::vector<MissedRevisit> misses;            // the missed revisits, in the order counted
  std::map<std::string, int> miss_reasons;      // misses per MissReasonName
};

class LoopTally {
 public:
  // Counts into `figures`, which must outlive the tally; the caller sets its frames and
  // query_frames_with_truth.
  explicit LoopTally(LoopFigures* figures) : figures_(figures) {}

  // One frame's status, by name (LoopStatusName, RigLoopStatusName).
  void CountStatus(std::string_view status);
  // A detected loop: correct or not by the ground truth, or of a pair listed as ambiguous, which
  // precision leaves out. True when it counts as correct (for precision and recall).
  bool CountDetection(bool correct, bool ambiguous);
  // A revisit without a loop counted correct, and why.
  void CountMiss(MissedRevisit miss);
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
