#include "core/common/descriptor.h"

#include <opencv2/core.hpp>

namespace recog {

int DescriptorFormat::cv_type() const { return type == DescriptorType::kBinary ? CV_8U : CV_32F; }

std::string DescriptorFormat::ToString() const {
  if (type == DescriptorType::kBinary) return "binary-" + std::to_string(size_bytes * 8);
  return "float-" + std::to_string(size_bytes / 4);
}

Status DescriptorFormat::Validate() const {
  if (type != DescriptorType::kBinary && type != DescriptorType::kFloat) {
    return Status::InvalidArgument("unknown descriptor type " + std::to_string(int(type)));
  }
  const uint32_t unit = type == DescriptorType::kBinary ? 8 : 4;
  if (size_bytes == 0 || size_bytes > 4096 || size_bytes % unit != 0) {
    return Status::InvalidArgument(
        "descriptor size of " + std::to_string(size_bytes) + " bytes is not valid for " +
        (type == DescriptorType::kBinary ? "binary" : "float") + " descriptors (a multiple of " +
        std::to_string(unit) + " between " + std::to_string(unit) + " and 4096)");
  }
  return Status::Ok();
}

Status CheckDescriptorMatrix(const cv::Mat& descriptors, const DescriptorFormat& format) {
  if (descriptors.empty()) return Status::Ok();
  if (descriptors.dims != 2 || descriptors.channels() != 1 ||
      descriptors.depth() != format.cv_type() || descriptors.cols != format.cols()) {
    return Status::InvalidArgument("descriptors have " + std::to_string(descriptors.cols) +
                                   " columns of type " + cv::typeToString(descriptors.type()) +
                                   "; expected " + format.ToString() + " (" +
                                   std::to_string(format.cols()) + " columns of type " +
                                   cv::typeToString(format.cv_type()) + ")");
  }
  if (!descriptors.isContinuous()) {
    return Status::InvalidArgument("descriptor matrix must be continuous (clone() a ROI first)");
  }
  return Status::Ok();
}

}  // namespace recog
