// What `recog eval place` says of the revisits it missed, in every mode: each missed revisit's
// reason (MissReason, tools/evaluation/loop_tally.h: the stage of the loop detector that lost it)
// as JSON (`misses`, `miss_reasons`), as a summary line per map and as one line per miss.
#pragma once

#include <functional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "tools/evaluation/loop_tally.h"

namespace recog::cli {

// How a report names frame i (0-based): its file, or a rig frame's number.
using FrameName = std::function<std::string(int)>;

// The misses of one map into `out`: `misses` (frames from 1; with their files when `names` is
// given) and `miss_reasons`, every reason with its count.
void AddMissesJson(const LoopFigures& e, const std::vector<std::string>* names,
                   nlohmann::json* out);

// One line after a map's precision and recall: how many of its revisits were missed, and why
// ("missed 54 of 56: no candidate 10, wrong top candidate 25 (a true place ranked 2-5: 9), ...").
// `label` names the map ("inter-map"; empty for a single map). Nothing when no frame revisits it.
void PrintMissSummary(const std::string& label, const LoopFigures& e);

// Every miss of a map, one line each, as the loops are listed ("missed A: failed geometry, 9
// inliers of 34 matches with B"); `label` as for PrintMissSummary.
void PrintMisses(const std::string& label, const LoopFigures& e, const FrameName& name);

}  // namespace recog::cli
