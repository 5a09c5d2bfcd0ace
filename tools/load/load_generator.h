// The load generator behind `recog load`: simulated robots that replay recorded image sequences
// into recogd, each through its own StreamFrames stream into its own fresh map, and what they
// measured.
//
// Robot i replays sequence i % (number of sequences): the images of a folder in natural order
// (ListImages), or of OUT/images for a folder written by `recog seqgen`, the folders first, then
// the ROS 1 bag when there is one (its image topic in stamp order, ros_bag.h). Frames are
// prepared before the run, so that reading and encoding cost nothing while it lasts: the files'
// own bytes when they are JPEG or PNG (other formats, and a bag's frames, as raw grey pixels), or,
// with features_on_client, the ORB features client::ExtractOrbFeatures computes from them (the
// server's defaults, so the map answers alike); a bag's frames carry the intrinsics of its camera
// info, with its depth or right images (AttachBagGeometry, remote_support.h). A robot loops over
// its sequence when it needs more frames, and sends frame k at start + k / rate (as soon as
// possible when rate is 0), or, with bag_speed, at the bag's own pace (the frames' stamps from the
// first, divided by bag_speed; each pass over the bag one mean frame interval after the last
// frame), but never more than `in_flight` frames ahead of their answers. For every objects_every-th
// frame (frames 0, K, 2K, ...) the robot also calls RecognizeObjects with the camera's intrinsics,
// on that frame or on object_image, one call at a time on a thread of its own, while its stream
// goes on.
//
// Phases: every robot creates its map `<map_prefix>-<run id>-<i>` (CreateMap with the server's
// default settings) and opens its stream; then all start together (the run: its wall time, the
// throughputs and the client's CPU time cover this phase only); each stops after `frames` frames
// or `duration` seconds and waits for its answers; then the maps are deleted (DeleteMap, unless
// keep_maps). A robot whose map cannot be created does not run; a robot whose stream fails stops
// (streams are not retried). Nothing waits forever: a robot that gets no answer for the client's
// deadline (ClientOptions::deadline) cancels its stream, and its unanswered frames count as
// CANCELLED errors.
//
// All robots share the client (one channel: one HTTP/2 connection, a stream per robot). Latency
// is the time from handing a request to the client library (FrameStream::Send, or the
// RecognizeObjects call, retries included) to its answer, so it includes the wait behind the
// robot's own frames in flight: the server answers a stream's frames one at a time.
//
// The generator's own cost is the CPU time (user + system, getrusage) of this process during the
// run, per frame sent; the server runs in another process. Its inverse is the frames one core of
// this machine could generate per second, to compare with the frames per second the server
// answered: when it is several times larger, the figures measure the server, not the generator.
//
// Verification: the first pass of each robot over its sequence must give the loops the offline
// loop detector finds (what `recog eval place` runs: FrameSource, ExtractSequence with the default
// features, DetectLoops over an in-memory database with the bundled place vocabulary), with the
// settings the server reports for the robot's map. Map frame ids are the frame indices, as each
// map is fresh and gets its sequence in order from frame 0. Only the frames of the first pass that
// were sent are compared (a detection depends on the frames before it only).
#pragma once

#include <cstdint>
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "client/cpp/frame_stream.h"
#include "client/cpp/recognition_client.h"
#include "core/common/status.h"
#include "core/object/model/object_model.h"
#include "recognition/v1/common.pb.h"
#include "tools/evaluation/place_evaluation.h"
#include "tools/evaluation/ros_bag.h"

namespace recog::cli {

namespace pb = ::recognition::v1;

// A ROS 1 bag replayed by the robots (`recog load --bag`).
struct LoadBag {
  std::string path;
  BagTopics topics;
  BagReadOptions options;
};

struct LoadOptions {
  // Folders of images (or `recog seqgen` output folders); at least one, or a bag.
  std::vector<std::string> sequences;
  // Default none: a bag replayed as one more sequence.
  std::optional<LoadBag> bag;
  // Simulated robots, 1 to 1024.
  int robots = 1;
  // Exactly one of these bounds each robot's run: frames to send (> 0), or seconds (> 0).
  uint64_t frames = 0;
  double duration_s = 0;
  // Frames per second per robot; default 0: as fast as the in_flight bound allows.
  double rate_hz = 0;
  // Default 0: frames go at rate_hz. > 0 (with a bag, without rate_hz): a robot replaying the bag
  // sends its frames at bag_speed times the pace of their stamps (1: as recorded).
  double bag_speed = 0;
  // Default 4: frames a robot may have sent and not yet had answered, 1 to the client's
  // max_frames_in_flight.
  uint32_t in_flight = 4;
  // Default false: send the files' bytes. true: send ORB features extracted before the run.
  bool features_on_client = false;
  // Default 0: no object recognition. K > 0: RecognizeObjects on frames 0, K, 2K, ... of each
  // robot, which needs `camera`.
  uint32_t objects_every = 0;
  // Default none: the intrinsics sent with the RecognizeObjects frames (only with objects_every).
  std::optional<CameraIntrinsics> camera;
  // Default "": recognise objects on the robot's current frame; else on this image.
  std::string object_image;
  // Default false: compare each robot's loops with the offline detector (header comment).
  bool verify = false;
  // Default "load": maps are named <map_prefix>-<run id>-<robot>. 1 to 64 characters of
  // [A-Za-z0-9._-].
  std::string map_prefix = "load";
  // Default false: delete the maps at the end.
  bool keep_maps = false;

  // INVALID_ARGUMENT naming the first bad option (files are checked when they are read).
  Status Validate() const;
};

// The RPCs a robot calls, in the order of its life: the keys of LoadReport::rpcs.
inline constexpr char kCreateMapRpc[] = "CreateMap";
inline constexpr char kStreamFramesRpc[] = "StreamFrames";  // one call per frame in the stats
inline constexpr char kRecognizeObjectsRpc[] = "RecognizeObjects";
inline constexpr char kDeleteMapRpc[] = "DeleteMap";

// One latency measurement: when the request was sent (seconds since the start of the run;
// negative for map creation, before it) and how long its answer took.
struct LatencySample {
  double at_s = 0;
  double latency_ms = 0;
};

// What one RPC saw: CreateMap, StreamFrames (one entry per frame), RecognizeObjects, DeleteMap.
struct RpcStats {
  uint64_t ok = 0;                         // answered without error
  std::map<std::string, uint64_t> errors;  // by gRPC code name ("UNAVAILABLE")
  std::vector<LatencySample> samples;      // of the answers without error

  uint64_t ErrorCount() const;
  // Nearest-rank percentile (0..100) of the latencies in ms; 0 without samples.
  double LatencyPercentile(double percentile) const;
  void Merge(const RpcStats& other);
};

// Each robot's first pass compared with the offline detector.
struct Verification {
  bool ok = false;
  int frames_compared = 0;
  int server_loops = 0;   // loops the server detected in those frames
  int offline_loops = 0;  // loops the offline detector detected in them
  std::string detail;     // the first difference, or why nothing could be compared
};

struct RobotReport {
  std::string map;
  std::string sequence;  // the folder of images
  uint64_t frames_sent = 0;
  uint64_t frames_answered = 0;  // answered without error
  uint64_t loops = 0;            // answers with a verified loop
  // Why the robot did not run or stopped early: the RPC that failed (CreateMap or StreamFrames)
  // and its status (DEADLINE_EXCEEDED when the stream was cancelled for want of answers). Empty
  // and OK when it ran to the end.
  std::string failed_rpc;
  grpc::Status status;
  std::optional<Verification> verification;  // with LoadOptions::verify
};

struct LoadReport {
  std::string run_id;
  double wall_s = 0;                     // the run: from the common start to the last answer
  std::map<std::string, RpcStats> rpcs;  // by RPC name; only those that were called
  uint64_t frames_sent = 0;              // StreamFrames frames and RecognizeObjects calls
  uint64_t frames_answered = 0;          // of those, answered without error
  uint64_t loops = 0;
  double client_cpu_s = 0;  // CPU time (user + system) of this process during the run
  std::vector<RobotReport> robots;

  // Answers without error per second of the run of an RPC of the run (StreamFrames,
  // RecognizeObjects); nullopt for the others (map creation and deletion are outside the run).
  std::optional<double> PerSecond(const std::string& rpc) const;
  // The server's throughput: frames answered per second of the run (a RecognizeObjects call is a
  // frame too).
  double FramesPerSecond() const;
  // The generator's cost: its CPU milliseconds per frame sent; 0 when none was sent.
  double ClientCpuMsPerFrame() const;
  // The frames one core could send at that cost, per second (0 when unknown).
  double GeneratorCapacity() const;
  // GeneratorCapacity() / FramesPerSecond(): how far the generator is from being the bottleneck.
  double CapacityRatio() const;
  // Whether every robot's verification passed (true without verification).
  bool Verified() const;
};

// A load ready to run: its options, and every frame read and prepared, so that reading and
// encoding cost nothing during the run. Prepare before connecting the client, so that its first
// calls follow Connect() at once: a channel whose first connection attempt nobody polled within
// the client's reconnect backoff (100 ms; e.g. while this thread extracted features) stays in
// TRANSIENT_FAILURE, and the client's changing calls (CreateMap) then fail with UNAVAILABLE.
class LoadGenerator {
 public:
  // INVALID_ARGUMENT for bad options; the errors of reading the images (NOT_FOUND for a missing
  // folder or file, INVALID_ARGUMENT for one that is not an image).
  static StatusOr<LoadGenerator> Prepare(const LoadOptions& options);

  // Runs the load on `client`'s server. `progress(done, total)` (optional) is called from this
  // thread about ten times a second during the run: frames answered of frames to send, or
  // milliseconds elapsed of the duration. INVALID_ARGUMENT when in_flight exceeds the client's
  // max_frames_in_flight; the errors of the offline run of --verify. Failed RPCs are counted in
  // the report, not returned.
  StatusOr<LoadReport> Run(client::RecognitionClient& client,
                           const std::function<void(uint64_t, uint64_t)>& progress = {}) const;

  // One sequence, ready to send.
  struct Sequence {
    std::string folder;                                      // of the images, or the bag
    std::vector<std::string> files;                          // in natural order; a bag's names
    std::vector<client::FrameStream::PreparedFrame> frames;  // one per file
    bool bag = false;
    // A bag's frames: seconds from the first frame's stamp, and one pass over the bag (the last
    // offset and a mean frame interval).
    std::vector<double> offsets_s;
    double pass_s = 0;
  };

 private:
  LoadOptions options_;
  std::vector<Sequence> sequences_;
  std::optional<pb::Frame> object_frame_;  // with the intrinsics
};

// The offline detector that --verify compares a robot's answers with, for a map with `settings`
// (every field set, as MapInfo has them): its preset, with the settings the map keeps over it
// (core/place/detector_settings.h), as recogd runs it.
StatusOr<PlaceEvaluationOptions> OfflineDetectorOptions(const pb::MapSettings& settings);

// The report as JSON: run, per-RPC counts, throughput, latency percentiles and errors, loops,
// client CPU and capacity, robots with their verification.
nlohmann::json LoadReportJson(const LoadReport& report);

// Latency over the run (x: seconds since the start, y: ms): the median and the 99th percentile of
// each of 40 time slices, per RPC of the run. INVALID_ARGUMENT when nothing was answered.
Status WriteLatencyPlot(const LoadReport& report, const std::string& path);

}  // namespace recog::cli
