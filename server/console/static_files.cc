#include "server/console/static_files.h"

#include <filesystem>
#include <system_error>

namespace recog::server {

namespace fs = std::filesystem;

std::string_view StaticContentType(std::string_view extension) {
  if (extension == ".html") return "text/html; charset=utf-8";
  if (extension == ".js" || extension == ".mjs") return "text/javascript; charset=utf-8";
  if (extension == ".css") return "text/css; charset=utf-8";
  if (extension == ".json" || extension == ".map") return "application/json";
  if (extension == ".png") return "image/png";
  if (extension == ".svg") return "image/svg+xml";
  if (extension == ".ico") return "image/x-icon";
  if (extension == ".woff2") return "font/woff2";
  return "";
}

void StaticFiles::AddFolder(const std::string& url_prefix, const std::string& folder) {
  std::error_code error;
  fs::recursive_directory_iterator it(folder, fs::directory_options::follow_directory_symlink,
                                      error);
  for (; !error && it != fs::recursive_directory_iterator() && files_.size() < kMaxFiles;
       it.increment(error)) {
    const fs::path& path = it->path();
    const std::string name = path.filename().string();
    if (name.starts_with(".")) {
      if (it->is_directory(error)) it.disable_recursion_pending();
      continue;
    }
    const std::string_view type = StaticContentType(path.extension().string());
    if (type.empty() || !it->is_regular_file(error)) continue;
    const std::string relative = path.lexically_relative(folder).generic_string();
    files_[url_prefix + "/" + relative] = File{path.string(), std::string(type)};
  }
}

const StaticFiles::File* StaticFiles::Find(std::string_view url_path) const {
  const auto it = files_.find(std::string(url_path));
  return it == files_.end() ? nullptr : &it->second;
}

}  // namespace recog::server
