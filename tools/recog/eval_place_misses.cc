#include "tools/recog/eval_place_misses.h"

#include <algorithm>
#include <cstdio>
#include <optional>
#include <utility>

#include "core/common/median.h"

namespace recog::cli {
namespace {

// "wrong top candidate" for MissReason::kWrongTopCandidate.
std::string ReasonText(MissReason reason) {
  std::string text(MissReasonName(reason));
  std::replace(text.begin(), text.end(), '_', ' ');
  return text;
}

// Where the first true candidate of these misses ranked: " (a true place ranked 1: 3, 2-5: 9,
// 6+: 13)", empty when none had one.
std::string RankSummary(const std::vector<const MissedRevisit*>& misses) {
  int first = 0, top_five = 0, further = 0;
  for (const MissedRevisit* m : misses) {
    if (!m->true_rank) continue;
    ++(*m->true_rank == 1 ? first : *m->true_rank <= 5 ? top_five : further);
  }
  std::string parts;
  for (const auto& [ranks, count] : {std::pair{"1", first}, {"2-5", top_five}, {"6+", further}}) {
    if (count == 0) continue;
    parts += (parts.empty() ? "" : ", ") + std::string(ranks) + ": " + std::to_string(count);
  }
  return parts.empty() ? "" : " (a true place ranked " + parts + ")";
}

// The median verification of these misses: " (median 6 inliers of 31 matches)", empty when none
// holds one.
std::string EvidenceSummary(const std::vector<const MissedRevisit*>& misses) {
  std::vector<double> inliers, correspondences;
  for (const MissedRevisit* m : misses) {
    if (m->inliers) inliers.push_back(*m->inliers);
    if (m->correspondences) correspondences.push_back(*m->correspondences);
  }
  if (inliers.empty()) return "";
  char text[80];
  std::snprintf(text, sizeof(text), " (median %g inliers", Median(inliers));
  std::string summary = text;
  if (!correspondences.empty()) {
    std::snprintf(text, sizeof(text), " of %g matches", Median(correspondences));
    summary += text;
  }
  return summary + ")";
}

// A miss as the text report lists it, after "missed <frame>: ".
std::string MissText(const MissedRevisit& m, const FrameName& name) {
  const std::string candidate = m.candidate ? name(*m.candidate) : "?";
  const std::string true_rank = m.true_rank
                                    ? ", a true place at rank " + std::to_string(*m.true_rank) +
                                          " (" + name(*m.true_candidate) + ")"
                                    : "";
  std::string evidence;
  if (m.inliers) evidence = ", " + std::to_string(*m.inliers) + " inliers";
  if (m.inliers && m.correspondences) {
    evidence += " of " + std::to_string(*m.correspondences) + " matches";
  }
  const std::string reason = ReasonText(m.reason);
  switch (m.reason) {
    case MissReason::kNotQueried:
      return reason + " (" + m.status + ")";
    case MissReason::kNoCandidate:
      return reason + (m.status == "no_candidates" ? " (the query returned nothing)"
                                                   : " (no true place among the candidates)");
    case MissReason::kLowScore:
      return reason + true_rank;
    case MissReason::kWrongTopCandidate:
      return reason + " " + candidate + true_rank;
    case MissReason::kNotConsistent:
      if (!m.consistent_queries) return reason + " with " + candidate + " (" + m.status + ")";
      return reason + " with " + candidate + " (" + std::to_string(*m.consistent_queries) +
             (*m.consistent_queries == 1 ? " consistent previous query)"
                                         : " consistent previous queries)");
    case MissReason::kFailedGeometry:
      return reason + evidence + " with " + candidate +
             (m.failed_metric ? ", refused by the 3D check" : "") +
             (m.status != "failed_geometry" ? " (" + m.status + ")" : "");
    case MissReason::kWrongLoop:
      return reason + " to " + candidate + evidence + true_rank;
  }
  return reason;
}

}  // namespace

void AddMissesJson(const LoopFigures& e, const std::vector<std::string>* names,
                   nlohmann::json* out) {
  const auto number = [](const std::optional<int>& frame) {
    return frame ? nlohmann::json(*frame + 1) : nlohmann::json(nullptr);
  };
  const auto file = [&](const std::optional<int>& frame) {
    return frame ? nlohmann::json((*names)[size_t(*frame)]) : nlohmann::json(nullptr);
  };
  const auto optional = [](const auto& value) {
    return value ? nlohmann::json(*value) : nlohmann::json(nullptr);
  };
  nlohmann::json misses = nlohmann::json::array();
  for (const MissedRevisit& m : e.misses) {
    nlohmann::json miss = {{"query", m.query + 1},
                           {"reason", std::string(MissReasonName(m.reason))},
                           {"status", m.status},
                           {"candidate", number(m.candidate)},
                           {"true_candidate", number(m.true_candidate)},
                           {"true_rank", optional(m.true_rank)},
                           {"inliers", optional(m.inliers)},
                           {"correspondences", optional(m.correspondences)},
                           {"consistent_queries", optional(m.consistent_queries)},
                           {"failed_metric", m.failed_metric}};
    if (names != nullptr) {
      miss["query_file"] = (*names)[size_t(m.query)];
      miss["candidate_file"] = file(m.candidate);
      miss["true_candidate_file"] = file(m.true_candidate);
    }
    misses.push_back(std::move(miss));
  }
  nlohmann::json reasons = nlohmann::json::object();
  for (const MissReason reason : kMissReasons) {
    const std::string name(MissReasonName(reason));
    reasons[name] = e.miss_reasons.count(name) ? e.miss_reasons.at(name) : 0;
  }
  (*out)["misses"] = std::move(misses);
  (*out)["miss_reasons"] = std::move(reasons);
}

void PrintMissSummary(const std::string& label, const LoopFigures& e) {
  if (e.query_frames_with_truth == 0) return;
  std::string line = (label.empty() ? "" : label + " ") + "missed " +
                     std::to_string(e.misses.size()) + " of " +
                     std::to_string(e.query_frames_with_truth);
  const char* separator = ": ";
  for (const MissReason reason : kMissReasons) {
    std::vector<const MissedRevisit*> these;
    for (const MissedRevisit& m : e.misses) {
      if (m.reason == reason) these.push_back(&m);
    }
    if (these.empty()) continue;
    line += separator + ReasonText(reason) + " " + std::to_string(these.size());
    if (reason == MissReason::kLowScore || reason == MissReason::kWrongTopCandidate) {
      line += RankSummary(these);
    } else if (reason == MissReason::kFailedGeometry) {
      line += EvidenceSummary(these);
    }
    separator = ", ";
  }
  std::printf("%s\n", line.c_str());
}

void PrintMisses(const std::string& label, const LoopFigures& e, const FrameName& name) {
  const std::string prefix = label.empty() ? "" : label + " ";
  for (const MissedRevisit& m : e.misses) {
    std::printf("%smissed %s: %s\n", prefix.c_str(), name(m.query).c_str(),
                MissText(m, name).c_str());
  }
}

}  // namespace recog::cli
