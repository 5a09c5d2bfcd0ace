// Reading and writing vocabularies: the project's own binary format, and detection of the DBoW2
// formats (see dbow2_format.h).
//
// The project format ("rvoc") is the in-memory layout of Vocabulary behind a fixed header, so a
// load is one private mmap of the body plus a checksum, never a parse:
//
//   offset  size  field
//   0       8     magic "RECOGVOC"
//   8       4     format version (1)
//   12      4     header size in bytes (128)
//   16      1     descriptor type (1 binary, 2 float)
//   17      1     weighting (DBoW2 numbering)
//   18      1     scoring (DBoW2 numbering)
//   19      1     reserved (0)
//   20      4     descriptor size in bytes
//   24      4     branching k
//   28      4     depth L
//   32      4     number of trees T
//   36      4     number of nodes
//   40      4     number of words
//   44      4     reserved (0)
//   48      8     body size in bytes
//   56      8     XXH3-64 checksum of the body
//   64      8     XXH3-64 checksum of header bytes 0..63
//   72      56    reserved (0)
//   128     ...   body: Vocabulary::buffer()
//
// All integers little-endian. Any mismatch (magic, version, sizes, either checksum) is DATA_LOSS
// with a message naming the file and what is wrong; a file that cannot be opened is NOT_FOUND.
#pragma once

#include <string>

#include "core/common/status.h"
#include "core/vocabulary/vocabulary.h"

namespace recog {

enum class VocabularyFileFormat {
  kRecog,      // the project's binary format (.rvoc)
  kDbow2Text,  // DBoW2/ORB-SLAM text (ORBvoc.txt)
  kDbow2Yaml,  // DBoW2 OpenCV-YAML (.yml, .yaml, .yml.gz)
};

// Guesses the format from the first bytes of the file (and the .gz suffix).
StatusOr<VocabularyFileFormat> DetectVocabularyFormat(const std::string& path);

// Writes the project format (atomically: a temporary file renamed into place).
Status SaveVocabulary(const Vocabulary& vocabulary, const std::string& path);
// Reads the project format.
StatusOr<Vocabulary> LoadVocabulary(const std::string& path);
// Reads any supported format, detected from the file's contents.
StatusOr<Vocabulary> LoadAnyVocabulary(const std::string& path);

// Path of a vocabulary shipped with the project (e.g. "place_orb_k10_l5.rvoc"):
// $RECOG_VOCABULARY_DIR when set, otherwise the project's vocabularies/ folder, or, when the file
// is not there but cmake --install put it in <prefix>/share/recog/vocabularies, that one.
std::string BundledVocabularyPath(const std::string& file_name);
std::string DefaultPlaceVocabularyPath();   // the bundled place vocabulary (k = 10, L = 5, ORB)
std::string DefaultObjectVocabularyPath();  // the bundled object vocabulary (12 trees, ORB)

}  // namespace recog
