// Line plots written as PNG images (OpenCV drawing, no plotting library): enough for the
// precision-recall curves and latency plots the evaluation tools produce.
#pragma once

#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "core/common/status.h"

namespace recog::cli {

struct PlotSeries {
  std::string label;
  std::vector<cv::Point2d> points;        // drawn in order, joined by lines
  cv::Scalar color{200, 80, 20};          // BGR
  std::vector<std::string> point_labels;  // optional, one per point (e.g. the alpha)
};

struct PlotOptions {
  std::string title;
  std::string x_label, y_label;
  double x_min = 0, x_max = 1, y_min = 0, y_max = 1;
  int width = 800, height = 600;
};

// Draws the series on axes with ticks and labels and writes `path` (PNG). INVALID_ARGUMENT for
// an empty range, INTERNAL when the file cannot be written.
Status WritePlotPng(const std::string& path, const PlotOptions& options,
                    const std::vector<PlotSeries>& series);

}  // namespace recog::cli
