#include "core/common/file_io.h"

#include <filesystem>

namespace recog {

namespace fs = std::filesystem;

StatusOr<std::string> ReadWholeFile(const std::string& path, const std::string& what) {
  std::error_code ec;
  const fs::file_status status = fs::status(path, ec);
  if (ec || !fs::exists(status)) return Status::NotFound(what + " does not exist");
  if (!fs::is_regular_file(status)) return Status::NotFound(what + " is not a regular file");
  const uintmax_t size = fs::file_size(path, ec);
  File file(std::fopen(path.c_str(), "rb"));
  if (ec || !file) return Status::NotFound("cannot open " + what);
  std::string content(size_t(size), '\0');
  if (std::fread(content.data(), 1, content.size(), file.get()) != content.size()) {
    return Status::DataLoss("cannot read " + what);
  }
  return content;
}

Status WriteFileAtomically(const std::string& path, std::initializer_list<std::string_view> parts) {
  const std::string tmp = path + ".tmp";
  {
    File file(std::fopen(tmp.c_str(), "wb"));
    if (!file) return Status::NotFound("cannot create '" + tmp + "'");
    bool written = true;
    for (std::string_view part : parts) {
      written = written && std::fwrite(part.data(), 1, part.size(), file.get()) == part.size();
    }
    if (!written || std::fflush(file.get()) != 0) {
      std::remove(tmp.c_str());
      return Status::ResourceExhausted("cannot write '" + tmp + "' (disk full?)");
    }
  }
  std::error_code ec;
  fs::rename(tmp, path, ec);
  if (ec) {
    std::remove(tmp.c_str());
    return Status::Internal("cannot rename '" + tmp + "' to '" + path + "': " + ec.message());
  }
  return Status::Ok();
}

}  // namespace recog
