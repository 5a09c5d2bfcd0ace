// recog stream: a recorded sequence (folder, list, video or ROS 1 or ROS 2 bag; or a multi-camera
// rig sequence) through one StreamFrames call of recogd, printing every loop closure as it is
// answered, over the C++ client library. It takes the ServerFlags; a failed call prints one line
// "recog stream: CODE: message" and exits 1.
#include <chrono>
#include <csignal>
#include <cstdio>
#include <deque>
#include <filesystem>
#include <future>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include <nlohmann/json.hpp>
#include <opencv2/features2d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "client/cpp/frame_stream.h"
#include "client/cpp/frames.h"
#include "client/cpp/recognition_client.h"
#include "core/object/model/object_model.h"
#include "core/place/detector_settings.h"
#include "tools/common/cli_support.h"
#include "tools/common/remote_support.h"
#include "tools/common/server_flags.h"
#include "tools/evaluation/object_evaluation.h"
#include "tools/evaluation/place_evaluation.h"
#include "tools/evaluation/rig_dataset.h"
#include "tools/evaluation/rig_file.h"
#include "tools/recog/bag_flags.h"
#include "tools/recog/commands.h"
#include "tools/recog/loop_json.h"
#include "wire/grpc_code_names.h"

namespace recog::cli {
namespace {

namespace fs = std::filesystem;
using client::RecognitionClient;
using Json = nlohmann::ordered_json;

// ---- recog stream ----

struct StreamArgs {
  ServerFlags server;
  std::string map, images, rig, draw;
  double depth_scale = 5000;  // --rig: units per metre of the cameras' 16-bit depth images
  std::string preset;  // with create: the new map's detector preset (the server's when empty)
  std::string group;   // with create: the new map's group
  std::vector<std::string> search_maps;  // other maps every frame is looked up in
  std::string search_group;
  double rate = 0;
  uint64_t frames = 0;  // 0: every frame of the sequence
  bool features_on_client = false, create = false, timestamps = false, quiet = false;
  bool keep_thumbnails = false;  // with create: the new map keeps a thumbnail of each frame
  BagFlags bag;                  // --bag and its topics, instead of --images
};

// Set by SIGINT/SIGTERM while `recog stream` runs: stop reading frames, take the answers of those
// sent, close the stream and print the summary.
volatile std::sig_atomic_t stop_streaming = 0;
void StopStreaming(int) { stop_streaming = 1; }

// Frames sent ahead of their answers: enough to keep the server busy while a frame travels.
constexpr size_t kFramesInFlight = 4;

// The frame of one image of the sequence (see the --help of recog stream).
client::Result<pb::Frame> StreamFrame(const StreamArgs& args, bool from_file,
                                      const std::string& name, const cv::Mat& gray) {
  if (args.features_on_client) {
    auto features = client::ExtractOrbFeatures(gray);
    if (!features.ok()) return features.status();
    return client::FrameFromFeatures(features->keypoints, features->descriptors, gray.size());
  }
  return from_file ? FrameFromImageFile(name, gray) : client::FrameFromImage(gray);
}

// What recog stream sends: the frames of an image sequence (--images), or the rig frames of a
// rig sequence (--rig: one view per camera, with the camera's depth image when it has one).
class StreamSequence {
 public:
  static StatusOr<StreamSequence> Open(const StreamArgs& args) {
    StreamSequence sequence;
    if (!args.rig.empty()) {
      RECOG_ASSIGN_OR_RETURN(sequence.rig_, ReadRigDataset(args.rig));
      for (const RigCamera& camera : sequence.rig_->cameras) {
        sequence.cameras_.push_back(camera.name);
      }
    } else {
      RECOG_ASSIGN_OR_RETURN(sequence.images_,
                             args.bag.given() ? args.bag.Open() : FrameSource::Open(args.images));
      sequence.cameras_ = {""};
      if (const RosBagReader* bag = sequence.images_->bag()) {
        sequence.bag_camera_ = bag->FrameCamera();
        RECOG_ASSIGN_OR_RETURN(sequence.baseline_, bag->StereoBaseline());
        if (!sequence.bag_camera_.has_value() &&
            !(args.bag.topics.depth.empty() && args.bag.topics.right.empty())) {
          return Status::InvalidArgument(
              "--depth-topic and --right-topic need --camera-info-topic");
        }
        if (!args.bag.topics.right.empty() && !sequence.baseline_.has_value()) {
          return Status::InvalidArgument(
              "--right-topic needs --right-camera-info-topic (its P gives the baseline)");
        }
      }
    }
    return sequence;
  }

  size_t size() const { return rig_ ? rig_->images.size() : images_->size(); }
  // The camera of each of a frame's images ("" for the one camera of an image sequence).
  const std::vector<std::string>& cameras() const { return cameras_; }
  // With --rig: the rig of a map --create makes.
  void AddRig(pb::MapSettings* settings) const {
    if (!rig_) return;
    for (const RigCamera& c : rig_->cameras) {
      pb::RigCameraSettings* camera = settings->add_rig();
      *camera = client::MakeRigCamera(c.name, c.size, c.K, c.distortion, c.body_R_camera,
                                      c.body_t_camera);
      camera->mutable_intrinsics()->set_lens(pb::LensModel(c.lens));  // the same numbers
    }
  }

  // The next frame, its name (its first image's path) and its grey images (one per camera);
  // false at the end. A frame that cannot be read or built is an error, and the next call goes
  // on with the following one.
  StatusOr<bool> Next(const StreamArgs& args, pb::Frame* frame, std::string* name,
                      std::vector<cv::Mat>* images) {
    images->clear();
    std::optional<double> recorded;
    if (rig_) {
      if (next_ == rig_->images.size()) return false;
      const size_t i = next_++;
      *frame = pb::Frame();
      *name = rig_->images[i].front();
      for (size_t c = 0; c < cameras_.size(); ++c) {
        RECOG_ASSIGN_OR_RETURN(cv::Mat gray, ReadGrayImage(rig_->images[i][c]));
        client::Result<pb::Frame> view =
            StreamFrame(args, /*from_file=*/true, rig_->images[i][c], gray);
        if (!view.ok()) return Status::InvalidArgument(view.status().error_message());
        RECOG_RETURN_IF_ERROR(AttachDepth(rig_->depths[i][c], args.depth_scale, &*view));
        const grpc::Status added = client::AddRigView(cameras_[c], std::move(*view), frame);
        if (!added.ok()) return Status::InvalidArgument(added.error_message());
        images->push_back(std::move(gray));
      }
      recorded = rig_->timestamps[i];
    } else {
      cv::Mat gray;
      RECOG_ASSIGN_OR_RETURN(const bool more, images_->Next(&gray, name));
      if (!more) return false;
      const bool from_file = !images_->is_video() && !images_->is_bag();
      client::Result<pb::Frame> built = StreamFrame(args, from_file, *name, gray);
      if (!built.ok()) return Status::InvalidArgument(built.status().error_message());
      *frame = std::move(*built);
      if (images_->is_bag()) {
        RECOG_ASSIGN_OR_RETURN(const cv::Mat depth, images_->depth());
        RECOG_ASSIGN_OR_RETURN(const cv::Mat right, images_->right());
        RECOG_RETURN_IF_ERROR(AttachBagGeometry(bag_camera_, baseline_, depth, right, frame)
                                  .WithContext("frame " + *name));
      }
      images->push_back(std::move(gray));
      recorded = images_->timestamp();
    }
    if (args.timestamps) {
      frame->set_timestamp(
          recorded.has_value()
              ? *recorded
              : std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch())
                    .count());
    }
    return true;
  }

 private:
  StreamSequence() = default;

  // A camera's depth image (none when `path` is empty), in units of 1/units_per_metre metres.
  static Status AttachDepth(const std::string& path, double units_per_metre, pb::Frame* view) {
    if (path.empty()) return Status::Ok();
    const cv::Mat depth = cv::imread(path, cv::IMREAD_ANYDEPTH);
    if (depth.empty()) return Status::InvalidArgument("cannot read depth image '" + path + "'");
    const grpc::Status attached = client::AttachDepth(depth, units_per_metre, view);
    if (!attached.ok()) return Status::InvalidArgument(path + ": " + attached.error_message());
    return Status::Ok();
  }

  std::optional<FrameSource> images_;
  std::optional<CameraIntrinsics> bag_camera_;  // a bag's frames' camera (--camera-info-topic)
  std::optional<double> baseline_;              // a bag's stereo baseline
  std::optional<RigDataset> rig_;
  std::vector<std::string> cameras_;
  size_t next_ = 0;
};

// What recog stream keeps of the frames it sent, to name (and draw) the loops.
struct SentFrames {
  std::vector<std::string> names;             // by sequence: file names
  std::vector<std::vector<cv::Mat>> images;   // by sequence, per camera, with --draw
  std::map<uint64_t, size_t> sequence_of_id;  // the map's frame id -> sequence

  // "45 (45.jpg)"; "3" for a frame that an earlier session added.
  std::string Describe(uint64_t id) const {
    const auto found = sequence_of_id.find(id);
    return std::to_string(id) +
           (found == sequence_of_id.end() ? "" : " (" + names[found->second] + ")");
  }
};

// "rear>front, front>front": the camera pairs of a rig loop (empty for other loops).
std::string CameraPairs(const pb::LoopResult& r) {
  std::string pairs;
  for (const pb::RigCameraMatch& pair : r.rig().pairs()) {
    pairs += (pairs.empty() ? "" : ", ") + pair.query_camera() + ">" + pair.match_camera();
  }
  return pairs;
}

// The two images of a loop side by side with their inlier correspondences and a caption, as
// DIR/loop_<frame>_<match>.png. A rig loop shows its first camera pair.
Status DrawLoop(const std::string& dir, const SentFrames& sent,
                const std::vector<std::string>& cameras, const pb::LoopResult& r) {
  const uint64_t frame = r.frame_id(), match = r.match_frame_id();
  const size_t a = sent.sequence_of_id.at(frame), b = sent.sequence_of_id.at(match);
  size_t query_camera = 0, match_camera = 0;
  const google::protobuf::RepeatedPtrField<pb::Correspondence>* inliers =
      &r.inlier_correspondences();
  if (r.rig().pairs_size() > 0) {
    const pb::RigCameraMatch& pair = r.rig().pairs(0);
    const auto index = [&](const std::string& name) {
      return size_t(std::find(cameras.begin(), cameras.end(), name) - cameras.begin());
    };
    query_camera = index(pair.query_camera());
    match_camera = index(pair.match_camera());
    if (query_camera == cameras.size() || match_camera == cameras.size()) {
      return Status::InvalidArgument("the loop names a camera the sequence does not have");
    }
    inliers = &pair.inlier_correspondences();
  }
  std::vector<cv::KeyPoint> query_points, match_points;
  std::vector<cv::DMatch> lines;
  for (const pb::Correspondence& c : *inliers) {
    lines.emplace_back(int(query_points.size()), int(match_points.size()), 0.0f);
    query_points.emplace_back(c.query_x(), c.query_y(), 1.0f);
    match_points.emplace_back(c.match_x(), c.match_y(), 1.0f);
  }
  cv::Mat canvas;
  cv::drawMatches(sent.images[a][query_camera], query_points, sent.images[b][match_camera],
                  match_points, lines, canvas, cv::Scalar(0, 200, 0));
  cv::copyMakeBorder(canvas, canvas, 36, 0, 0, 0, cv::BORDER_CONSTANT, cv::Scalar(255, 255, 255));
  const std::string pairs = CameraPairs(r);
  const std::string caption = "frame " + sent.Describe(frame) + " closes a loop with frame " +
                              sent.Describe(match) + ": " + std::to_string(r.inliers()) +
                              " inliers" + (pairs.empty() ? "" : " (" + pairs + ")");
  // The caption shrinks to fit small images.
  int baseline = 0;
  const double width = cv::getTextSize(caption, cv::FONT_HERSHEY_SIMPLEX, 0.6, 1, &baseline).width;
  const double scale = std::min(0.6, 0.6 * (canvas.cols - 16) / width);
  cv::putText(canvas, caption, {8, 25}, cv::FONT_HERSHEY_SIMPLEX, scale, cv::Scalar(0, 0, 0), 1,
              cv::LINE_AA);
  const std::string path =
      (fs::path(dir) / ("loop_" + std::to_string(frame) + "_" + std::to_string(match) + ".png"))
          .string();
  if (!cv::imwrite(path, canvas)) return Status::Internal("cannot write '" + path + "'");
  return Status::Ok();
}

// --rate and the sequence: what the command line cannot check by itself.
Status CheckStreamFlags(const StreamArgs& args) {
  if (!(args.rate >= 0)) return Status::InvalidArgument("--rate must be >= 0");
  if (int(!args.images.empty()) + int(!args.rig.empty()) + int(args.bag.given()) != 1) {
    return Status::InvalidArgument("give --images or --rig (or --bag)");
  }
  return Status::Ok();
}

// --draw: its folder, created when missing.
Status CreateDrawFolder(const std::string& dir) {
  if (dir.empty()) return Status::Ok();
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) return Status::InvalidArgument("cannot create '" + dir + "': " + ec.message());
  return Status::Ok();
}

// The map the frames go into (made with --create and its settings), the maps also searched, and
// what the answers hold.
pb::StreamConfig StreamConfigOf(const StreamArgs& args, const StreamSequence& source) {
  pb::StreamConfig config;
  config.set_map(args.map);
  config.set_create_if_missing(args.create);
  if (!args.preset.empty()) config.mutable_settings()->set_preset(args.preset);
  if (!args.group.empty()) config.mutable_settings()->set_group(args.group);
  if (args.keep_thumbnails) config.mutable_settings()->set_keep_thumbnails(true);
  for (const std::string& name : args.search_maps) config.add_search_maps(name);
  config.set_search_group(args.search_group);
  if (args.create) source.AddRig(config.mutable_settings());
  // Drawn loops show their inliers.
  config.mutable_options()->set_include_correspondences(!args.draw.empty());
  return config;
}

// What recog stream prints of the answers, taken in the order of their frames (a line per loop,
// inter-map loop, candidate loop or failed frame; with --json an object per line), the loops it
// draws, and its counts for the summary.
class StreamReport {
 public:
  StreamReport(const StreamArgs& args, const StreamSequence& source, ProgressBar* progress)
      : args_(args), source_(source), progress_(progress) {}

  // Keeps what the report needs of a frame about to be sent: its name, its images with --draw.
  void FrameSent(const std::string& name, std::vector<cv::Mat> images) {
    sent_.names.push_back(fs::path(name).filename().string());
    if (!args_.draw.empty()) sent_.images.push_back(std::move(images));
  }
  size_t frames_sent() const { return sent_.names.size(); }

  // Reports the answer of the next frame; false once the stream has failed (see failure()).
  bool ReportAnswer(client::FrameStream::Answer answer) {
    if (!answer.ok()) {
      failure_ = answer.status();
      return false;
    }
    const size_t sequence = answered_++;
    progress_->Update("frames", answered_, source_.size());
    if (answer->has_error()) {
      FrameFailed(sequence, answer->error());
      return true;
    }
    const pb::LoopResult& r = answer->result();
    if (r.has_frame_id()) sent_.sequence_of_id[r.frame_id()] = sequence;
    for (const pb::InterMapMatch& found : answer->inter_map()) InterMapLoop(sequence, found);
    if (r.status() == pb::LOOP_STATUS_CANDIDATE && r.has_match_frame_id()) {
      Candidate(r);
    } else if (r.status() == pb::LOOP_STATUS_LOOP_DETECTED && r.has_match_frame_id()) {
      Loop(sequence, r);
    }
    return true;
  }

  // A frame that could not be read or sent: reported, and the stream goes on.
  void ReportSkipped(const Status& status) {
    ++errors_;
    progress_->Finish();
    Fail("stream", status);
  }

  // How the stream failed (OK while it has not).
  const grpc::Status& failure() const { return failure_; }

  // The last line: the counts, the time since `start` and the rate.
  void PrintSummary(std::chrono::steady_clock::time_point start) const {
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    const double rate = seconds > 0 ? double(answered_) / seconds : 0.0;
    if (args_.server.json) {
      std::printf("%s\n", Json({{"event", "summary"},
                                {"map", args_.map},
                                {"frames", answered_},
                                {"loops", loops_},
                                {"inter_map_loops", inter_map_loops_},
                                {"errors", errors_},
                                {"seconds", seconds},
                                {"frames_per_second", rate}})
                              .dump()
                              .c_str());
      return;
    }
    const bool searching = !args_.search_maps.empty() || !args_.search_group.empty();
    std::printf("%zu frames, %zu loops, %s%zu errors in %.2f s (%.1f frames/s)\n", answered_,
                loops_,
                searching ? (std::to_string(inter_map_loops_) + " inter-map loops, ").c_str() : "",
                errors_, seconds, rate);
  }

  // The exit status: 1 when any frame failed.
  int ExitCode() const { return errors_ == 0 ? 0 : 1; }

 private:
  void FrameFailed(size_t sequence, const pb::FrameError& e) {
    ++errors_;
    progress_->Finish();
    std::fprintf(stderr, "recog stream: frame %s: %s: %s\n", sent_.names[sequence].c_str(),
                 std::string(GrpcCodeName(grpc::StatusCode(e.code()))).c_str(),
                 e.message().c_str());
  }

  // The frame was also seen in one of the maps searched (--search-maps, --search-group).
  void InterMapLoop(size_t sequence, const pb::InterMapMatch& found) {
    ++inter_map_loops_;
    const pb::LoopResult& m = found.result();
    if (args_.server.json) {
      Json loop = {{"event", "inter_map_loop"}, {"map", found.map()}};
      loop.update(LoopJson(m));
      loop["frame_file"] = sent_.names[sequence];
      std::printf("%s\n", loop.dump().c_str());
      return;
    }
    progress_->Finish();
    std::printf(
        "frame %s was seen in map '%s' as frame %llu%s: %u inliers\n",
        sent_.names[sequence].c_str(), found.map().c_str(),
        static_cast<unsigned long long>(m.match_frame_id()),
        m.match_client_frame_id().empty() ? "" : (" (" + m.match_client_frame_id() + ")").c_str(),
        m.inliers());
  }

  // A loop awaiting the next keyframes' confirmation (MapSettings.keyframe_confirmations): shown,
  // not counted as a loop.
  void Candidate(const pb::LoopResult& r) {
    if (args_.server.json) {
      Json candidate = {{"event", "candidate"}};
      candidate.update(LoopJson(r));
      std::printf("%s\n", candidate.dump().c_str());
    } else {
      progress_->Finish();
      std::printf("frame %s: candidate loop with frame %s, %u inliers, awaiting confirmation\n",
                  sent_.Describe(r.frame_id()).c_str(), sent_.Describe(r.match_frame_id()).c_str(),
                  r.inliers());
    }
    std::fflush(stdout);
  }

  // A loop closure: printed, and drawn with --draw when both frames are of this session.
  void Loop(size_t sequence, const pb::LoopResult& r) {
    ++loops_;
    if (args_.server.json) {
      Json loop = {{"event", "loop"}};
      loop.update(LoopJson(r));
      loop["frame_file"] = sent_.names[sequence];
      const auto match = sent_.sequence_of_id.find(r.match_frame_id());
      if (match != sent_.sequence_of_id.end()) loop["match_file"] = sent_.names[match->second];
      std::printf("%s\n", loop.dump().c_str());
    } else {
      progress_->Finish();
      const std::string pairs = CameraPairs(r);
      std::printf("frame %s closes a loop with frame %s: %u inliers%s\n",
                  sent_.Describe(r.frame_id()).c_str(), sent_.Describe(r.match_frame_id()).c_str(),
                  r.inliers(), pairs.empty() ? "" : (" (" + pairs + ")").c_str());
    }
    std::fflush(stdout);
    if (!args_.draw.empty() && r.has_frame_id() &&
        sent_.sequence_of_id.contains(r.match_frame_id())) {
      if (Status s = DrawLoop(args_.draw, sent_, source_.cameras(), r); !s.ok()) {
        ++errors_;
        Fail("stream", s);
      }
    }
  }

  const StreamArgs& args_;
  const StreamSequence& source_;
  ProgressBar* const progress_;
  SentFrames sent_;
  size_t answered_ = 0, loops_ = 0, inter_map_loops_ = 0, errors_ = 0;
  grpc::Status failure_;
};

// The answers of the frames sent, in their order, each reported as soon as it is taken; the
// reporting stops once the stream has failed.
class PendingAnswers {
 public:
  explicit PendingAnswers(StreamReport* report) : report_(report) {}

  void Add(std::future<client::FrameStream::Answer> answer) {
    pending_.push_back(std::move(answer));
  }
  // False once the stream has failed.
  bool streaming() const { return streaming_; }

  // Reports the answers that come before `until`, in order.
  void TakeUntil(std::chrono::steady_clock::time_point until) {
    while (streaming_ && !pending_.empty() &&
           pending_.front().wait_until(until) == std::future_status::ready) {
      TakeOldest();
    }
  }
  // Waits for answers (oldest first) until at most `in_flight` frames are unanswered.
  void TakeAllBut(size_t in_flight) {
    while (streaming_ && pending_.size() > in_flight) TakeOldest();
  }

 private:
  void TakeOldest() {
    streaming_ = report_->ReportAnswer(pending_.front().get());
    pending_.pop_front();
  }

  StreamReport* const report_;
  std::deque<std::future<client::FrameStream::Answer>> pending_;
  bool streaming_ = true;
};

// While it lives, SIGINT and SIGTERM set stop_streaming (cleared first) instead of ending the
// process.
class StopStreamingOnSignals {
 public:
  StopStreamingOnSignals() {
    stop_streaming = 0;
    previous_int_ = std::signal(SIGINT, StopStreaming);
    previous_term_ = std::signal(SIGTERM, StopStreaming);
  }
  ~StopStreamingOnSignals() {
    std::signal(SIGINT, previous_int_);
    std::signal(SIGTERM, previous_term_);
  }
  StopStreamingOnSignals(const StopStreamingOnSignals&) = delete;
  StopStreamingOnSignals& operator=(const StopStreamingOnSignals&) = delete;

 private:
  void (*previous_int_)(int);
  void (*previous_term_)(int);
};

// With --rate: when the frame numbered `sent` (from 0) is due, `start` being the first's time.
std::chrono::steady_clock::time_point DueTime(std::chrono::steady_clock::time_point start,
                                              size_t sent, double rate) {
  return start + std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                     std::chrono::duration<double>(double(sent) / rate));
}

// Sends the frames of `source` (--frames of them, or all) at --rate, or a few ahead of their
// answers, reporting each answer as it comes; until the end of the sequence, a failed stream or
// SIGINT/SIGTERM. The answers of the last frames are left in *answers.
void SendFrames(const StreamArgs& args, std::chrono::steady_clock::time_point start,
                StreamSequence* source, client::FrameStream* stream, StreamReport* report,
                PendingAnswers* answers) {
  const StopStreamingOnSignals stop_on_signals;
  while (answers->streaming() && !stop_streaming &&
         (args.frames == 0 || report->frames_sent() < args.frames)) {
    pb::Frame frame;
    std::string name;
    std::vector<cv::Mat> images;
    StatusOr<bool> more = source->Next(args, &frame, &name, &images);
    if (!more.ok()) {
      report->ReportSkipped(more.status());
      continue;
    }
    if (!*more) break;
    if (args.rate > 0) {
      const auto due = DueTime(start, report->frames_sent(), args.rate);
      answers->TakeUntil(due);
      std::this_thread::sleep_until(due);
    }
    report->FrameSent(name, std::move(images));
    answers->Add(stream->Send(std::move(frame)));
    answers->TakeUntil(std::chrono::steady_clock::now());  // those that have come
    answers->TakeAllBut(kFramesInFlight);
  }
}

int RunStream(const StreamArgs& args, RecognitionClient& client) {
  if (Status s = CheckStreamFlags(args); !s.ok()) return Fail("stream", s);
  auto source = StreamSequence::Open(args);
  if (!source.ok()) return Fail("stream", source.status());
  if (Status s = CreateDrawFolder(args.draw); !s.ok()) return Fail("stream", s);
  auto stream = client::FrameStream::Open(client, StreamConfigOf(args, *source));
  if (!stream.ok()) return Fail("stream", stream.status());
  ProgressBar progress(!args.quiet);
  StreamReport report(args, *source, &progress);
  const auto start = std::chrono::steady_clock::now();
  PendingAnswers answers(&report);
  SendFrames(args, start, &*source, stream->get(), &report, &answers);
  answers.TakeAllBut(0);  // the answers still due
  const grpc::Status end = (*stream)->Close();
  progress.Finish();
  if (!report.failure().ok()) return Fail("stream", report.failure());
  if (!end.ok()) return Fail("stream", end);
  report.PrintSummary(start);
  return report.ExitCode();
}

}  // namespace

void AddStreamCommands(CLI::App& app, int* exit_code) {
  auto stream_args = std::make_shared<StreamArgs>();
  CLI::App* stream = app.add_subcommand(
      "stream", "Stream a recorded sequence into a map of recogd and print every loop closure");
  stream->footer(
      "JPEG and PNG files are sent as they are: the server decodes them to the grey pixels that "
      "`recog eval place` reads, so the loops are the same. Other images, video frames and a "
      "bag's frames are sent as raw grey pixels (a bag's with the intrinsics of "
      "--camera-info-topic, and its depth or right images for metric loops). Frames are numbered "
      "as the map numbers them, from 0. --json prints one "
      "object per line: {\"event\": \"loop\", ...} per loop, then {\"event\": \"summary\", ...}. "
      "A frame that fails on its own is reported and the stream goes on; the exit status is then "
      "1. Ctrl-C (SIGINT) or SIGTERM stops reading frames: the answers of those sent are taken, "
      "the stream is closed and the summary printed (how a camera stream ends).");
  stream->add_option("--map", stream_args->map, "Map name")->required();
  CLI::Option* images =
      stream->add_option("--images", stream_args->images,
                         "Folder of frames, a list file, a video, or camera:N for the live camera "
                         "/dev/videoN");
  stream_args->bag.AddTo(stream, images);
  stream
      ->add_option("--rig", stream_args->rig,
                   "Instead of --images, a multi-camera rig sequence (a folder with rig.yaml and "
                   "one folder per camera, a EuRoC folder of cam0, cam1, ... or a KITTI sequence "
                   "folder) into a rig map: every frame carries one view per camera, and a "
                   "camera's depth image when it has one")
      ->excludes(images);
  stream
      ->add_option("--depth-scale", stream_args->depth_scale,
                   "With --rig: units per metre of the cameras' 16-bit depth images")
      ->capture_default_str()
      ->needs("--rig");
  stream->add_option("--frames", stream_args->frames, "Stop after this many frames (0: all)")
      ->capture_default_str();
  stream
      ->add_option("--rate", stream_args->rate,
                   "Frames per second to send (0: as fast as the "
                   "server answers, a few frames in flight)")
      ->capture_default_str();
  stream->add_flag("--features-on-client", stream_args->features_on_client,
                   "Extract the ORB features here and send them instead of the images");
  stream->add_flag("--create", stream_args->create,
                   "Create the map (with the server's default settings) if it does not exist");
  stream
      ->add_option("--preset", stream_args->preset,
                   "With --create: the new map's detector preset:\n" + PresetHelp())
      ->check(CLI::IsMember([] {
        std::vector<std::string> names;
        for (const DetectorPresetInfo& info : DetectorPresets()) {
          names.emplace_back(DetectorPresetName(info.preset));
        }
        return names;
      }()))
      ->needs("--create");
  stream
      ->add_option("--group", stream_args->group,
                   "With --create: the new map's group (searched together by --search-group)")
      ->needs("--create");
  stream
      ->add_flag("--keep-thumbnails", stream_args->keep_thumbnails,
                 "With --create: the new map keeps a small JPEG of each frame, which the web "
                 "console shows beside its loops")
      ->needs("--create");
  stream->add_option("--search-maps", stream_args->search_maps,
                     "Other maps every frame is also looked up in (relocalisation; their matches "
                     "are reported as inter-map loops)");
  stream->add_option("--search-group", stream_args->search_group,
                     "Every map of this group is searched too, as --search-maps");
  stream->add_option("--draw", stream_args->draw,
                     "Folder for a PNG per loop (loop_<frame>_<match>.png): both frames side by "
                     "side with their inlier correspondences (a rig loop: its first camera pair)");
  stream->add_flag(
      "--timestamps", stream_args->timestamps,
      "Stamp each frame with its time in the dataset (TUM, EuRoC, KITTI, a bag's "
      "header stamps; 0.0 is a time), or else this machine's clock when it is sent (the map's "
      "recent_seconds then applies instead of recent_frames)");
  stream->add_flag("-q,--quiet", stream_args->quiet, "No progress output");
  ConnectCommand(stream, &stream_args->server, exit_code, [stream_args](RecognitionClient& client) {
    return RunStream(*stream_args, client);
  });
}

}  // namespace recog::cli
