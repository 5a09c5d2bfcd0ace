// recog bag info BAG: what a bag holds (tools/bag/bag_info.h); recog bag extract BAG --topic T -o
// DIR: an image topic's frames as image files with a TUM-style rgb.txt of their stamps. For ROS 1
// bags, MCAP files, rosbag2 sqlite3 files and rosbag2 folders alike.
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "tools/bag/bag_info.h"
#include "tools/evaluation/ros_bag.h"
#include "tools/recog/commands.h"

namespace recog::cli {
namespace {

struct BagInfoArgs {
  std::string bag;
  bool json = false;
};

int RunBagInfo(const BagInfoArgs& args) {
  const StatusOr<bag::BagDescription> description = bag::DescribeBag(args.bag);
  if (!description.ok()) {
    std::fprintf(stderr, "recog bag info: %s\n", description.status().ToString().c_str());
    return 1;
  }
  if (args.json) {
    std::printf("%s\n", bag::DescriptionJson(*description).dump().c_str());
  } else {
    std::fputs(bag::DescriptionText(*description).c_str(), stdout);
  }
  return 0;
}

struct BagExtractArgs {
  std::string bag;
  std::string topic;
  std::string output;
};

// A compressed image's file name extension, by its first bytes (the reader took only JPEG and PNG).
const char* EncodedExtension(const std::vector<uint8_t>& data) {
  return data.size() >= 2 && data[0] == 0xff && data[1] == 0xd8 ? ".jpg" : ".png";
}

// Frame `frame`'s image as file `stem` + extension: a compressed image's bytes as they are, raw
// pixels as a lossless PNG (colour in BGR, or grey); the file's name relative to the output.
StatusOr<std::string> WriteFrameImage(const BagFrame& frame, const std::filesystem::path& dir,
                                      const std::string& stem) {
  const std::string name =
      stem + (frame.encoded.empty() ? ".png" : EncodedExtension(frame.encoded));
  const std::string path = (dir / name).string();
  if (!frame.encoded.empty()) {
    std::ofstream out(path, std::ios::binary);
    out.write(reinterpret_cast<const char*>(frame.encoded.data()),
              std::streamsize(frame.encoded.size()));
    if (!out.flush()) return Status::Unavailable("cannot write '" + path + "'");
  } else if (!cv::imwrite(path, frame.color.empty() ? frame.gray : frame.color)) {
    return Status::Unavailable("cannot write '" + path + "'");
  }
  return name;
}

Status ExtractBag(const BagExtractArgs& args) {
  namespace fs = std::filesystem;
  BagTopics topics;
  topics.image = args.topic;
  BagReadOptions options;
  options.keep_color = true;
  options.keep_encoded = true;
  RECOG_ASSIGN_OR_RETURN(RosBagReader reader, RosBagReader::Open(args.bag, topics, options));
  const fs::path dir = args.output;
  std::error_code ec;
  fs::create_directories(dir / "rgb", ec);
  if (ec)
    return Status::Unavailable("cannot create '" + (dir / "rgb").string() + "': " + ec.message());
  std::string list =
      "# recog bag extract " + args.bag + " --topic " + args.topic + "\n# timestamp filename\n";
  BagFrame frame;
  for (;;) {
    RECOG_ASSIGN_OR_RETURN(const bool more, reader.Next(&frame));
    if (!more) break;
    char stem[32];
    std::snprintf(stem, sizeof(stem), "rgb/%06llu", static_cast<unsigned long long>(frame.index));
    RECOG_ASSIGN_OR_RETURN(const std::string name, WriteFrameImage(frame, dir, stem));
    list.append(BagStampText(frame.stamp_ns)).append(" ").append(name).append("\n");
    if ((frame.index + 1) % 100 == 0) {
      std::fprintf(stderr, "recog bag extract: %llu of %zu frames\r",
                   static_cast<unsigned long long>(frame.index + 1), reader.size());
    }
  }
  std::ofstream out(dir / "rgb.txt");
  out << list;
  if (!out.flush()) return Status::Unavailable("cannot write '" + (dir / "rgb.txt").string() + "'");
  std::printf("%zu frames of %s written to %s (rgb.txt: their stamps)\n", reader.size(),
              args.topic.c_str(), args.output.c_str());
  return Status::Ok();
}

}  // namespace

void AddBagCommands(CLI::App& app, int* exit_code) {
  CLI::App* bag = app.add_subcommand("bag", "Robot recordings: ROS 1 and ROS 2 bags");
  bag->require_subcommand(1);
  auto args = std::make_shared<BagInfoArgs>();
  CLI::App* info = bag->add_subcommand(
      "info",
      "What a bag holds: storage, files, compression, duration, and per topic its type, message "
      "count and, for images, encoding and size (docs/cli.md, \"ROS bags\")");
  info->add_option("bag", args->bag,
                   "A ROS 1 bag, an MCAP file, a rosbag2 sqlite3 file or a rosbag2 folder")
      ->required();
  info->add_flag("--json", args->json, "Print JSON");
  info->callback([args, exit_code] { *exit_code = RunBagInfo(*args); });

  auto extract_args = std::make_shared<BagExtractArgs>();
  CLI::App* extract = bag->add_subcommand(
      "extract",
      "An image topic's frames as image files in header-stamp order (a CompressedImage's JPEG or "
      "PNG bytes as they are, raw pixels as PNG) with rgb.txt of their stamps: a folder that "
      "`--images` reads as the TUM layout");
  extract->add_option("bag", extract_args->bag, "The bag (as for `recog bag info`)")->required();
  extract->add_option("--topic", extract_args->topic, "The image topic")->required();
  extract->add_option("-o,--output", extract_args->output, "The folder to write (rgb/, rgb.txt)")
      ->required();
  extract->callback([extract_args, exit_code] {
    const Status s = ExtractBag(*extract_args);
    if (!s.ok()) std::fprintf(stderr, "recog bag extract: %s\n", s.ToString().c_str());
    *exit_code = s.ok() ? 0 : 1;
  });
}

}  // namespace recog::cli
