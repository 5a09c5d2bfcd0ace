#include "tools/evaluation/loop_tally.h"

#include <algorithm>
#include <numeric>
#include <utility>

namespace recog::cli {

StageStats StatsOf(const std::vector<double>& values) {
  StageStats s;
  if (values.empty()) return s;
  s.mean = std::accumulate(values.begin(), values.end(), 0.0) / double(values.size());
  s.median = Median(values);
  s.max = *std::max_element(values.begin(), values.end());
  return s;
}

std::string_view MissReasonName(MissReason reason) {
  switch (reason) {
    case MissReason::kNotQueried:
      return "not_queried";
    case MissReason::kNoCandidate:
      return "no_candidate";
    case MissReason::kLowScore:
      return "low_score";
    case MissReason::kWrongTopCandidate:
      return "wrong_top_candidate";
    case MissReason::kNotConsistent:
      return "not_consistent";
    case MissReason::kFailedGeometry:
      return "failed_geometry";
    case MissReason::kWrongLoop:
      return "wrong_loop";
  }
  return "unknown";
}

void LoopTally::CountStatus(std::string_view status) {
  ++figures_->statuses[std::string(status)];
  figures_->frame_statuses.emplace_back(status);
}

bool LoopTally::CountDetection(bool correct, bool ambiguous) {
  ++figures_->detections;
  if (ambiguous) {
    ++figures_->ambiguous;
    return false;
  }
  if (correct) ++figures_->correct;
  return correct;
}

void LoopTally::CountMiss(MissedRevisit miss) {
  ++figures_->miss_reasons[std::string(MissReasonName(miss.reason))];
  figures_->misses.push_back(std::move(miss));
}

void LoopTally::AddTime(const std::string& stage, double ms) { times_[stage].push_back(ms); }

void LoopTally::Finish() {
  LoopFigures& f = *figures_;
  for (const auto& [stage, values] : times_) f.timing_ms[stage] = StatsOf(values);
  const int judged = f.detections - f.ambiguous;
  f.precision = judged > 0 ? double(f.correct) / judged : 1.0;
  f.recall = f.query_frames_with_truth > 0 ? double(f.correct) / f.query_frames_with_truth : 0.0;
}

Status CheckTruthCovers(const GroundTruth& truth, size_t frames, std::string_view sequence) {
  if (truth.frames != int(frames)) {
    return Status::InvalidArgument("the ground truth covers " + std::to_string(truth.frames) +
                                   " frames but the " + std::string(sequence) + " has " +
                                   std::to_string(frames));
  }
  return Status::Ok();
}

}  // namespace recog::cli
