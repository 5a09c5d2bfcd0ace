// StaticFiles: the files the console serves, by exact name. The list is made once, at start,
// from the folders given (the pages, Debian's three.js and Chart.js): every regular file of a
// known type gets the URL path of its place in its folder, and a request is answered only when
// its decoded path is one of them. Nothing else is reachable (no "..", no NUL trick such as
// "main.js%00.html", no file added later), and each file's type comes from its own extension.
// Thread-safe once built (const).
#pragma once

#include <string>
#include <string_view>
#include <unordered_map>

namespace recog::server {

class StaticFiles {
 public:
  struct File {
    std::string path;          // on disk
    std::string content_type;  // from its extension
  };

  // Adds the files under `folder` (recursively, symbolic links followed; hidden files and files of
  // other types left out) as `url_prefix` + "/" + their path in the folder. A missing folder adds
  // nothing. At most kMaxFiles in all.
  void AddFolder(const std::string& url_prefix, const std::string& folder);

  // The file served at `url_path`, or null.
  const File* Find(std::string_view url_path) const;

  size_t size() const { return files_.size(); }

  static constexpr size_t kMaxFiles = 50000;

 private:
  std::unordered_map<std::string, File> files_;  // by URL path
};

// The content type of a file the console serves, from its extension; "" for other files.
std::string_view StaticContentType(std::string_view extension);

}  // namespace recog::server
