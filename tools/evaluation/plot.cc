#include "tools/evaluation/plot.h"

#include <cstdio>
#include <filesystem>
#include <fstream>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

namespace recog::cli {
namespace {

// A CSV field, quoted when it holds a comma, a quote or a line break (RFC 4180).
std::string CsvField(const std::string& text) {
  if (text.find_first_of(",\"\r\n") == std::string::npos) return text;
  std::string quoted = "\"";
  for (char c : text) {
    if (c == '"') quoted += '"';
    quoted += c;
  }
  return quoted + '"';
}

Status WritePlotCsv(const std::string& path, const PlotOptions& o,
                    const std::vector<PlotSeries>& series) {
  std::ofstream out(path);
  out << "series," << CsvField(o.x_label.empty() ? "x" : o.x_label) << ','
      << CsvField(o.y_label.empty() ? "y" : o.y_label) << ",point_label\n";
  out.precision(10);
  for (const PlotSeries& s : series) {
    for (size_t i = 0; i < s.points.size(); ++i) {
      out << CsvField(s.label) << ',' << s.points[i].x << ',' << s.points[i].y << ','
          << CsvField(i < s.point_labels.size() ? s.point_labels[i] : "") << '\n';
    }
  }
  out.close();
  if (!out) return Status::Internal("cannot write the plot's CSV '" + path + "'");
  return Status::Ok();
}

}  // namespace

std::string PlotCsvPath(const std::string& png_path) {
  return std::filesystem::path(png_path).replace_extension(".csv").string();
}

Status WritePlot(const std::string& path, const PlotOptions& o,
                 const std::vector<PlotSeries>& series) {
  if (!(o.x_max > o.x_min) || !(o.y_max > o.y_min) || o.width < 200 || o.height < 150) {
    return Status::InvalidArgument("plot needs a non-empty range and at least 200x150 pixels");
  }
  if (std::filesystem::path(path).extension() == ".csv") {
    return Status::InvalidArgument("plot '" + path +
                                   "': the image needs another extension than .csv");
  }
  cv::Mat image(o.height, o.width, CV_8UC3, cv::Scalar(255, 255, 255));
  const int left = 70, right = 20, top = 60, bottom = 60;
  const int w = o.width - left - right, h = o.height - top - bottom;
  const auto to_pixel = [&](cv::Point2d p) {
    return cv::Point(left + int((p.x - o.x_min) / (o.x_max - o.x_min) * w),
                     top + h - int((p.y - o.y_min) / (o.y_max - o.y_min) * h));
  };
  const cv::Scalar black(0, 0, 0), grey(220, 220, 220);
  const int font = cv::FONT_HERSHEY_SIMPLEX;
  for (int i = 0; i <= 10; ++i) {  // grid and ticks
    const double fx = o.x_min + (o.x_max - o.x_min) * i / 10.0;
    const double fy = o.y_min + (o.y_max - o.y_min) * i / 10.0;
    const cv::Point px = to_pixel({fx, o.y_min}), py = to_pixel({o.x_min, fy});
    cv::line(image, px, {px.x, top}, grey, 1);
    cv::line(image, py, {left + w, py.y}, grey, 1);
    char buf[32];
    std::snprintf(buf, sizeof(buf), "%.2g", fx);
    cv::putText(image, buf, {px.x - 12, top + h + 20}, font, 0.45, black, 1, cv::LINE_AA);
    std::snprintf(buf, sizeof(buf), "%.2g", fy);
    cv::putText(image, buf, {left - 45, py.y + 5}, font, 0.45, black, 1, cv::LINE_AA);
  }
  cv::rectangle(image, {left, top}, {left + w, top + h}, black, 1);
  cv::putText(image, o.title, {left, 25}, font, 0.6, black, 1, cv::LINE_AA);
  cv::putText(image, o.x_label, {left + w / 2 - 40, o.height - 15}, font, 0.55, black, 1,
              cv::LINE_AA);
  cv::putText(image, o.y_label, {5, top - 12}, font, 0.55, black, 1, cv::LINE_AA);

  int legend_y = top + h - 20 * int(series.size());
  for (const PlotSeries& s : series) {
    for (size_t i = 0; i < s.points.size(); ++i) {
      const cv::Point p = to_pixel(s.points[i]);
      if (i > 0) cv::line(image, to_pixel(s.points[i - 1]), p, s.color, 2, cv::LINE_AA);
      cv::circle(image, p, 4, s.color, cv::FILLED, cv::LINE_AA);
      if (i < s.point_labels.size()) {
        cv::putText(image, s.point_labels[i], p + cv::Point(6, -6), font, 0.35, s.color, 1,
                    cv::LINE_AA);
      }
    }
    if (!s.label.empty()) {
      cv::line(image, {left + w - 180, legend_y}, {left + w - 150, legend_y}, s.color, 2);
      cv::putText(image, s.label, {left + w - 145, legend_y + 5}, font, 0.45, black, 1,
                  cv::LINE_AA);
      legend_y += 20;
    }
  }
  try {
    if (!cv::imwrite(path, image)) return Status::Internal("cannot write plot '" + path + "'");
  } catch (const cv::Exception& e) {
    return Status::Internal("cannot write plot '" + path + "': " + e.what());
  }
  return o.write_csv ? WritePlotCsv(PlotCsvPath(path), o, series) : Status::Ok();
}

}  // namespace recog::cli
