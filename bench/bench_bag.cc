// What reading a ROS 1 bag costs beyond decoding its images (tools/evaluation/ros_bag.h): 40
// frames of 640 x 480 (the bundled corridor frames, enlarged and shifted) in a bag per encoding,
// written by Debian's python3-rosbag (tests/testing/write_bag.py) at start:
//   BM_ReadBag/<encoding>   RosBagReader::Read of each frame in turn: the bag's record read and
//                           deserialised, the pixels copied or converted to grey, or decoded.
//   BM_DecodeOnly/<encoding> the same pixels without the bag: a copy of the grey image (mono8),
//                           RGB to grey (rgb8), cv::imdecode of the very bytes the bag holds
//                           (jpeg, png).
//   BM_OpenBag/<encoding>   RosBagReader::Open, which reads every message's fields (not its
//                           pixels) to check them; its counter ms_per_frame is per frame.
// The bag's own cost per frame is BM_ReadBag minus BM_DecodeOnly of the same encoding (the
// target: under 1 ms for 640 x 480). Encodings: mono8, rgb8, jpeg, png.
//
// Run: build/bin/bench_bag
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
#include "tools/evaluation/ros_bag.h"

namespace recog::cli {
namespace {

namespace fs = std::filesystem;

constexpr int kFrames = 40;
constexpr char kTopic[] = "/camera/image_raw";
const char* const kEncodings[] = {"mono8", "rgb8", "jpeg", "png"};

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

// Per encoding: the bag, and what decoding without it starts from (the grey or RGB pixels, or
// the encoded bytes the bag holds).
struct Input {
  std::string bag;
  std::vector<cv::Mat> pixels;
  std::vector<std::vector<uint8_t>> encoded;
};

// The folder of the bags and their images, removed at the end.
const fs::path& WorkFolder() {
  static const fs::path dir =
      fs::temp_directory_path() / ("recog_bench_bag_" + std::to_string(::getpid()));
  return dir;
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
      input.bag = (dir / (encoding + ".bag")).string();
      const std::string command = "/usr/bin/python3 " + std::string(RECOG_SOURCE_DIR) +
                                  "/tests/testing/write_bag.py " + input.bag + " --images " +
                                  images.string() + " --encoding " + encoding;
      if (std::system(command.c_str()) != 0) {
        std::fprintf(stderr, "bench_bag: '%s' failed (python3-rosbag installed?)\n",
                     command.c_str());
        std::exit(1);
      }
    }
    return made;
  }();
  return inputs;
}

RosBagReader OpenOrDie(const std::string& bag) {
  BagTopics topics;
  topics.image = kTopic;
  StatusOr<RosBagReader> reader = RosBagReader::Open(bag, topics);
  if (!reader.ok()) {
    std::fprintf(stderr, "bench_bag: %s\n", reader.status().ToString().c_str());
    std::exit(1);
  }
  return std::move(reader).value();
}

void BM_ReadBag(benchmark::State& state, const std::string& encoding) {
  RosBagReader reader = OpenOrDie(Inputs().at(encoding).bag);
  size_t i = 0;
  for (auto _ : state) {
    StatusOr<BagFrame> frame = reader.Read(i++ % reader.size());
    if (!frame.ok()) state.SkipWithError(frame.status().ToString().c_str());
    benchmark::DoNotOptimize(frame->gray.data);
  }
}

void BM_DecodeOnly(benchmark::State& state, const std::string& encoding) {
  const Input& input = Inputs().at(encoding);
  size_t i = 0;
  for (auto _ : state) {
    cv::Mat gray;
    if (encoding == "mono8") {
      gray = input.pixels[i++ % input.pixels.size()].clone();
    } else if (encoding == "rgb8") {
      cv::cvtColor(input.pixels[i++ % input.pixels.size()], gray, cv::COLOR_RGB2GRAY);
    } else {
      gray = cv::imdecode(input.encoded[i++ % input.encoded.size()], cv::IMREAD_GRAYSCALE);
    }
    benchmark::DoNotOptimize(gray.data);
  }
}

void BM_OpenBag(benchmark::State& state, const std::string& encoding) {
  const std::string& bag = Inputs().at(encoding).bag;
  double ms = 0;
  for (auto _ : state) {
    const auto start = std::chrono::steady_clock::now();
    RosBagReader reader = OpenOrDie(bag);
    ms +=
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    benchmark::DoNotOptimize(reader.size());
  }
  state.counters["ms_per_frame"] = ms / double(state.iterations() * kFrames);
}

void Register() {
  for (const char* encoding : kEncodings) {
    benchmark::RegisterBenchmark((std::string("BM_ReadBag/") + encoding).c_str(), BM_ReadBag,
                                 std::string(encoding))
        ->Unit(benchmark::kMillisecond);
    benchmark::RegisterBenchmark((std::string("BM_DecodeOnly/") + encoding).c_str(), BM_DecodeOnly,
                                 std::string(encoding))
        ->Unit(benchmark::kMillisecond);
    benchmark::RegisterBenchmark((std::string("BM_OpenBag/") + encoding).c_str(), BM_OpenBag,
                                 std::string(encoding))
        ->Unit(benchmark::kMillisecond);
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
