#include "tools/evaluation/frame_poses.h"

#include <algorithm>
#include <cctype>
#include <charconv>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "core/common/median.h"
#include "tools/common/cli_support.h"
#include "tools/evaluation/plot.h"
#include "tools/evaluation/visp_files.h"

namespace recog::cli {

namespace fs = std::filesystem;

std::optional<int> FrameNumber(const std::string& path) {
  const std::string stem = fs::path(path).stem().string();
  size_t start = stem.size();
  while (start > 0 && std::isdigit(static_cast<unsigned char>(stem[start - 1]))) --start;
  int number = 0;
  const char* end = stem.data() + stem.size();
  const auto [last, error] = std::from_chars(stem.data() + start, end, number);
  if (start == stem.size() || error != std::errc() || last != end) return std::nullopt;
  return number;
}

StatusOr<std::map<int, RigidTransform>> ReadFramePoses(const std::string& path) {
  std::ifstream in(path);
  if (!fs::is_regular_file(path) || !in) {
    return Status::NotFound("pose list '" + path + "' cannot be read");
  }
  std::map<int, RigidTransform> poses;
  std::map<int, int> line_of_frame;
  std::string line;
  for (int number = 1; std::getline(in, line); ++number) {
    std::istringstream fields(line.substr(0, line.find('#')));
    std::vector<std::string> tokens;
    for (std::string token; fields >> token;) tokens.push_back(token);
    if (tokens.empty()) continue;
    const std::string where = path + ":" + std::to_string(number);
    if (tokens.size() != 13) {
      return Status::InvalidArgument(
          where + ": expected a frame number and 12 numbers (r11..r33 tx ty tz), got " +
          std::to_string(tokens.size()) + " fields");
    }
    const bool digits = std::all_of(tokens[0].begin(), tokens[0].end(), [](char c) {
      return std::isdigit(static_cast<unsigned char>(c)) != 0;
    });
    const std::optional<int> frame = digits ? FrameNumber(tokens[0]) : std::nullopt;
    if (!frame) {
      return Status::InvalidArgument(where + ": '" + tokens[0] + "' is not a frame number");
    }
    RigidTransform pose;
    for (size_t k = 1; k < tokens.size(); ++k) {
      RECOG_ASSIGN_OR_RETURN(const std::vector<double> value, ParseNumbers(where, tokens[k]));
      if (value.size() != 1) {
        return Status::InvalidArgument(where + ": '" + tokens[k] + "' is not a finite number");
      }
      (k <= 9 ? pose.R.val[k - 1] : pose.t[int(k) - 10]) = value[0];
    }
    if (!IsRotationMatrix(pose.R)) {
      return Status::InvalidArgument(where + ": r11..r33 is not a rotation matrix");
    }
    if (const auto [seen, added] = line_of_frame.emplace(*frame, number); !added) {
      return Status::InvalidArgument(where + ": frame " + std::to_string(*frame) +
                                     " again (first on line " + std::to_string(seen->second) + ")");
    }
    poses[*frame] = pose;
  }
  if (poses.empty()) return Status::InvalidArgument("pose list '" + path + "' holds no pose");
  return poses;
}

StatusOr<RigidTransform> ReadPoseOfFrame(const std::string& pose_path,
                                         const std::string& image_path) {
  if (fs::path(pose_path).extension() == ".pos") return ReadVispPose(pose_path);
  const std::optional<int> frame = FrameNumber(image_path);
  if (!frame) {
    return Status::InvalidArgument("'" + image_path + "' has no frame number to look up in '" +
                                   pose_path + "'");
  }
  RECOG_ASSIGN_OR_RETURN(const auto poses, ReadFramePoses(pose_path));
  const auto pose = poses.find(*frame);
  if (pose == poses.end()) {
    return Status::NotFound("pose list '" + pose_path + "' has no line for frame " +
                            std::to_string(*frame) + " ('" + image_path + "')");
  }
  return pose->second;
}

std::optional<FramePoseScore> ScoreFramePose(const std::map<int, RigidTransform>& poses,
                                             const std::string& image_path,
                                             const std::string& expect,
                                             const std::vector<Detection>& detections,
                                             const SizeRecallOptions& options) {
  const std::optional<int> frame = FrameNumber(image_path);
  if (!frame) return std::nullopt;
  const auto pose = poses.find(*frame);
  if (pose == poses.end()) return std::nullopt;
  ObjectTruthFrame truth;
  truth.image = fs::path(image_path).filename().string();
  truth.camera_from_object = pose->second;
  truth.in_view = 1;
  truth.visible = true;
  FramePoseScore score;
  score.frame = *frame;
  score.score = ScoreTruthFrame(truth, expect, detections, options);
  const auto found = std::find_if(detections.begin(), detections.end(),
                                  [&](const Detection& d) { return d.name == expect; });
  if (found != detections.end()) score.inliers = found->inliers;
  return score;
}

PoseErrorSummary SummarisePoseErrors(const std::vector<FramePoseScore>& frames) {
  PoseErrorSummary summary;
  std::vector<double> rotation, translation;
  for (const FramePoseScore& f : frames) {
    ++summary.frames_with_pose;
    summary.wrong_objects += f.score.other_objects;
    if (!f.score.found) continue;
    ++summary.found;
    summary.correct_pose += f.score.correct_pose;
    rotation.push_back(f.score.rotation_error_deg);
    translation.push_back(f.score.translation_error_m);
  }
  if (summary.frames_with_pose > 0) {
    summary.recall = double(summary.found) / double(summary.frames_with_pose);
  }
  summary.median_rotation_error_deg = Median(rotation);
  summary.median_translation_error_m = Median(translation);
  return summary;
}

Status WritePoseErrorCsv(const std::vector<FramePoseScore>& frames, const std::string& path) {
  std::ofstream out(path);
  out.precision(10);
  out << "frame,found,inliers,rotation_error_deg,translation_error_m,wrong_objects\n";
  for (const FramePoseScore& f : frames) {
    out << f.frame << ',' << int(f.score.found) << ',' << f.inliers << ',';
    if (f.score.found) {
      out << f.score.rotation_error_deg << ',' << f.score.translation_error_m;
    } else {
      out << ',';
    }
    out << ',' << f.score.other_objects << '\n';
  }
  out.close();
  if (!out) return Status::Internal("cannot write '" + path + "'");
  return Status::Ok();
}

Status WritePoseErrorPlot(const std::vector<FramePoseScore>& frames, const std::string& title,
                          const std::string& path) {
  PlotSeries rotation{"rotation error (deg)", {}, cv::Scalar(200, 80, 20), {}};
  PlotSeries translation{"translation error (cm)", {}, cv::Scalar(40, 160, 40), {}};
  PlotOptions plot;
  plot.title = title;
  plot.x_label = "frame";
  plot.y_label = "error: degrees / centimetres";
  plot.write_csv = false;  // WritePoseErrorCsv writes every frame, found or not
  if (!frames.empty()) {
    const auto [first, last] = std::minmax_element(
        frames.begin(), frames.end(),
        [](const FramePoseScore& a, const FramePoseScore& b) { return a.frame < b.frame; });
    plot.x_min = first->frame;
    plot.x_max = std::max(last->frame, first->frame + 1);
  }
  double largest = 0;
  for (const FramePoseScore& f : frames) {
    if (!f.score.found) continue;
    rotation.points.push_back({double(f.frame), f.score.rotation_error_deg});
    translation.points.push_back({double(f.frame), 100 * f.score.translation_error_m});
    largest = std::max({largest, f.score.rotation_error_deg, 100 * f.score.translation_error_m});
  }
  plot.y_max = std::max(1.0, 1.05 * largest);
  return WritePlot(path, plot, {rotation, translation});
}

}  // namespace recog::cli
