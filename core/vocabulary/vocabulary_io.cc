#include "core/vocabulary/vocabulary_io.h"

#include <array>
#include <cctype>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <memory>

#include <xxhash.h>

#include "core/common/file_io.h"
#include "core/vocabulary/dbow2_format.h"

namespace recog {
namespace {

constexpr char kMagic[8] = {'R', 'E', 'C', 'O', 'G', 'V', 'O', 'C'};
constexpr uint32_t kVersion = 1;
constexpr uint32_t kHeaderSize = 128;
constexpr size_t kHeaderChecksumSpan = 64;  // header bytes covered by the header checksum

template <class T>
void Put(uint8_t* header, size_t offset, T value) {
  std::memcpy(header + offset, &value, sizeof(T));
}
template <class T>
T Get(const uint8_t* header, size_t offset) {
  T value;
  std::memcpy(&value, header + offset, sizeof(T));
  return value;
}

StatusOr<File> OpenForReading(const std::string& path) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) {
    return Status::NotFound("vocabulary file '" + path + "' does not exist");
  }
  if (std::filesystem::is_directory(path, ec)) {
    return Status::InvalidArgument("'" + path + "' is a directory, not a vocabulary file");
  }
  File file(std::fopen(path.c_str(), "rb"));
  if (!file) return Status::NotFound("cannot open vocabulary file '" + path + "'");
  return file;
}

}  // namespace

StatusOr<VocabularyFileFormat> DetectVocabularyFormat(const std::string& path) {
  RECOG_ASSIGN_OR_RETURN(File file, OpenForReading(path));
  std::array<char, 16> head{};
  const size_t got = std::fread(head.data(), 1, head.size(), file.get());
  if (got >= sizeof(kMagic) && std::memcmp(head.data(), kMagic, sizeof(kMagic)) == 0) {
    return VocabularyFileFormat::kRecog;
  }
  const bool gzip = got >= 2 && uint8_t(head[0]) == 0x1f && uint8_t(head[1]) == 0x8b;
  if (gzip || std::string_view(head.data(), got).starts_with("%YAML")) {
    return VocabularyFileFormat::kDbow2Yaml;
  }
  if (got > 0 && (std::isdigit(uint8_t(head[0])) != 0)) return VocabularyFileFormat::kDbow2Text;
  return Status::DataLoss("'" + path + "' is not a vocabulary file (unknown format)");
}

Status SaveVocabulary(const Vocabulary& vocabulary, const std::string& path) {
  if (vocabulary.empty()) return Status::InvalidArgument("cannot save an empty vocabulary");
  const VocabularyInfo& info = vocabulary.info();
  const std::span<const uint8_t> body = vocabulary.buffer();

  std::array<uint8_t, kHeaderSize> header{};
  std::memcpy(header.data(), kMagic, sizeof(kMagic));
  Put<uint32_t>(header.data(), 8, kVersion);
  Put<uint32_t>(header.data(), 12, kHeaderSize);
  header[16] = uint8_t(info.descriptor.type);
  header[17] = uint8_t(info.weighting);
  header[18] = uint8_t(info.scoring);
  Put<uint32_t>(header.data(), 20, info.descriptor.size_bytes);
  Put<uint32_t>(header.data(), 24, info.branching);
  Put<uint32_t>(header.data(), 28, info.depth);
  Put<uint32_t>(header.data(), 32, info.num_trees);
  Put<uint32_t>(header.data(), 36, uint32_t(vocabulary.num_nodes()));
  Put<uint32_t>(header.data(), 40, uint32_t(vocabulary.num_words()));
  Put<uint64_t>(header.data(), 48, uint64_t(body.size()));
  Put<uint64_t>(header.data(), 56, vocabulary.checksum());
  Put<uint64_t>(header.data(), 64, XXH3_64bits(header.data(), kHeaderChecksumSpan));

  return WriteFileAtomically(
      path, {std::string_view(reinterpret_cast<const char*>(header.data()), header.size()),
             std::string_view(reinterpret_cast<const char*>(body.data()), body.size())});
}

StatusOr<Vocabulary> LoadVocabulary(const std::string& path) {
  RECOG_ASSIGN_OR_RETURN(File file, OpenForReading(path));
  const std::string where = "vocabulary file '" + path + "'";
  std::array<uint8_t, kHeaderSize> header{};
  if (std::fread(header.data(), 1, header.size(), file.get()) != header.size()) {
    return Status::DataLoss(where + " is truncated: shorter than its 128-byte header");
  }
  if (std::memcmp(header.data(), kMagic, sizeof(kMagic)) != 0) {
    return Status::DataLoss(where + " is not in the project format (bad magic)");
  }
  if (Get<uint64_t>(header.data(), 64) != XXH3_64bits(header.data(), kHeaderChecksumSpan)) {
    return Status::DataLoss(where + " has a corrupt header (checksum mismatch)");
  }
  if (const uint32_t version = Get<uint32_t>(header.data(), 8); version != kVersion) {
    return Status::DataLoss(where + " has format version " + std::to_string(version) +
                            "; this build reads version " + std::to_string(kVersion));
  }
  if (Get<uint32_t>(header.data(), 12) != kHeaderSize) {
    return Status::DataLoss(where + " has an unexpected header size");
  }
  VocabularyInfo info;
  info.descriptor.type = DescriptorType(header[16]);
  info.weighting = WeightingType(header[17]);
  info.scoring = ScoringType(header[18]);
  info.descriptor.size_bytes = Get<uint32_t>(header.data(), 20);
  info.branching = Get<uint32_t>(header.data(), 24);
  info.depth = Get<uint32_t>(header.data(), 28);
  info.num_trees = Get<uint32_t>(header.data(), 32);
  const uint32_t num_nodes = Get<uint32_t>(header.data(), 36);
  const uint32_t num_words = Get<uint32_t>(header.data(), 40);
  const uint64_t body_size = Get<uint64_t>(header.data(), 48);
  const uint64_t checksum = Get<uint64_t>(header.data(), 56);
  if (Status s = info.descriptor.Validate(); !s.ok())
    return s.WithContext(where, StatusCode::kDataLoss);
  if (num_words == 0 || num_words > num_nodes ||
      body_size != Vocabulary::BufferSize(info, num_nodes, num_words)) {
    return Status::DataLoss(where + " has inconsistent node/word counts in its header");
  }
  std::error_code ec;
  const uintmax_t file_size = std::filesystem::file_size(path, ec);
  if (ec || file_size != kHeaderSize + body_size) {
    return Status::DataLoss(where + " has " + std::to_string(file_size) + " bytes; its header " +
                            "announces " + std::to_string(kHeaderSize + body_size) +
                            " (truncated or padded file)");
  }

  // The body is mapped, not read: no copy, and the pages come straight from the page cache.
  RECOG_ASSIGN_OR_RETURN(LayoutBuffer body, LayoutBuffer::MapFile(path, kHeaderSize, body_size));
  auto vocabulary = Vocabulary::FromLayout(info, num_nodes, num_words, std::move(body));
  if (!vocabulary.ok()) return vocabulary.status().WithContext(where, StatusCode::kDataLoss);
  if (vocabulary->checksum() != checksum) {
    return Status::DataLoss(where + " is corrupt (body checksum mismatch)");
  }
  return vocabulary;
}

StatusOr<Vocabulary> LoadAnyVocabulary(const std::string& path) {
  RECOG_ASSIGN_OR_RETURN(VocabularyFileFormat format, DetectVocabularyFormat(path));
  switch (format) {
    case VocabularyFileFormat::kRecog:
      return LoadVocabulary(path);
    case VocabularyFileFormat::kDbow2Text:
      return ImportDbow2Text(path);
    case VocabularyFileFormat::kDbow2Yaml:
      return ImportDbow2Yaml(path);
  }
  return Status::Internal("unhandled vocabulary format");
}

std::string BundledVocabularyPath(const std::string& file_name) {
  if (const char* env = std::getenv("RECOG_VOCABULARY_DIR"); env != nullptr && *env != '\0') {
    return std::string(env) + "/" + file_name;
  }
  const std::string in_source = std::string(RECOG_DEFAULT_VOCABULARY_DIR) + "/" + file_name;
  const std::string installed = std::string(RECOG_INSTALLED_VOCABULARY_DIR) + "/" + file_name;
  return std::filesystem::exists(in_source) || !std::filesystem::exists(installed) ? in_source
                                                                                   : installed;
}

std::string DefaultPlaceVocabularyPath() { return BundledVocabularyPath("place_orb_k10_l5.rvoc"); }
std::string DefaultObjectVocabularyPath() {
  return BundledVocabularyPath("object_orb_t12_k10_l4.rvoc");
}

}  // namespace recog
