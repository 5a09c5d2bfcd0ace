// What reading a bag costs beyond decoding its images (tools/evaluation/ros_bag.h): 40 frames of
// 640 x 480 (the bundled corridor frames, enlarged and shifted) in a bag per storage and encoding,
// the k-th stamped 1000 + k/30 s (header stamp and log time), written at start:
//  - ROS 1: by Debian's python3-rosbag (tests/testing/write_bag.py), uncompressed;
//  - ROS 2, each a rosbag2 folder (metadata.yaml version 5 and one file) written by the
//    test-support writer tests/testing/ros2_bag_writer.h, the frames sensor_msgs/msg/Image
//    (mono8, rgb8) or CompressedImage (jpeg, png) in little-endian CDR:
//      mcap_zstd, mcap_lz4  MCAP, chunks of rosbag2's default size (closed once their records
//                           reach 768 KiB: 1 rgb8 frame, 3 mono8, 3 PNG or 16-17 JPEG frames a
//                           chunk) compressed with zstd or lz4 (every chunk compressed, also those
//                           that do not shrink, which the MCAP library would store as they are);
//                           message indexes, chunk indexes, statistics, CRCs;
//      sqlite3              rosbag2's sqlite3 storage (topics and messages tables).
// Benchmarks (the storage left out of the names for ROS 1):
//   BM_ReadBag/[<storage>/]<encoding>  RosBagReader::Read of each frame in turn, in stamp order
//       (the recording order): the bag's message read (a chunk decompressed once for the frames
//       it holds), deserialised, the pixels copied or converted to grey, or decoded. Counters per
//       frame: decode_ms, the same frame decoded without the bag right after each read (as
//       BM_DecodeOnly does, outside the timing), and bag_ms, the read's time less that decoding.
//   BM_DecodeOnly/<encoding>  the same pixels without a bag: a copy of the grey image (mono8),
//       RGB to grey (rgb8), cv::imdecode of the very bytes the bags hold (jpeg, png).
//   BM_OpenBag/[<storage>/]<encoding>  RosBagReader::Open, which reads every message's fields (not
//       its pixels, but every chunk is decompressed) to check them; counter ms_per_frame.
// The bag's own cost per frame is BM_ReadBag minus BM_DecodeOnly of the same encoding (or, from
// one run, the counter bag_ms); the target: under 1 ms for 640 x 480, for every storage.
// Storages: ROS 1, mcap_zstd, mcap_lz4, sqlite3. Encodings: mono8, rgb8, jpeg, png.
//
// Run: build/bin/bench_bag   (medians: --benchmark_repetitions=5
//                             --benchmark_report_aggregates_only=true)
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <string>
#include <vector>

#include <benchmark/benchmark.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "tests/testing/data_paths.h"
#include "tests/testing/ros2_bag_writer.h"
#include "tools/evaluation/ros_bag.h"

namespace recog::cli {
namespace {

namespace fs = std::filesystem;

constexpr int kFrames = 40;
constexpr char kTopic[] = "/camera/image_raw";
const char* const kEncodings[] = {"mono8", "rgb8", "jpeg", "png"};
// The ROS 2 storages (WriteRos2Bags).
const char* const kRos2Storages[] = {"mcap_zstd", "mcap_lz4", "sqlite3"};

// The frames: colour 640 x 480 images, each bundled corridor frame enlarged and shifted.
std::vector<cv::Mat> Frames() {
  std::vector<cv::Mat> photos;
  for (const char* name : {"1.jpg", "20.jpg", "41.jpg", "60.jpg"}) {
    cv::Mat photo = cv::imread(testing::ProjectTestData("corridor/" + std::string(name)));
    if (photo.empty()) {
      std::fprintf(stderr, "bench_bag: tests/data/corridor/%s is missing\n", name);
      std::exit(1);
    }
    cv::resize(photo, photo, cv::Size(680, 510));
    photos.push_back(photo);
  }
  std::vector<cv::Mat> frames;
  for (int k = 0; k < kFrames; ++k) {
    const int shift = (k / 4) * 4;
    frames.push_back(photos[size_t(k % 4)](cv::Rect(shift, shift / 2, 640, 480)).clone());
  }
  return frames;
}

// Frame k's stamp as write_bag.py gives it (rospy.Time.from_sec(1000 + k * (1 / 30))).
testing::HeaderFields StampOf(int k) {
  const double seconds = 1000.0 + k * (1.0 / 30);
  const auto sec = int32_t(seconds);
  return {.sec = sec, .nanosec = uint32_t((seconds - sec) * 1e9), .frame_id = "camera", .seq = 0};
}

// Per encoding: the bags by storage ("ros1", kRos2Storages), and what decoding without them
// starts from (the grey or RGB pixels, or the encoded bytes the bags hold).
struct Input {
  std::map<std::string, std::string> bags;
  std::vector<cv::Mat> pixels;
  std::vector<std::vector<uint8_t>> encoded;
};

// The folder of the bags and their images, removed at the end.
const fs::path& WorkFolder() {
  static const fs::path dir =
      fs::temp_directory_path() / ("recog_bench_bag_" + std::to_string(::getpid()));
  return dir;
}

void ExitIfError(const Status& status) {
  if (status.ok()) return;
  std::fprintf(stderr, "bench_bag: %s\n", status.ToString().c_str());
  std::exit(1);
}

// The ROS 2 bags of `input`'s frames in `encoding`, a rosbag2 folder per storage in `dir`.
void WriteRos2Bags(const std::string& encoding, const fs::path& dir, Input* input) {
  const bool compressed = encoding == "jpeg" || encoding == "png";
  const std::vector<testing::BagTopic> topics = {
      {.id = 1,
       .name = kTopic,
       .type = compressed ? "sensor_msgs/msg/CompressedImage" : "sensor_msgs/msg/Image",
       .serialization_format = "cdr"}};
  std::vector<testing::BagMessage> messages;
  for (int k = 0; k < kFrames; ++k) {
    std::vector<uint8_t> cdr;
    if (compressed) {
      cdr = testing::Serialized(
          testing::CdrSerializer(),
          testing::CompressedImageFields{
              .header = StampOf(k), .format = encoding, .data = input->encoded[size_t(k)]});
    } else {
      const cv::Mat& pixels = input->pixels[size_t(k)];
      cdr = testing::Serialized(
          testing::CdrSerializer(),
          testing::ImageFields{.header = StampOf(k),
                               .height = uint32_t(pixels.rows),
                               .width = uint32_t(pixels.cols),
                               .encoding = encoding,
                               .is_bigendian = false,
                               .step = uint32_t(pixels.step[0]),
                               .data = {pixels.data, pixels.total() * pixels.elemSize()}});
    }
    const testing::HeaderFields stamp = StampOf(k);
    messages.push_back({.topic_id = 1,
                        .log_time = uint64_t(stamp.sec) * 1000000000 + stamp.nanosec,
                        .data = std::string(cdr.begin(), cdr.end())});
  }
  for (const std::string storage : kRos2Storages) {
    const std::string folder = (dir / (storage + "_" + encoding)).string();
    testing::McapOptions mcap = testing::Rosbag2McapOptions();  // zstd
    if (storage == "mcap_lz4") mcap.compression = "lz4";
    ExitIfError(testing::WriteRosbag2Folder(folder, storage == "sqlite3" ? "sqlite3" : "mcap",
                                            topics, messages, mcap));
    input->bags[storage] = folder;
  }
}

const std::map<std::string, Input>& Inputs() {
  static const std::map<std::string, Input> inputs = [] {
    const fs::path& dir = WorkFolder();
    fs::remove_all(dir);
    std::map<std::string, Input> made;
    const std::vector<cv::Mat> frames = Frames();
    for (const std::string encoding : kEncodings) {
      const fs::path images = dir / encoding;
      fs::create_directories(images);
      Input& input = made[encoding];
      for (int k = 0; k < kFrames; ++k) {
        const cv::Mat& bgr = frames[size_t(k)];
        const std::string name = std::to_string(k + 1);
        if (encoding == "jpeg" || encoding == "png") {
          std::vector<uint8_t> bytes;
          cv::imencode(encoding == "jpeg" ? ".jpg" : ".png", bgr, bytes);
          std::ofstream((images / (name + (encoding == "jpeg" ? ".jpg" : ".png"))).string(),
                        std::ios::binary)
              .write(reinterpret_cast<const char*>(bytes.data()), std::streamsize(bytes.size()));
          input.encoded.push_back(std::move(bytes));
        } else {
          cv::imwrite((images / (name + ".png")).string(), bgr);
          cv::Mat pixels;
          if (encoding == "mono8") {
            cv::cvtColor(bgr, pixels, cv::COLOR_BGR2GRAY);
          } else {
            cv::cvtColor(bgr, pixels, cv::COLOR_BGR2RGB);
          }
          input.pixels.push_back(pixels);
        }
      }
      const std::string bag = (dir / (encoding + ".bag")).string();
      const std::string command = "/usr/bin/python3 " + std::string(RECOG_SOURCE_DIR) +
                                  "/tests/testing/write_bag.py " + bag + " --images " +
                                  images.string() + " --encoding " + encoding;
      if (std::system(command.c_str()) != 0) {
        std::fprintf(stderr, "bench_bag: '%s' failed (python3-rosbag installed?)\n",
                     command.c_str());
        std::exit(1);
      }
      input.bags["ros1"] = bag;
      WriteRos2Bags(encoding, dir, &input);
    }
    return made;
  }();
  return inputs;
}

RosBagReader OpenOrDie(const std::string& bag) {
  BagTopics topics;
  topics.image = kTopic;
  StatusOr<RosBagReader> reader = RosBagReader::Open(bag, topics);
  ExitIfError(reader.status());
  return std::move(reader).value();
}

// Frame i's grey image decoded without a bag, as the bag reader decodes it.
cv::Mat DecodeWithoutBag(const Input& input, const std::string& encoding, size_t i) {
  cv::Mat gray;
  if (encoding == "mono8") {
    gray = input.pixels[i % input.pixels.size()].clone();
  } else if (encoding == "rgb8") {
    cv::cvtColor(input.pixels[i % input.pixels.size()], gray, cv::COLOR_RGB2GRAY);
  } else {
    gray = cv::imdecode(input.encoded[i % input.encoded.size()], cv::IMREAD_GRAYSCALE);
  }
  return gray;
}

double MillisecondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start)
      .count();
}

void BM_ReadBag(benchmark::State& state, const std::string& storage, const std::string& encoding) {
  const Input& input = Inputs().at(encoding);
  RosBagReader reader = OpenOrDie(input.bags.at(storage));
  size_t i = 0;
  double read_ms = 0, decode_ms = 0;
  for (auto _ : state) {
    auto start = std::chrono::steady_clock::now();
    StatusOr<BagFrame> frame = reader.Read(i % reader.size());
    if (!frame.ok()) {
      state.SkipWithError(frame.status().ToString().c_str());
      break;
    }
    benchmark::DoNotOptimize(frame->gray.data);
    read_ms += MillisecondsSince(start);
    state.PauseTiming();
    start = std::chrono::steady_clock::now();
    benchmark::DoNotOptimize(DecodeWithoutBag(input, encoding, i++).data);
    decode_ms += MillisecondsSince(start);
    state.ResumeTiming();
  }
  const auto frames = double(std::max<size_t>(i, 1));
  state.counters["decode_ms"] = decode_ms / frames;
  state.counters["bag_ms"] = (read_ms - decode_ms) / frames;
}

void BM_DecodeOnly(benchmark::State& state, const std::string& encoding) {
  const Input& input = Inputs().at(encoding);
  size_t i = 0;
  for (auto _ : state) benchmark::DoNotOptimize(DecodeWithoutBag(input, encoding, i++).data);
}

void BM_OpenBag(benchmark::State& state, const std::string& storage, const std::string& encoding) {
  const std::string& bag = Inputs().at(encoding).bags.at(storage);
  double ms = 0;
  for (auto _ : state) {
    const auto start = std::chrono::steady_clock::now();
    RosBagReader reader = OpenOrDie(bag);
    ms += MillisecondsSince(start);
    benchmark::DoNotOptimize(reader.size());
  }
  state.counters["ms_per_frame"] = ms / double(state.iterations() * kFrames);
}

void Register() {
  const auto name = [](const char* benchmark, const std::string& storage, const char* encoding) {
    return std::string(benchmark) + "/" + (storage == "ros1" ? "" : storage + "/") + encoding;
  };
  for (const char* encoding : kEncodings) {
    benchmark::RegisterBenchmark(name("BM_ReadBag", "ros1", encoding).c_str(), BM_ReadBag,
                                 std::string("ros1"), std::string(encoding))
        ->Unit(benchmark::kMillisecond);
    benchmark::RegisterBenchmark((std::string("BM_DecodeOnly/") + encoding).c_str(), BM_DecodeOnly,
                                 std::string(encoding))
        ->Unit(benchmark::kMillisecond);
    benchmark::RegisterBenchmark(name("BM_OpenBag", "ros1", encoding).c_str(), BM_OpenBag,
                                 std::string("ros1"), std::string(encoding))
        ->Unit(benchmark::kMillisecond);
    for (const char* storage : kRos2Storages) {
      benchmark::RegisterBenchmark(name("BM_ReadBag", storage, encoding).c_str(), BM_ReadBag,
                                   std::string(storage), std::string(encoding))
          ->Unit(benchmark::kMillisecond);
      benchmark::RegisterBenchmark(name("BM_OpenBag", storage, encoding).c_str(), BM_OpenBag,
                                   std::string(storage), std::string(encoding))
          ->Unit(benchmark::kMillisecond);
    }
  }
}

}  // namespace
}  // namespace recog::cli

int main(int argc, char** argv) {
  recog::cli::Register();
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  std::filesystem::remove_all(recog::cli::WorkFolder());
  return 0;
}
