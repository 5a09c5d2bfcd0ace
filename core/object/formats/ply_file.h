// PLY point clouds (the Stanford polygon format) as object models use them: the vertex element's
// positions and, when present, normals. The reader takes ASCII and binary_little_endian files and
// skips every other element and property (faces, colours, confidences); it validates what it
// reads and returns DATA_LOSS naming the file and line for malformed input, NOT_FOUND for a
// missing file. The writer writes ASCII, atomically.
#pragma once

#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "core/common/status.h"

namespace recog {

// A PLY point cloud: positions, and normals when the file has them (else empty).
struct PointCloud {
  std::vector<cv::Point3f> points;
  std::vector<cv::Vec3f> normals;  // empty, or one per point
};

// Reads an ASCII or binary_little_endian PLY file's vertex element (x y z, optional nx ny nz;
// other properties are skipped).
StatusOr<PointCloud> ReadPly(const std::string& path);
// Writes an ASCII PLY (with normals when cloud.normals is not empty), atomically.
Status WritePly(const std::string& path, const PointCloud& cloud);

}  // namespace recog
