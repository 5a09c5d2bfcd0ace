// GroundTruth: which earlier frames of an image sequence show the same place as each query frame,
// as used to score a loop-closure detector, and the two text files that store it.
//
// Semantics: frame i "matches" frame j when j < i and both show the same place on different visits
// (frames of one visit follow each other and are not loops). Only the lower triangle counts.
//
// Dense format (ground_truth.txt, as shipped with the corridor data set): N lines of N values, each
// value 0 or 1, separated by single spaces, every line ending in '\n'. Line i, column j (both
// counted from 1) is 1 when frame i matches the earlier frame j:
//
//   0 0 0 0
//   0 0 0 0
//   1 0 0 0
//   1 1 0 0
//
// Sparse format (ground_truth.sparse.txt, for long sequences): a header line
// "# recog sparse ground truth v1 N", then one line per query frame that has matches, in increasing
// order of i, "i: j1 j2 ..." with 1-based frame numbers and j1 < j2 < ... < i:
//
//   # recog sparse ground truth v1 4
//   3: 1
//   4: 1 2
//
// The reader accepts either (a first line starting with '#' means sparse), skips blank lines and,
// in the sparse format, further lines starting with '#'. In a dense file, 1s on or above the
// diagonal (symmetric matrices, as some public data sets ship them) are not loops under the
// semantics above: they are counted in `ignored_entries` and otherwise dropped.
#pragma once

#include <set>
#include <string>
#include <utility>
#include <vector>

#include "core/common/status.h"

namespace recog::cli {

struct GroundTruth {
  int frames = 0;
  // matches[i]: 0-based frames j < i that frame i matches, increasing. Size `frames`.
  std::vector<std::vector<int>> matches;
  // Pairs (i, j), 0-based, i > j, that are neither the same place nor different places (a loop
  // between them is left out of precision); empty unless ReadAmbiguousPairs filled it.
  std::set<std::pair<int, int>> ambiguous;
  // Dense files only: 1s on or above the diagonal, which were ignored.
  long long ignored_entries = 0;

  // True when frame `query` matches frame `other` (0-based); false for out-of-range frames.
  bool Matches(int query, int other) const;
  // True when the pair (either order) is listed as ambiguous.
  bool IsAmbiguous(int query, int other) const;
  // Number of frames with at least one match.
  int QueriesWithMatches() const;
  // Total number of (query, match) pairs.
  long long NumPairs() const;
  // OK when `matches` has `frames` entries, each increasing and within [0, i).
  Status Validate() const;
};

// Reads either format. NOT_FOUND for a missing file; DATA_LOSS (with the line number) for a
// malformed one.
StatusOr<GroundTruth> ReadGroundTruth(const std::string& path);

// Reads a list of ambiguous pairs into truth->ambiguous: '#' starts a comment, blank lines are
// skipped, every other line is "i j", two different 1-based frame numbers of the sequence.
// NOT_FOUND for a missing file; DATA_LOSS naming the line for anything else.
Status ReadAmbiguousPairs(const std::string& path, GroundTruth* truth);

// Write the dense / sparse format. INVALID_ARGUMENT when `truth` does not validate, INTERNAL when
// the file cannot be written.
Status WriteDenseGroundTruth(const GroundTruth& truth, const std::string& path);
Status WriteSparseGroundTruth(const GroundTruth& truth, const std::string& path);

}  // namespace recog::cli
