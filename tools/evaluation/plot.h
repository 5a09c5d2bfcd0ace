// Line plots written as PNG images (OpenCV drawing, no plotting library): enough for the
// precision-recall curves and latency plots the evaluation tools produce. Every plot's numbers
// are written beside it as CSV (PlotCsvPath), for whoever would rather plot them their own way.
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
  // false when the caller writes a richer CSV of its own at PlotCsvPath(path).
  bool write_csv = true;
};

// The CSV beside the plot `png_path`: the same path with the extension .csv.
std::string PlotCsvPath(const std::string& png_path);

// Draws the series on axes with ticks and labels and writes `path` (PNG), and, with write_csv,
// the plotted points to PlotCsvPath(path): a header "series,<x_label>,<y_label>,point_label",
// then one row per point in drawing order. INVALID_ARGUMENT for an empty range or a path ending
// in .csv, INTERNAL when a file cannot be written.
Status WritePlot(const std::string& path, const PlotOptions& options,
                 const std::vector<PlotSeries>& series);

}  // namespace recog::cli
