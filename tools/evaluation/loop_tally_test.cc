#include "tools/evaluation/loop_tally.h"

#include <gtest/gtest.h>

namespace recog::cli {
namespace {

TEST(LoopTallyTest, PrecisionLeavesAmbiguousPairsOutAndRecallCountsTheRevisits) {
  LoopFigures figures;
  figures.frames = 10;
  figures.query_frames_with_truth = 4;
  LoopTally tally(&figures);
  for (const char* status :
       {"loop_detected", "loop_detected", "loop_detected", "loop_detected", "low_score"}) {
    tally.CountStatus(status);
  }
  tally.CountDetection(/*correct=*/true, /*ambiguous=*/false);
  tally.CountDetection(true, false);
  tally.CountDetection(false, false);
  tally.CountDetection(false, /*ambiguous=*/true);
  tally.Finish();
  EXPECT_EQ(figures.detections, 4);
  EXPECT_EQ(figures.correct, 2);
  EXPECT_EQ(figures.ambiguous, 1);
  EXPECT_DOUBLE_EQ(figures.precision, 2.0 / 3.0);
  EXPECT_DOUBLE_EQ(figures.recall, 0.5);
  EXPECT_EQ(figures.statuses, (std::map<std::string, int>{{"loop_detected", 4}, {"low_score", 1}}));
}

TEST(LoopTallyTest, NothingDetectedIsFullPrecisionAndNoRevisitIsZeroRecall) {
  LoopFigures figures;
  figures.frames = 3;
  LoopTally tally(&figures);
  tally.CountDetection(false, true);  // only an ambiguous pair: nothing judged
  tally.Finish();
  EXPECT_EQ(figures.precision, 1.0);
  EXPECT_EQ(figures.recall, 0.0);
}

TEST(LoopTallyTest, EachStageGetsTheMeanMedianAndMaxOfItsFrames) {
  LoopFigures figures;
  LoopTally tally(&figures);
  for (const double ms : {4.0, 1.0, 3.0, 2.0}) tally.AddTime("query", ms);
  tally.AddTime("features", 7.0);
  tally.Finish();
  ASSERT_EQ(figures.timing_ms.size(), 2u);
  const StageStats& query = figures.timing_ms.at("query");
  EXPECT_DOUBLE_EQ(query.mean, 2.5);
  EXPECT_DOUBLE_EQ(query.median, 2.5);
  EXPECT_DOUBLE_EQ(query.max, 4.0);
  EXPECT_DOUBLE_EQ(figures.timing_ms.at("features").median, 7.0);
  const StageStats none = StatsOf({});
  EXPECT_EQ(none.mean, 0.0);
  EXPECT_EQ(none.max, 0.0);
}

// Recall's complement: a revisit without a correct loop is a miss, counted by its reason; an
// ambiguous pair's loop is not counted correct.
TEST(LoopTallyTest, MissesAreCountedByReasonBesideEachFramesStatus) {
  LoopFigures figures;
  LoopTally tally(&figures);
  tally.CountStatus("loop_detected");
  tally.CountStatus("failed_geometry");
  tally.CountStatus("loop_detected");
  EXPECT_EQ(figures.frame_statuses,
            (std::vector<std::string>{"loop_detected", "failed_geometry", "loop_detected"}));
  EXPECT_TRUE(tally.CountDetection(/*correct=*/true, /*ambiguous=*/false));
  EXPECT_FALSE(tally.CountDetection(true, /*ambiguous=*/true));
  EXPECT_FALSE(tally.CountDetection(false, false));
  MissedRevisit failed;
  failed.query = 1;
  failed.reason = MissReason::kFailedGeometry;
  tally.CountMiss(failed);
  MissedRevisit wrong = failed;
  wrong.query = 2;
  wrong.reason = MissReason::kWrongLoop;
  tally.CountMiss(wrong);
  tally.CountMiss(failed);
  ASSERT_EQ(figures.misses.size(), 3u);
  EXPECT_EQ(figures.misses[1].query, 2);
  EXPECT_EQ(figures.miss_reasons,
            (std::map<std::string, int>{{"failed_geometry", 2}, {"wrong_loop", 1}}));
  EXPECT_EQ(MissReasonName(MissReason::kWrongTopCandidate), "wrong_top_candidate");
  EXPECT_EQ(std::size(kMissReasons), 7u);
}

TEST(LoopTallyTest, TheTruthMustCoverTheSequence) {
  GroundTruth truth;
  truth.frames = 3;
  truth.matches.resize(3);
  EXPECT_TRUE(CheckTruthCovers(truth, 3, "sequence").ok());
  const Status short_truth = CheckTruthCovers(truth, 4, "rig sequence");
  EXPECT_EQ(short_truth.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(short_truth.message().find("covers 3 frames but the rig sequence has 4"),
            std::string::npos)
      << short_truth.ToString();
}

}  // namespace
}  // namespace recog::cli
