// Test helpers for the dataset readers' tests (dataset_layouts_test.cc, rig_dataset_test.cc): a
// fresh folder of files written by the test, and a check of an error's code and message.
#pragma once

#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include "core/common/status.h"

namespace recog::cli::testing {

// A fresh folder under the temp directory, removed at the end of the test, with helpers that
// write grey PNGs of `png_size` and text files in it.
class TestFolder {
 public:
  explicit TestFolder(const std::string& name, cv::Size png_size = {16, 16})
      : root_(std::filesystem::temp_directory_path() /
              ("recog_" + name + "_" + std::to_string(::getpid()))),
        png_size_(png_size) {
    std::filesystem::remove_all(root_);
    std::filesystem::create_directories(root_);
  }
  ~TestFolder() { std::filesystem::remove_all(root_); }
  std::string path() const { return root_.string(); }
  std::string operator/(const std::string& child) const { return (root_ / child).string(); }

  void Png(const std::string& name, int value = 128) const {
    std::filesystem::create_directories((root_ / name).parent_path());
    ASSERT_TRUE(cv::imwrite(*this / name, cv::Mat(png_size_, CV_8UC1, cv::Scalar(value))));
  }
  void Text(const std::string& name, const std::string& text) const {
    std::filesystem::create_directories((root_ / name).parent_path());
    std::ofstream(*this / name) << text;
  }

 private:
  std::filesystem::path root_;
  cv::Size png_size_;
};

// `result` failed with `code`, its message containing `needle`.
template <typename T>
void ExpectError(const StatusOr<T>& result, StatusCode code, const std::string& needle) {
  ASSERT_FALSE(result.ok());
  EXPECT_EQ(result.status().code(), code) << result.status().ToString();
  EXPECT_NE(result.status().message().find(needle), std::string::npos)
      << "no '" << needle << "' in: " << result.status().ToString();
}

}  // namespace recog::cli::testing
