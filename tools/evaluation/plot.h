// Line plots written as PNG images, drawn by gnuplot (Debian's gnuplot-nox, its pngcairo
// terminal): the precision-recall curves, recall and error curves and latency plots the
// evaluation tools produce. Every plot's numbers are written beside it as CSV (PlotCsvPath), for
// whoever would rather plot them their own way, and the whole chart as JSON (PlotJsonPath), which
// recogd's web console draws (docs/console.md, "Charts").
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
// The JSON beside it: the same path with the extension .json. It holds {"title", "x_label",
// "y_label", "x_min", "x_max", "y_min", "y_max", "series": [{"label", "color" ("#rrggbb"),
// "points": [[x, y], ...], "point_labels": [...]}]}.
std::string PlotJsonPath(const std::string& png_path);

// Writes, with write_csv, the plotted points to PlotCsvPath(path) (a header
// "series,<x_label>,<y_label>,point_label", then one row per point in drawing order), then draws
// the series (lines and points, a legend, a grid) with the title and axis labels and writes
// `path` (PNG, width x height), then writes the chart to PlotJsonPath(path). Point labels of a
// series closer than ~30 pixels to the previous drawn one are left out of the image (not the CSV)
// so that none overlap. INVALID_ARGUMENT for an empty range or a path ending in .csv or .json,
// INTERNAL when a file cannot be written or gnuplot fails or is missing (the CSV is written first,
// either way).
Status WritePlot(const std::string& path, const PlotOptions& options,
                 const std::vector<PlotSeries>& series);

}  // namespace recog::cli
