// The flags that read a ROS 1 or ROS 2 bag instead of a folder of frames, shared by `recog eval
// place`, `recog stream` and `recog load`: --bag FILE --topic T, with --camera-info-topic,
// --depth-topic, --right-topic, --right-camera-info-topic and --max-depth-offset
// (tools/evaluation/ros_bag.h reads the bag); `recog eval sequence` takes the first three only.
#pragma once

#include <string>

#include <CLI/CLI.hpp>

#include "core/common/status.h"
#include "tools/evaluation/place_evaluation.h"
#include "tools/evaluation/ros_bag.h"

namespace recog::cli {

struct BagFlags {
  std::string bag;  // empty: no bag
  BagTopics topics;
  BagReadOptions options;

  bool given() const { return !bag.empty(); }

  // Adds the flags to `command`; --bag excludes `folder` (the command's --images or
  // --sequences), the topics and --max-depth-offset need --bag.
  void AddTo(CLI::App* command, CLI::Option* folder);
  // Only --bag (help: `help`), --topic and --camera-info-topic, for a command that reads neither
  // depth nor right images (`recog eval sequence`); --bag excludes `folder`. Returns --bag's
  // option, for the command's own flags that need it.
  CLI::Option* AddImageTo(CLI::App* command, CLI::Option* folder, const std::string& help);

  // The bag's frames. Without --topic, INVALID_ARGUMENT listing the bag's image topics; the
  // errors of FrameSource::OpenBag.
  StatusOr<FrameSource> Open() const;
};

}  // namespace recog::cli
