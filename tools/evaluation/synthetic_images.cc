#include "tools/evaluation/synthetic_images.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

namespace recog::cli {
namespace {

namespace fs = std::filesystem;

uint64_t SplitMix64(uint64_t x) {
  x += 0x9e3779b97f4a7c15ULL;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
  return x ^ (x >> 31);
}

// Multiplies by the illumination gain (global times a linear gradient, at least 0.05) and adds the
// noise, rounding to 8 bits with saturation.
void ApplyIllumination(const cv::Mat& src, const cv::Mat& noise, double gain, double gradient_x,
                       double gradient_y, cv::Mat* dst) {
  dst->create(src.size(), src.type());
  const int channels = src.channels();
  const double cx = (src.cols - 1) / 2.0, cy = (src.rows - 1) / 2.0;
  const double sx = gradient_x / std::max(1.0, src.cols / 2.0);
  const double sy = gradient_y / std::max(1.0, src.rows / 2.0);
  for (int y = 0; y < src.rows; ++y) {
    const uint8_t* in = src.ptr<uint8_t>(y);
    const float* n = noise.empty() ? nullptr : noise.ptr<float>(y);
    uint8_t* out = dst->ptr<uint8_t>(y);
    const double row_gain = 1 + sy * (y - cy);
    for (int x = 0; x < src.cols; ++x) {
      const float g = float(std::max(0.05, gain * (row_gain + sx * (x - cx))));
      for (int c = 0; c < channels; ++c) {
        const int k = x * channels + c;
        float v = float(in[k]) * g;
        if (n != nullptr) v += n[k];
        out[k] = cv::saturate_cast<uint8_t>(v);
      }
    }
  }
}

}  // namespace

uint64_t StreamSeed(uint64_t seed, uint64_t stream, uint64_t index) {
  return SplitMix64(SplitMix64(seed ^ SplitMix64(stream)) + index);
}

double Uniform(std::mt19937_64& rng, double lo, double hi) {
  return lo + (hi - lo) * (double(rng() >> 11) * 0x1.0p-53);
}

double Symmetric(std::mt19937_64& rng, double limit) { return Uniform(rng, -limit, limit); }

Status CheckRange(const char* name, double value, double lo, double hi) {
  if (!std::isfinite(value) || value < lo || value > hi) {
    char buf[200];
    std::snprintf(buf, sizeof(buf), "%s = %g is outside [%g, %g]", name, value, lo, hi);
    return Status::InvalidArgument(buf);
  }
  return Status::Ok();
}

StatusOr<cv::Mat> ReadPhoto(const std::string& path) {
  std::error_code ec;
  if (!fs::exists(path, ec)) return Status::NotFound("photo '" + path + "' does not exist");
  cv::Mat photo;
  try {
    photo = cv::imread(path, cv::IMREAD_ANYCOLOR);  // 8-bit grey or BGR
  } catch (const cv::Exception& e) {
    return Status::InvalidArgument("photo '" + path + "' could not be decoded: " + e.what());
  }
  if (photo.empty())
    return Status::InvalidArgument("photo '" + path + "' is not a decodable image");
  if (photo.depth() != CV_8U) photo.convertTo(photo, CV_8U);
  if (photo.channels() == 4) cv::cvtColor(photo, photo, cv::COLOR_BGRA2BGR);
  if (photo.channels() != 1 && photo.channels() != 3) {
    return Status::InvalidArgument("photo '" + path + "' has " + std::to_string(photo.channels()) +
                                   " channels (expected grey or colour)");
  }
  return photo;
}

void ApplyCameraEffects(const CameraEffects& effects, cv::Mat* image) {
  if (effects.blur_sigma >= 0.2) {
    cv::GaussianBlur(*image, *image, cv::Size(), effects.blur_sigma, effects.blur_sigma,
                     cv::BORDER_REFLECT);
  }
  if (effects.gain == 1 && effects.gradient_x == 0 && effects.gradient_y == 0 &&
      effects.noise_sigma == 0) {
    return;
  }
  cv::Mat noise;
  if (effects.noise_sigma > 0) {
    noise.create(image->size(), CV_32FC(image->channels()));
    cv::RNG noise_rng(effects.noise_seed);
    noise_rng.fill(noise, cv::RNG::NORMAL, 0.0, effects.noise_sigma);
  }
  cv::Mat out;
  ApplyIllumination(*image, noise, effects.gain, effects.gradient_x, effects.gradient_y, &out);
  *image = std::move(out);
}

Status PrepareOutputFolder(const std::string& dir) {
  std::error_code ec;
  if (fs::exists(dir, ec)) {
    if (!fs::is_directory(dir, ec)) {
      return Status::InvalidArgument("output '" + dir + "' exists and is not a folder");
    }
    if (!fs::is_empty(dir, ec) || ec) {
      return Status::InvalidArgument("output folder '" + dir +
                                     "' is not empty; refusing to overwrite it");
    }
  }
  fs::create_directories(dir, ec);
  if (ec) return Status::Internal("cannot create folder '" + dir + "': " + ec.message());
  return Status::Ok();
}

Status WriteImage(const std::string& path, const cv::Mat& image, const std::vector<int>& params) {
  bool written = false;
  try {
    written = cv::imwrite(path, image, params);
  } catch (const cv::Exception& e) {
    return Status::Internal("cannot write '" + path + "': " + e.what());
  }
  if (!written) return Status::Internal("cannot write '" + path + "'");
  return Status::Ok();
}

}  // namespace recog::cli
