#include "tools/evaluation/plot.h"

#include <sys/wait.h>
#include <unistd.h>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <optional>
#include <sstream>

#include <nlohmann/json.hpp>

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

// A gnuplot string literal: double-quoted, with its backslashes and quotes escaped.
std::string GnuplotString(const std::string& text) {
  std::string quoted = "\"";
  for (char c : text) {
    if (c == '"' || c == '\\') quoted += '\\';
    quoted += (c == '\n' || c == '\r') ? ' ' : c;
  }
  return quoted + '"';
}

// "#rrggbb" of an OpenCV BGR colour.
std::string HexColor(const cv::Scalar& bgr) {
  char hex[8];
  std::snprintf(hex, sizeof(hex), "#%02x%02x%02x", int(bgr[2]) & 255, int(bgr[1]) & 255,
                int(bgr[0]) & 255);
  return hex;
}

// The chart as JSON (the web console draws it: docs/console.md, "Charts").
Status WritePlotJson(const std::string& path, const PlotOptions& o,
                     const std::vector<PlotSeries>& series) {
  nlohmann::json chart = {{"title", o.title},     {"x_label", o.x_label},
                          {"y_label", o.y_label}, {"x_min", o.x_min},
                          {"x_max", o.x_max},     {"y_min", o.y_min},
                          {"y_max", o.y_max},     {"series", nlohmann::json::array()}};
  for (const PlotSeries& s : series) {
    nlohmann::json points = nlohmann::json::array();
    for (const cv::Point2d& p : s.points) points.push_back({p.x, p.y});
    chart["series"].push_back({{"label", s.label},
                               {"color", HexColor(s.color)},
                               {"points", points},
                               {"point_labels", s.point_labels}});
  }
  std::ofstream out(path);
  out << chart.dump() << '\n';
  out.close();
  if (!out) return Status::Internal("cannot write the plot's JSON '" + path + "'");
  return Status::Ok();
}

// The gnuplot commands that draw the plot into `path`: each series as lines and points from an
// inline data block, its point labels thinned so that no two drawn labels of a series are closer
// than about 30 pixels (they are the same data in the CSV).
std::string GnuplotScript(const std::string& path, const PlotOptions& o,
                          const std::vector<PlotSeries>& series) {
  std::ostringstream gp;
  gp.precision(10);
  gp << "set terminal pngcairo size " << o.width << "," << o.height
     << " font \"DejaVu Sans,10\" noenhanced\n"
     << "set output " << GnuplotString(path) << "\n"
     << "set title " << GnuplotString(o.title) << "\n"
     << "set xlabel " << GnuplotString(o.x_label) << "\n"
     << "set ylabel " << GnuplotString(o.y_label) << "\n"
     << "set xrange [" << o.x_min << ":" << o.x_max << "]\n"
     << "set yrange [" << o.y_min << ":" << o.y_max << "]\n"
     << "set grid\nset key bottom right box opaque\n";
  // Pixels per unit, approximately (the frame leaves ~120 x ~100 pixels for the axes' text).
  const double x_scale = (o.width - 120) / (o.x_max - o.x_min);
  const double y_scale = (o.height - 100) / (o.y_max - o.y_min);
  std::vector<std::string> plots;
  for (size_t k = 0; k < series.size(); ++k) {
    const PlotSeries& s = series[k];
    if (s.points.empty()) continue;
    const std::string block = "$series" + std::to_string(k);
    gp << block << " << EOD\n";
    std::optional<cv::Point2d> last_label;
    bool labelled = false;
    for (size_t i = 0; i < s.points.size(); ++i) {
      std::string label = i < s.point_labels.size() ? s.point_labels[i] : "";
      const cv::Point2d& p = s.points[i];
      if (!label.empty() && last_label.has_value() &&
          std::hypot((p.x - last_label->x) * x_scale, (p.y - last_label->y) * y_scale) < 30.0) {
        label.clear();
      }
      if (!label.empty()) {
        last_label = p;
        labelled = true;
      }
      gp << p.x << " " << p.y << " " << GnuplotString(label) << "\n";
    }
    gp << "EOD\n";
    const std::string color = HexColor(s.color);
    plots.push_back(block + " using 1:2 with linespoints lw 2 pt 7 ps 0.7 lc rgb \"" + color +
                    "\" title " + GnuplotString(s.label));
    if (labelled) {
      plots.push_back(block +
                      " using 1:2:3 with labels offset char 0.6,0.6 left font \",8\" tc rgb \"" +
                      color + "\" notitle");
    }
  }
  gp << "plot ";
  if (plots.empty()) gp << "NaN notitle";  // axes only
  for (size_t i = 0; i < plots.size(); ++i) gp << (i > 0 ? ", \\\n  " : "") << plots[i];
  gp << "\nset output\n";
  return gp.str();
}

// Runs gnuplot on `script`, which writes `path`. INTERNAL with gnuplot's own words when it fails
// or is missing.
Status RunGnuplot(const std::string& script, const std::string& path) {
  char dir_template[] = "/tmp/recog-plot-XXXXXX";
  const char* dir = ::mkdtemp(dir_template);
  if (dir == nullptr) return Status::Internal("cannot make a temporary folder for gnuplot");
  const std::filesystem::path script_path = std::filesystem::path(dir) / "plot.gp";
  std::string output;
  int code = -1;
  {
    std::ofstream out(script_path);
    out << script;
  }
  // The folder's name is mkdtemp's (letters, digits, '/' and '-'): nothing for the shell to read.
  if (FILE* pipe = ::popen(("gnuplot " + script_path.string() + " 2>&1").c_str(), "r")) {
    char buffer[512];
    while (std::fgets(buffer, sizeof(buffer), pipe) != nullptr) output += buffer;
    const int status = ::pclose(pipe);
    code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  }
  std::error_code ignored;
  std::filesystem::remove_all(dir, ignored);
  if (code == 127) {
    return Status::Internal("drawing plot '" + path +
                            "' needs gnuplot (Debian: apt-get install gnuplot-nox); its numbers "
                            "are in the CSV beside it");
  }
  if (code != 0 || !std::filesystem::exists(path)) {
    while (!output.empty() && (output.back() == '\n' || output.back() == ' ')) output.pop_back();
    return Status::Internal("cannot write plot '" + path +
                            "': gnuplot: " + (output.empty() ? "failed" : output));
  }
  return Status::Ok();
}

}  // namespace

std::string PlotCsvPath(const std::string& png_path) {
  return std::filesystem::path(png_path).replace_extension(".csv").string();
}

std::string PlotJsonPath(const std::string& png_path) {
  return std::filesystem::path(png_path).replace_extension(".json").string();
}

Status WritePlot(const std::string& path, const PlotOptions& o,
                 const std::vector<PlotSeries>& series) {
  if (!(o.x_max > o.x_min) || !(o.y_max > o.y_min) || o.width < 200 || o.height < 150) {
    return Status::InvalidArgument("plot needs a non-empty range and at least 200x150 pixels");
  }
  const std::string extension = std::filesystem::path(path).extension().string();
  if (extension == ".csv" || extension == ".json") {
    return Status::InvalidArgument("plot '" + path +
                                   "': the image needs another extension than .csv or .json");
  }
  if (o.write_csv) RECOG_RETURN_IF_ERROR(WritePlotCsv(PlotCsvPath(path), o, series));
  RECOG_RETURN_IF_ERROR(RunGnuplot(GnuplotScript(path, o, series), path));
  return WritePlotJson(PlotJsonPath(path), o, series);
}

}  // namespace recog::cli
