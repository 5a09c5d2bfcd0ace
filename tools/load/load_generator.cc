#include "tools/load/load_generator.h"

#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cctype>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <deque>
#include <filesystem>
#include <latch>
#include <memory>
#include <mutex>
#include <thread>
#include <utility>

#include "client/cpp/frame_stream.h"
#include "client/cpp/frames.h"
#include "core/features/feature_extractor.h"
#include "core/place/detector_settings.h"
#include "core/vocabulary/vocabulary_io.h"
#include "tools/common/cli_support.h"
#include "tools/common/remote_support.h"
#include "tools/common/server_flags.h"
#include "tools/evaluation/plot.h"
#include "wire/grpc_code_names.h"
#include "wire/map_settings_text.h"

namespace recog::cli {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;
using nlohmann::json;

constexpr int kMaxRobots = 1024;
constexpr size_t kMaxPrefix = 64;

double SecondsBetween(Clock::time_point from, Clock::time_point to) {
  return std::chrono::duration<double>(to - from).count();
}

// CPU time (user + system) this process has used so far, in seconds.
double ProcessCpuSeconds() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  const auto seconds = [](const timeval& t) { return double(t.tv_sec) + double(t.tv_usec) / 1e6; };
  return seconds(usage.ru_utime) + seconds(usage.ru_stime);
}

// The folder of a sequence's images: DIR/images for a `recog seqgen` output folder, else DIR.
std::string ImagesFolder(const std::string& dir) {
  std::error_code error;
  const fs::path images = fs::path(dir) / "images";
  return fs::is_directory(images, error) ? images.string() : dir;
}

// The frame a robot sends for the grey image `gray`: the bytes of its image file `path` (raw
// pixels without a file), or its ORB features.
StatusOr<pb::Frame> PrepareGrayFrame(const std::string& path, const cv::Mat& gray,
                                     bool features_on_client) {
  if (!features_on_client) {
    client::Result<pb::Frame> frame =
        path.empty() ? client::FrameFromImage(gray) : FrameFromImageFile(path, gray);
    if (!frame.ok()) return FromClient(frame.status());
    return std::move(frame).value();
  }
  client::Result<client::OrbFeatures> features = client::ExtractOrbFeatures(gray);
  if (!features.ok()) return FromClient(features.status());
  client::Result<pb::Frame> frame =
      client::FrameFromFeatures(features->keypoints, features->descriptors, gray.size());
  if (!frame.ok()) return FromClient(frame.status());
  return std::move(frame).value();
}

// The frame a robot sends for the image file `path`: its bytes, or its ORB features.
StatusOr<pb::Frame> PrepareFrame(const std::string& path, bool features_on_client) {
  RECOG_ASSIGN_OR_RETURN(const cv::Mat gray, ReadGrayImage(path));
  return PrepareGrayFrame(path, gray, features_on_client);
}

using Sequence = LoadGenerator::Sequence;

// The frames of a bag, ready to send, with their offsets in time (LoadOptions::bag_speed).
StatusOr<Sequence> PrepareBag(const LoadBag& bag, bool features_on_client) {
  RECOG_ASSIGN_OR_RETURN(FrameSource source,
                         FrameSource::OpenBag(bag.path, bag.topics, bag.options));
  const std::optional<CameraIntrinsics> camera = source.bag()->FrameCamera();
  RECOG_ASSIGN_OR_RETURN(const std::optional<double> baseline, source.bag()->StereoBaseline());
  Sequence sequence;
  sequence.folder = bag.path;
  sequence.bag = true;
  cv::Mat gray;
  std::string name;
  for (;;) {
    RECOG_ASSIGN_OR_RETURN(const bool more, source.Next(&gray, &name));
    if (!more) break;
    RECOG_ASSIGN_OR_RETURN(pb::Frame frame, PrepareGrayFrame("", gray, features_on_client));
    RECOG_ASSIGN_OR_RETURN(const cv::Mat depth, source.depth());
    RECOG_ASSIGN_OR_RETURN(const cv::Mat right, source.right());
    RECOG_RETURN_IF_ERROR(
        AttachBagGeometry(camera, baseline, depth, right, &frame).WithContext("frame " + name));
    sequence.files.push_back(name);
    sequence.frames.push_back(client::FrameStream::Prepare(std::move(frame)));
    sequence.offsets_s.push_back(*source.timestamp() - source.bag()->stamps().front());
  }
  const size_t n = sequence.offsets_s.size();
  const double last = sequence.offsets_s.back();
  sequence.pass_s = last + (n > 1 ? last / double(n - 1) : 1.0);
  return sequence;
}

// What --verify runs offline for a robot's sequence: the features of the folder's images, or of
// the bag's frames with the 3D points of their depth or right images when the robot sent them.
// The robots send no timestamps: tau_c counts frames offline too.
StatusOr<SequenceFeatures> OfflineFeatures(const std::string& folder,
                                           const std::optional<LoadBag>& bag, bool is_bag) {
  if (!is_bag) {
    RECOG_ASSIGN_OR_RETURN(FrameSource source, FrameSource::Open(folder));
    return ExtractSequence(source, PlaceFeatureOptions(), false);
  }
  RECOG_ASSIGN_OR_RETURN(FrameSource source,
                         FrameSource::OpenBag(bag->path, bag->topics, bag->options));
  std::optional<SequenceGeometryOptions> geometry;
  if (const std::optional<CameraIntrinsics> camera = source.bag()->FrameCamera()) {
    geometry.emplace();
    geometry->camera = *camera;
    geometry->depth_scale = 1.0 / 1000;  // 16UC1: millimetres
    RECOG_ASSIGN_OR_RETURN(const std::optional<double> baseline, source.bag()->StereoBaseline());
    geometry->baseline_m = baseline.value_or(0);
  }
  RECOG_ASSIGN_OR_RETURN(SequenceFeatures features,
                         ExtractSequence(source, PlaceFeatureOptions(), false, nullptr, geometry));
  features.timestamps.clear();
  return features;
}

// The run's clock: sample times are taken relative to `origin` (when the robots start setting
// up) and moved to the run's start once it is known.
struct RunClock {
  Clock::time_point origin = Clock::now();
  double At(Clock::time_point t) const { return SecondsBetween(origin, t); }
};

// A robot's answer to one frame of its first pass, for verification.
struct FirstPassAnswer {
  bool answered = false;  // without error
  std::string error;      // else why not
  bool loop = false;
  uint64_t match = 0;  // with `loop`
};

// One simulated robot: its map, its stream and what it measured.
//
// Setup, Run and Cleanup run on the robot's thread. Frames are sent by Pump, from whichever
// thread frees a slot or reaches a frame's time: the gRPC thread that delivers an answer (so that
// a robot sending as fast as it may costs no thread switch per frame), or the robot's thread,
// which wakes at the frames' times, at the end of the duration, to give up on a silent server,
// and to make the RecognizeObjects calls (those block: never on a gRPC thread).
class Robot {
 public:
  Robot(client::RecognitionClient& client, const LoadOptions& options, const Sequence& sequence,
        const pb::Frame* object_frame, const RunClock& clock, std::string map)
      : client_(client),
        options_(options),
        sequence_(sequence),
        object_frame_(object_frame),
        clock_(clock) {
    report_.map = std::move(map);
    report_.sequence = sequence.folder;
    paced_ = options.rate_hz > 0 || (options.bag_speed > 0 && sequence.bag);
    size_t first_pass = sequence.frames.size();
    if (options.frames > 0) first_pass = std::min<size_t>(first_pass, options.frames);
    first_pass_.resize(first_pass);
  }

  // Creates the map and opens the stream; on failure the robot will not run.
  void Setup() {
    const Clock::time_point sent = Clock::now();
    client::Result<pb::MapInfo> info = client_.CreateMap(report_.map);
    Record(create_, sent, info.status());
    if (!info.ok()) {
      Stop(kCreateMapRpc, info.status());
      return;
    }
    map_ = std::move(info).value();
    pb::StreamConfig config;
    config.set_map(report_.map);
    client::Result<std::unique_ptr<client::FrameStream>> stream =
        client::FrameStream::Open(client_, config);
    if (!stream.ok()) {
      Stop(kStreamFramesRpc, stream.status());
      return;
    }
    stream_ = std::move(stream).value();
  }

  // Sends the robot's frames from `start` on, then waits for their answers.
  void Run(Clock::time_point start, std::atomic<uint64_t>* answers) {
    if (stream_ == nullptr) return;
    answers_ = answers;
    start_ = start;
    if (options_.duration_s > 0) {
      end_ = start + std::chrono::duration_cast<Clock::duration>(
                         std::chrono::duration<double>(options_.duration_s));
    }
    Pump();
    std::unique_lock lock(mutex_);
    for (;;) {
      if (!objects_due_.empty()) {
        const uint64_t k = objects_due_.front();
        objects_due_.pop_front();
        lock.unlock();
        RecognizeObjects(k);
        lock.lock();
        continue;
      }
      if (over_) break;
      const Clock::time_point now = Clock::now();
      Clock::time_point wake = end_;
      if (in_flight_ < options_.in_flight) {
        wake = std::min(wake, Scheduled(next_));
      } else {
        const Clock::time_point give_up = last_answer_ + client_.options().deadline;
        if (now >= give_up) {
          lock.unlock();
          GiveUp();
          lock.lock();
          continue;
        }
        wake = std::min(wake, give_up);
      }
      if (now >= wake) {
        lock.unlock();
        Pump();
        lock.lock();
      } else {
        changed_.wait_until(lock, wake);
      }
    }
    // Sending is over: wait for the answers (at most the client's deadline without any).
    while (in_flight_ > 0) {
      const Clock::time_point give_up = last_answer_ + client_.options().deadline;
      if (Clock::now() >= give_up) {
        lock.unlock();
        GiveUp();
        lock.lock();
        break;
      }
      changed_.wait_until(lock, give_up);
    }
    lock.unlock();
    const grpc::Status closed = stream_->Close();
    finished_at_ = Clock::now();
    if (!closed.ok()) Stop(kStreamFramesRpc, closed);
  }

  // Deletes the map (unless the options keep it).
  void Cleanup() {
    if (!map_.has_value() || options_.keep_maps) return;
    const Clock::time_point sent = Clock::now();
    Record(delete_, sent, client_.DeleteMap(report_.map).status());
  }

  // Compares the first pass with `offline`, the offline detector's results for the sequence with
  // the map's settings; `vocabulary_checksum` is the offline vocabulary's.
  Verification Verify(const std::vector<LoopResult>& offline,
                      const std::string& vocabulary_checksum) const {
    Verification v;
    if (!map_.has_value()) {
      v.detail = "the robot did not run (" + report_.failed_rpc + ": " +
                 DescribeStatus(report_.status) + ")";
      return v;
    }
    if (map_->vocabulary_checksum() != vocabulary_checksum) {
      v.detail = "the map's vocabulary " + map_->vocabulary_checksum() +
                 " is not the bundled place vocabulary " + vocabulary_checksum;
      return v;
    }
    const size_t compared = std::min<size_t>(first_pass_.size(), report_.frames_sent);
    const auto name = [&](uint64_t i) {
      return fs::path(sequence_.files[size_t(i)]).filename().string();
    };
    int differences = 0;
    for (size_t i = 0; i < compared; ++i) {
      const FirstPassAnswer& online = first_pass_[i];
      const LoopResult& r = offline[i];
      const bool offline_loop = r.status == LoopStatus::kLoopDetected;
      v.offline_loops += offline_loop;
      v.server_loops += online.loop;
      std::string difference;
      if (!online.answered) {
        difference = name(i) + " was not answered (" + online.error + ")";
      } else if (online.loop != offline_loop || (offline_loop && online.match != r.match)) {
        const auto describe = [&](bool loop, uint64_t match) {
          return loop ? "a loop with " + name(match) : std::string("no loop");
        };
        difference = name(i) + ": the server found " + describe(online.loop, online.match) +
                     ", the offline detector " + describe(offline_loop, r.match);
      }
      if (!difference.empty() && differences++ == 0) v.detail = difference;
    }
    v.frames_compared = int(compared);
    v.ok = differences == 0 && compared > 0;
    if (compared == 0) v.detail = "no frame was sent";
    if (differences > 1) v.detail += " (and " + std::to_string(differences - 1) + " more)";
    return v;
  }

  const std::optional<pb::MapInfo>& map() const { return map_; }
  bool is_bag() const { return sequence_.bag; }
  const RobotReport& report() const { return report_; }
  Clock::time_point finished_at() const { return finished_at_; }
  const RpcStats& stats(const std::string& rpc) const {
    if (rpc == kCreateMapRpc) return create_;
    if (rpc == kStreamFramesRpc) return frames_;
    if (rpc == kRecognizeObjectsRpc) return objects_;
    return delete_;
  }

 private:
  // When frame k is due.
  Clock::time_point Scheduled(uint64_t k) const {
    if (options_.bag_speed > 0 && sequence_.bag) {
      const size_t n = sequence_.offsets_s.size();
      const double at = double(k / n) * sequence_.pass_s + sequence_.offsets_s[size_t(k % n)];
      return start_ + std::chrono::duration_cast<Clock::duration>(
                          std::chrono::duration<double>(at / options_.bag_speed));
    }
    if (options_.rate_hz <= 0) return start_;
    return start_ + std::chrono::duration_cast<Clock::duration>(
                        std::chrono::duration<double>(double(k) / options_.rate_hz));
  }

  // Sends what is due, from any thread. One thread sends at a time, so that frames leave in
  // order; a call while another thread sends (or from inside a Send on the same thread) leaves
  // the work to that thread, which looks again before it stops.
  void Pump() {
    pump_requested_ = true;
    bool idle = false;
    while (pump_requested_ && sending_.compare_exchange_strong(idle, true)) {
      pump_requested_ = false;
      SendDue();
      sending_ = false;
      idle = false;
    }
  }

  // Sends frames while one is due and a slot is free; marks the sending over at the end.
  void SendDue() {
    for (;;) {
      uint64_t k = 0;
      Clock::time_point sent;
      {
        std::lock_guard lock(mutex_);
        if (over_) return;
        sent = Clock::now();
        if (sent >= end_ || (options_.frames > 0 && next_ == options_.frames)) {
          over_ = true;
          changed_.notify_all();
          return;
        }
        if (in_flight_ >= options_.in_flight || Scheduled(next_) > sent) return;
        k = next_++;
        if (in_flight_++ == 0) last_answer_ = sent;  // the wait for an answer starts now
        ++report_.frames_sent;
        if (options_.objects_every > 0 && k % options_.objects_every == 0) {
          objects_due_.push_back(k);
          changed_.notify_all();
        }
      }
      stream_->Send(sequence_.frames[size_t(k % sequence_.frames.size())],
                    [this, k, sent](client::FrameStream::Answer answer) {
                      OnAnswer(k, sent, std::move(answer));
                    });
    }
  }

  // Records the first reason the robot stopped.
  void Stop(const char* rpc, const grpc::Status& status) {
    std::lock_guard lock(stop_mutex_);
    if (!report_.status.ok()) return;
    report_.failed_rpc = rpc;
    report_.status = status;
  }

  // Cancels a stream that stopped answering: its frames in flight get CANCELLED.
  void GiveUp() {
    Stop(kStreamFramesRpc, {grpc::StatusCode::DEADLINE_EXCEEDED,
                            "no answer for " + std::to_string(client_.options().deadline.count()) +
                                " ms: the stream was cancelled"});
    {
      std::lock_guard lock(mutex_);
      over_ = true;
    }
    stream_->Cancel();
  }

  void OnAnswer(uint64_t k, Clock::time_point sent, client::FrameStream::Answer answer) {
    const Clock::time_point now = Clock::now();
    bool wake_robot = false;
    {
      std::lock_guard lock(mutex_);
      // The robot's thread waits for this answer when sending is over, or at a rate when the
      // slot frees up for a frame not yet due (at rate 0, Pump below sends it right away).
      wake_robot = over_ || (paced_ && in_flight_ == options_.in_flight);
      --in_flight_;
      last_answer_ = now;
      FirstPassAnswer* first = k < first_pass_.size() ? &first_pass_[size_t(k)] : nullptr;
      if (!answer.ok()) {
        ++frames_.errors[std::string(GrpcCodeName(answer.status().error_code()))];
        if (first != nullptr) first->error = DescribeStatus(answer.status());
        if (!over_) {
          over_ = true;  // the stream failed: nothing more can be sent
          wake_robot = true;
          Stop(kStreamFramesRpc, answer.status());
        }
      } else if (answer->has_error()) {
        const grpc::StatusCode code = grpc::StatusCode(answer->error().code());
        ++frames_.errors[std::string(GrpcCodeName(code))];
        if (first != nullptr) {
          first->error = DescribeStatus(grpc::Status(code, answer->error().message()));
        }
      } else {
        ++frames_.ok;
        ++report_.frames_answered;
        frames_.samples.push_back({clock_.At(sent), SecondsBetween(sent, now) * 1000});
        const pb::LoopResult& result = answer->result();
        const bool loop = result.status() == pb::LOOP_STATUS_LOOP_DETECTED;
        report_.loops += loop;
        if (first != nullptr) {
          first->answered = true;
          first->loop = loop;
          first->match = result.match_frame_id();
        }
      }
      if (wake_robot) changed_.notify_all();
    }
    ++*answers_;
    Pump();
  }

  // RecognizeObjects on frame k (or on the object image), on the robot's thread.
  void RecognizeObjects(uint64_t k) {
    pb::Frame frame;
    if (object_frame_ != nullptr) {
      frame = *object_frame_;
    } else {
      frame = sequence_.frames[size_t(k % sequence_.frames.size())]->frame();
      SetIntrinsics(*options_.camera, &frame);
    }
    const Clock::time_point sent = Clock::now();
    Record(objects_, sent, client_.RecognizeObjects(frame).status());
  }

  // Counts one unary call sent at `sent` and answered now with `status`.
  void Record(RpcStats& stats, Clock::time_point sent, const grpc::Status& status) const {
    if (status.ok()) {
      ++stats.ok;
      stats.samples.push_back({clock_.At(sent), SecondsBetween(sent, Clock::now()) * 1000});
    } else {
      ++stats.errors[std::string(GrpcCodeName(status.error_code()))];
    }
  }

  client::RecognitionClient& client_;
  const LoadOptions& options_;
  const Sequence& sequence_;
  const pb::Frame* const object_frame_;  // null: the robot's current frame
  const RunClock& clock_;
  bool paced_ = false;              // frames go at their times (rate or bag), not at once
  std::optional<pb::MapInfo> map_;  // once created
  std::unique_ptr<client::FrameStream> stream_;
  std::atomic<uint64_t>* answers_ = nullptr;          // every robot's answers, for progress
  Clock::time_point start_;                           // of the run
  Clock::time_point end_ = Clock::time_point::max();  // of the duration
  Clock::time_point finished_at_;                     // when Run returned
  RpcStats create_, objects_, delete_;                // the robot's thread's

  std::atomic<bool> sending_{false};         // a thread is in SendDue
  std::atomic<bool> pump_requested_{false};  // SendDue must look again

  std::mutex stop_mutex_;  // guards report_.failed_rpc and report_.status

  std::mutex mutex_;  // guards what the stream's answers change, below
  std::condition_variable changed_;
  uint64_t next_ = 0;  // the next frame to send
  uint32_t in_flight_ = 0;
  bool over_ = false;                 // no more frames will be sent
  Clock::time_point last_answer_;     // or when the oldest frame in flight was sent
  std::deque<uint64_t> objects_due_;  // frames whose RecognizeObjects call is due
  RpcStats frames_;
  RobotReport report_;
  std::vector<FirstPassAnswer> first_pass_;
};

}  // namespace

Status LoadOptions::Validate() const {
  if (sequences.empty() && !bag.has_value()) {
    return Status::InvalidArgument("--sequences: name at least one folder (or a --bag)");
  }
  if (robots < 1 || robots > kMaxRobots) {
    return Status::InvalidArgument("--robots must be between 1 and " + std::to_string(kMaxRobots) +
                                   ", not " + std::to_string(robots));
  }
  const bool by_duration = duration_s != 0;
  if ((frames > 0) == by_duration) {
    return Status::InvalidArgument("give either --frames N or --duration S (exactly one)");
  }
  if (by_duration && !(std::isfinite(duration_s) && duration_s > 0)) {
    return Status::InvalidArgument("--duration must be a positive number of seconds");
  }
  if (!(std::isfinite(rate_hz) && rate_hz >= 0)) {
    return Status::InvalidArgument("--rate must be 0 (as fast as possible) or a positive rate");
  }
  if (!(std::isfinite(bag_speed) && bag_speed >= 0)) {
    return Status::InvalidArgument("--bag-speed must be 0 or a positive factor");
  }
  if (bag_speed > 0 && (!bag.has_value() || rate_hz > 0)) {
    return Status::InvalidArgument("--bag-speed goes with --bag, without --rate");
  }
  if (in_flight < 1) return Status::InvalidArgument("--in-flight must be at least 1");
  const bool bag_camera = bag.has_value() && !bag->topics.camera_info.empty();
  if (objects_every > 0 && !camera.has_value() && !bag_camera) {
    return Status::InvalidArgument(
        "--objects-every needs --camera fx,fy,cx,cy (or a bag's --camera-info-topic)");
  }
  if (objects_every == 0 && (camera.has_value() || !object_image.empty())) {
    return Status::InvalidArgument("--camera and --object-image go with --objects-every");
  }
  if (camera.has_value()) RECOG_RETURN_IF_ERROR(camera->Validate());
  const bool prefix_ok = !map_prefix.empty() && map_prefix.size() <= kMaxPrefix &&
                         std::all_of(map_prefix.begin(), map_prefix.end(), [](unsigned char c) {
                           return std::isalnum(c) || c == '.' || c == '_' || c == '-';
                         });
  if (!prefix_ok) {
    return Status::InvalidArgument("--map-prefix must be 1 to " + std::to_string(kMaxPrefix) +
                                   " characters of [A-Za-z0-9._-]");
  }
  return Status::Ok();
}

uint64_t RpcStats::ErrorCount() const {
  uint64_t count = 0;
  for (const auto& [code, n] : errors) count += n;
  return count;
}

double RpcStats::LatencyPercentile(double percentile) const {
  if (samples.empty()) return 0;
  std::vector<double> sorted;
  sorted.reserve(samples.size());
  for (const LatencySample& s : samples) sorted.push_back(s.latency_ms);
  std::sort(sorted.begin(), sorted.end());
  const size_t rank = size_t(std::ceil(percentile / 100 * double(sorted.size())));
  return sorted[std::clamp<size_t>(rank, 1, sorted.size()) - 1];
}

void RpcStats::Merge(const RpcStats& other) {
  ok += other.ok;
  for (const auto& [code, n] : other.errors) errors[code] += n;
  samples.insert(samples.end(), other.samples.begin(), other.samples.end());
}

std::optional<double> LoadReport::PerSecond(const std::string& rpc) const {
  if (rpc != kStreamFramesRpc && rpc != kRecognizeObjectsRpc) return std::nullopt;
  const auto found = rpcs.find(rpc);
  if (found == rpcs.end() || wall_s <= 0) return 0.0;
  return double(found->second.ok) / wall_s;
}

double LoadReport::FramesPerSecond() const {
  return wall_s > 0 ? double(frames_answered) / wall_s : 0;
}

double LoadReport::ClientCpuMsPerFrame() const {
  return frames_sent > 0 ? client_cpu_s * 1000 / double(frames_sent) : 0;
}

double LoadReport::GeneratorCapacity() const {
  const double ms = ClientCpuMsPerFrame();
  return ms > 0 ? 1000 / ms : 0;
}

double LoadReport::CapacityRatio() const {
  const double served = FramesPerSecond();
  return served > 0 ? GeneratorCapacity() / served : 0;
}

bool LoadReport::Verified() const {
  return std::all_of(robots.begin(), robots.end(), [](const RobotReport& r) {
    return !r.verification.has_value() || r.verification->ok;
  });
}

StatusOr<LoadGenerator> LoadGenerator::Prepare(const LoadOptions& options) {
  RECOG_RETURN_IF_ERROR(options.Validate());
  LoadGenerator load;
  load.options_ = options;
  load.sequences_.resize(options.sequences.size());
  for (size_t s = 0; s < options.sequences.size(); ++s) {
    Sequence& sequence = load.sequences_[s];
    sequence.folder = ImagesFolder(options.sequences[s]);
    RECOG_ASSIGN_OR_RETURN(sequence.files, ListImages(sequence.folder));
    for (const std::string& file : sequence.files) {
      RECOG_ASSIGN_OR_RETURN(pb::Frame frame, PrepareFrame(file, options.features_on_client));
      sequence.frames.push_back(client::FrameStream::Prepare(std::move(frame)));
    }
  }
  if (options.bag.has_value()) {
    RECOG_ASSIGN_OR_RETURN(Sequence bag, PrepareBag(*options.bag, options.features_on_client));
    load.sequences_.push_back(std::move(bag));
    if (options.objects_every > 0 && !options.camera.has_value()) {
      RECOG_ASSIGN_OR_RETURN(
          RosBagReader reader,
          RosBagReader::Open(options.bag->path, options.bag->topics, options.bag->options));
      load.options_.camera = reader.FrameCamera();
    }
  }
  if (!options.object_image.empty()) {
    RECOG_ASSIGN_OR_RETURN(load.object_frame_,
                           PrepareFrame(options.object_image, options.features_on_client));
    SetIntrinsics(*options.camera, &*load.object_frame_);
  }
  return load;
}

StatusOr<LoadReport> LoadGenerator::Run(
    client::RecognitionClient& client,
    const std::function<void(uint64_t, uint64_t)>& progress) const {
  if (options_.in_flight > client.options().max_frames_in_flight) {
    return Status::InvalidArgument("--in-flight must be at most the client's " +
                                   std::to_string(client.options().max_frames_in_flight));
  }
  LoadReport report;
  report.run_id = std::to_string(std::chrono::duration_cast<std::chrono::seconds>(
                                     std::chrono::system_clock::now().time_since_epoch())
                                     .count()) +
                  "-" + std::to_string(getpid());
  const RunClock clock;
  std::vector<std::unique_ptr<Robot>> robots;
  for (int i = 0; i < options_.robots; ++i) {
    robots.push_back(std::make_unique<Robot>(
        client, options_, sequences_[size_t(i) % sequences_.size()],
        object_frame_.has_value() ? &*object_frame_ : nullptr, clock,
        options_.map_prefix + "-" + report.run_id + "-" + std::to_string(i)));
  }

  // Setup on every robot's thread at once, then the run, then the cleanup.
  const auto n = std::ptrdiff_t(robots.size());
  std::latch ready(n), finished(n), go(1), cleanup(1);
  Clock::time_point start;
  std::atomic<uint64_t> answers{0};
  std::vector<std::jthread> threads;
  for (const std::unique_ptr<Robot>& robot : robots) {
    threads.emplace_back([&, r = robot.get()] {
      r->Setup();
      ready.count_down();
      go.wait();
      r->Run(start, &answers);
      finished.count_down();
      cleanup.wait();
      r->Cleanup();
    });
  }
  ready.wait();
  const double cpu_before = ProcessCpuSeconds();
  start = Clock::now();
  go.count_down();
  const auto duration_ms = uint64_t(options_.duration_s * 1000);
  const auto report_progress = [&] {
    if (!progress) return;
    if (options_.frames > 0) {
      progress(answers.load(), options_.frames * uint64_t(options_.robots));
    } else {
      const auto elapsed = uint64_t(SecondsBetween(start, Clock::now()) * 1000);
      progress(std::min(elapsed, duration_ms), duration_ms);
    }
  };
  while (!finished.try_wait()) {
    report_progress();
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  report_progress();
  report.client_cpu_s = ProcessCpuSeconds() - cpu_before;
  Clock::time_point end = start;
  for (const std::unique_ptr<Robot>& robot : robots) end = std::max(end, robot->finished_at());
  report.wall_s = SecondsBetween(start, end);
  cleanup.count_down();
  threads.clear();  // joins, after the maps are deleted

  // Sample times from the start of the run.
  const double shift = clock.At(start);
  for (const std::unique_ptr<Robot>& robot : robots) {
    for (const char* rpc : {kCreateMapRpc, kStreamFramesRpc, kRecognizeObjectsRpc, kDeleteMapRpc}) {
      RpcStats stats = robot->stats(rpc);
      if (stats.ok + stats.ErrorCount() == 0) continue;
      for (LatencySample& sample : stats.samples) sample.at_s -= shift;
      report.rpcs[rpc].Merge(stats);
    }
    const RobotReport& r = robot->report();
    const RpcStats& objects = robot->stats(kRecognizeObjectsRpc);
    report.frames_sent += r.frames_sent + objects.ok + objects.ErrorCount();
    report.frames_answered += r.frames_answered + objects.ok;
    report.loops += r.loops;
    report.robots.push_back(r);
  }

  if (options_.verify) {
    // What `recog eval place` runs, once per sequence and map settings.
    RECOG_ASSIGN_OR_RETURN(Vocabulary vocabulary, LoadAnyVocabulary(DefaultPlaceVocabularyPath()));
    const std::string checksum = HexChecksum(vocabulary.checksum());
    const auto shared = std::make_shared<const Vocabulary>(std::move(vocabulary));
    std::map<std::string, SequenceFeatures> features;  // by folder (or bag)
    std::map<std::pair<std::string, std::string>, std::vector<LoopResult>> offline;
    const std::vector<LoopResult> none;  // for robots without a map, which Verify refuses
    for (size_t i = 0; i < robots.size(); ++i) {
      const Robot& robot = *robots[i];
      const std::string& folder = robot.report().sequence;
      const std::vector<LoopResult>* results = &none;
      if (robot.map().has_value()) {
        if (!features.contains(folder)) {
          RECOG_ASSIGN_OR_RETURN(features[folder],
                                 OfflineFeatures(folder, options_.bag, robot.is_bag()));
        }
        const pb::MapSettings& settings = robot.map()->settings();
        const auto key = std::make_pair(folder, settings.SerializeAsString());
        if (!offline.contains(key)) {
          RECOG_ASSIGN_OR_RETURN(PlaceEvaluationOptions offline_options,
                                 OfflineDetectorOptions(settings));
          RECOG_ASSIGN_OR_RETURN(offline[key],
                                 DetectLoops(features[folder], shared, offline_options));
        }
        results = &offline[key];
      }
      report.robots[i].verification = robot.Verify(*results, checksum);
    }
  }
  return report;
}

StatusOr<PlaceEvaluationOptions> OfflineDetectorOptions(const pb::MapSettings& settings) {
  PlaceEvaluationOptions options;
  std::vector<NamedSetting> values;
  const std::string unknown = MapSettingsAsText(settings, MapDetectorSettingNames(), &values);
  if (!unknown.empty()) return Status::Internal("MapSettings and the settings table: " + unknown);
  RECOG_RETURN_IF_ERROR(ApplyDetectorSettings(values, &options.detector));
  return options;
}

json LoadReportJson(const LoadReport& report) {
  json rpcs = json::object();
  for (const auto& [name, stats] : report.rpcs) {
    json rpc = {{"ok", stats.ok},
                {"errors", stats.errors},
                {"latency_ms",
                 {{"p50", stats.LatencyPercentile(50)},
                  {"p90", stats.LatencyPercentile(90)},
                  {"p99", stats.LatencyPercentile(99)},
                  {"max", stats.LatencyPercentile(100)}}}};
    if (const std::optional<double> per_s = report.PerSecond(name)) rpc["per_s"] = *per_s;
    rpcs[name] = std::move(rpc);
  }
  json robots = json::array();
  for (const RobotReport& r : report.robots) {
    json robot = {
        {"map", r.map},
        {"sequence", r.sequence},
        {"frames_sent", r.frames_sent},
        {"frames_answered", r.frames_answered},
        {"loops", r.loops},
        {"status", r.status.ok() ? "OK" : r.failed_rpc + ": " + DescribeStatus(r.status)}};
    if (r.verification.has_value()) {
      const Verification& v = *r.verification;
      robot["verification"] = {{"ok", v.ok},
                               {"frames_compared", v.frames_compared},
                               {"server_loops", v.server_loops},
                               {"offline_loops", v.offline_loops},
                               {"detail", v.detail}};
    }
    robots.push_back(std::move(robot));
  }
  return {{"run_id", report.run_id},
          {"wall_s", report.wall_s},
          {"frames_sent", report.frames_sent},
          {"frames_answered", report.frames_answered},
          {"frames_per_s", report.FramesPerSecond()},
          {"loops", report.loops},
          {"rpcs", rpcs},
          {"client",
           {{"cpu_s", report.client_cpu_s},
            {"cpu_ms_per_frame", report.ClientCpuMsPerFrame()},
            {"capacity_frames_per_s_per_core", report.GeneratorCapacity()},
            {"capacity_over_server_throughput", report.CapacityRatio()}}},
          {"verified", report.Verified()},
          {"robots", robots}};
}

Status WriteLatencyPlot(const LoadReport& report, const std::string& path) {
  constexpr int kSlices = 40;
  const double slice_s = std::max(report.wall_s, 1e-3) / kSlices;
  struct Style {
    const char* rpc;
    cv::Scalar p50, p99;  // BGR
  };
  const Style styles[] = {{kStreamFramesRpc, {200, 80, 20}, {240, 180, 120}},
                          {kRecognizeObjectsRpc, {40, 40, 220}, {140, 140, 250}}};
  std::vector<PlotSeries> series;
  double y_max = 0;
  for (const Style& style : styles) {
    const auto found = report.rpcs.find(style.rpc);
    if (found == report.rpcs.end() || found->second.samples.empty()) continue;
    std::vector<RpcStats> slices(kSlices);
    for (const LatencySample& s : found->second.samples) {
      slices[std::clamp(int(s.at_s / slice_s), 0, kSlices - 1)].samples.push_back(s);
    }
    PlotSeries p50{std::string(style.rpc) + " p50", {}, style.p50, {}};
    PlotSeries p99{std::string(style.rpc) + " p99", {}, style.p99, {}};
    for (int i = 0; i < kSlices; ++i) {
      if (slices[size_t(i)].samples.empty()) continue;
      const double x = (i + 0.5) * slice_s;
      p50.points.push_back({x, slices[size_t(i)].LatencyPercentile(50)});
      p99.points.push_back({x, slices[size_t(i)].LatencyPercentile(99)});
      y_max = std::max(y_max, p99.points.back().y);
    }
    series.push_back(std::move(p99));
    series.push_back(std::move(p50));
  }
  if (series.empty()) return Status::InvalidArgument("no answer to plot");
  PlotOptions plot;
  plot.title = "recog load: latency over the run (" + std::to_string(report.robots.size()) +
               " robots), p50 and p99 per slice of " + std::to_string(int(slice_s * 1000)) + " ms";
  plot.x_label = "seconds since the start";
  plot.y_label = "latency (ms)";
  plot.x_max = std::max(report.wall_s, 1e-3);
  plot.y_max = std::max(y_max * 1.1, 1.0);
  plot.width = 1000;
  return WritePlot(path, plot, series);
}

}  // namespace recog::cli
