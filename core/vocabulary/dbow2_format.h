// Import and export of the vocabulary formats of DBoW2 (dorian3d/DBoW2) and ORB-SLAM.
//
// Text (ORBvoc.txt): line 1 "k L scoring weighting"; then one line per node, root omitted, node
// ids being line numbers from 1: "parent_id is_leaf b0 ... b31 weight" (descriptor as 32 decimal
// bytes). Word ids follow the order of the leaves in the file.
//
// YAML (OpenCV FileStorage, .yml or .yml.gz): vocabulary: {k, L, scoringType, weightingType,
// nodes: [{nodeId, parentId, weight, descriptor}], words: [{wordId, nodeId}]}. The descriptor is
// decimal bytes ("212 176 ...") for ORB or a string of 256 '0'/'1' for BRIEF. DBoW2 writes a BRIEF
// descriptor as boost::dynamic_bitset does: the first character is the highest bit. Reading the
// string backwards gives the bytes most-significant bit first, which is how the 256 bits of an ORB
// descriptor map to a BRIEF string, so both notations land in the same 32 bytes.
//
// Children keep their order of appearance in the file, so ties in the descent are broken exactly
// as DBoW2 breaks them, and imported vocabularies reproduce DBoW2's words and weights.
// Malformed, truncated or inconsistent files give DATA_LOSS (or NOT_FOUND for a missing file),
// with the line or node at fault in the message.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <string_view>

#include "core/common/status.h"
#include "core/vocabulary/vocabulary.h"

namespace recog {

StatusOr<Vocabulary> ImportDbow2Text(const std::string& path);
StatusOr<Vocabulary> ImportDbow2Yaml(const std::string& path);

// Writes a one-tree binary-256 vocabulary as DBoW2 text; others are INVALID_ARGUMENT.
// The nodes are ordered so that parents come before children, siblings keep their order and,
// whenever the tree allows it, the leaves appear in word-id order, so that the word ids survive
// a re-import (DBoW2 text numbers words in leaf order). This holds for vocabularies trained by this
// project and for those imported from DBoW2. The file is written atomically (temporary + rename).
Status ExportDbow2Text(const Vocabulary& vocabulary, const std::string& path);

// One 256-bit descriptor in either DBoW2 notation: 32 decimal bytes separated by blanks (ORB), or
// 256 '0'/'1' characters (BRIEF, see above). DATA_LOSS when it is neither.
StatusOr<std::array<uint8_t, 32>> ParseDbow2Descriptor(std::string_view text);

}  // namespace recog
