// The JSON of place answers that `recog stream`, `recog query` and `recog relocalize` print with
// --json: a loop result (status, match, scores, evidence, correspondences, metric pose) and the
// server's timing of a frame.
#pragma once

#include <string>

#include <nlohmann/json.hpp>

#include "recognition/v1/place.pb.h"

namespace recog::cli {

namespace pb = ::recognition::v1;

// "loop_detected", ... (the proto's LOOP_STATUS_ name without the prefix, in lower case).
std::string StatusLabel(pb::LoopStatus status);
nlohmann::ordered_json LoopJson(const pb::LoopResult& result);
nlohmann::ordered_json TimingJson(const pb::Timing& timing);

}  // namespace recog::cli
