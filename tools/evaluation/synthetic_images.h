// Pieces the synthetic sequence generators share (`recog seqgen` for places and for objects):
// seeded random streams that do not depend on the standard library's distributions, range
// checks with clear errors, decoding photos, the camera effects applied to every rendered frame
// (blur, illumination, noise) and writing images into a fresh output folder.
#pragma once

#include <cstdint>
#include <random>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "core/common/status.h"

namespace recog::cli {

// Seed of item `index` of random stream `stream`: a bijective mix, so nearby (seed, stream,
// index) triples give unrelated generators.
uint64_t StreamSeed(uint64_t seed, uint64_t stream, uint64_t index);

// Uniform in [lo, hi), written out (not std::uniform_real_distribution) so that sequences do not
// depend on the standard library's implementation; Symmetric: uniform in [-limit, limit).
double Uniform(std::mt19937_64& rng, double lo, double hi);
double Symmetric(std::mt19937_64& rng, double limit);

// OK when value is finite and in [lo, hi]; otherwise INVALID_ARGUMENT "<name> = v is outside
// [lo, hi]".
Status CheckRange(const char* name, double value, double lo, double hi);

// A photo as 8-bit grey or BGR (alpha dropped). NOT_FOUND when the file does not exist,
// INVALID_ARGUMENT when it cannot be decoded or has another channel count.
StatusOr<cv::Mat> ReadPhoto(const std::string& path);

// What a camera adds to a rendered frame.
struct CameraEffects {
  double blur_sigma = 0;                  // Gaussian blur (BORDER_REFLECT); none below 0.2
  double gain = 1;                        // multiplicative illumination
  double gradient_x = 0, gradient_y = 0;  // illumination gradient, centre to edge
  double noise_sigma = 0;                 // additive Gaussian noise, grey levels
  uint64_t noise_seed = 0;                // cv::RNG seed of the noise
};

// Applies `effects` to an 8-bit image in place: blur, then the illumination gain (global times a
// linear gradient, at least 0.05) and the noise, rounding to 8 bits with saturation.
void ApplyCameraEffects(const CameraEffects& effects, cv::Mat* image);

// Makes `dir` ready for a generator's output: creates it; INVALID_ARGUMENT when it exists and is
// not an empty folder (never overwrites data), INTERNAL when it cannot be created.
Status PrepareOutputFolder(const std::string& dir);

// cv::imwrite with a Status: INTERNAL naming the path when it fails.
Status WriteImage(const std::string& path, const cv::Mat& image,
                  const std::vector<int>& params = {});

}  // namespace recog::cli
