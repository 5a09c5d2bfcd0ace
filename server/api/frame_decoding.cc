#include "server/api/frame_decoding.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/common/elapsed.h"
#include "core/common/text.h"

namespace recog::server {
namespace {

bool Finite(double v) { return std::isfinite(v); }

// An encoded JPEG or PNG as 8-bit grey; its declared size is charged to `budget` before it is
// decoded.
StatusOr<cv::Mat> DecodeEncodedImage(const std::string& bytes, PixelBudget& budget,
                                     const std::string& field = "frame.encoded_image") {
  if (bytes.empty()) return Status::InvalidArgument(field + " is empty");
  RECOG_ASSIGN_OR_RETURN(const ImageHeader header, ReadImageHeader(bytes, field));
  RECOG_RETURN_IF_ERROR(budget.Take(header, field));
  const cv::Mat buffer(1, int(bytes.size()), CV_8UC1, const_cast<char*>(bytes.data()));
  cv::Mat image;
  try {
    image = cv::imdecode(buffer, cv::IMREAD_GRAYSCALE);
  } catch (const cv::Exception&) {
    image.release();  // OpenCV refused it
  }
  if (image.empty()) {
    return Status::InvalidArgument(field + " is not a decodable JPEG or PNG image (" +
                                   std::to_string(bytes.size()) + " bytes)");
  }
  if (uint32_t(image.cols) != header.width || uint32_t(image.rows) != header.height) {
    return Status::InvalidArgument(field + " decodes to another size than its header declares");
  }
  if (image.depth() != CV_8U) image.convertTo(image, CV_8U, 1.0 / 256.0);  // 16-bit PNG
  return image;
}

StatusOr<cv::Mat> DecodeRawImage(const pb::RawImage& raw, PixelBudget& budget,
                                 const std::string& field = "frame.raw_image") {
  RECOG_RETURN_IF_ERROR(budget.Take(raw.width(), raw.height(), field));
  int channels = 0;
  switch (raw.format()) {
    case pb::PIXEL_FORMAT_GRAY8:
      channels = 1;
      break;
    case pb::PIXEL_FORMAT_BGR8:
      channels = 3;
      break;
    default:
      return Status::InvalidArgument(field + ".format must be GRAY8 or BGR8");
  }
  const uint64_t expected = uint64_t(raw.width()) * raw.height() * uint64_t(channels);
  if (raw.pixels().size() != expected) {
    return Status::InvalidArgument(field + ".pixels has " + std::to_string(raw.pixels().size()) +
                                   " bytes; " + std::to_string(raw.width()) + "x" +
                                   std::to_string(raw.height()) + "x" + std::to_string(channels) +
                                   " needs " + std::to_string(expected));
  }
  const cv::Mat view(int(raw.height()), int(raw.width()), CV_8UC(channels),
                     const_cast<char*>(raw.pixels().data()));
  cv::Mat grey;
  if (channels == 3) {
    cv::cvtColor(view, grey, cv::COLOR_BGR2GRAY);
  } else {
    grey = view.clone();
  }
  return grey;
}

StatusOr<FeatureSet> DecodeFeatures(const pb::Features& features, const DescriptorFormat& format) {
  if (features.descriptor_bytes() != format.size_bytes) {
    return Status::InvalidArgument(
        "frame.features.descriptor_bytes is " + std::to_string(features.descriptor_bytes()) +
        "; the server's vocabulary uses " + std::to_string(format.size_bytes) + "-byte " +
        format.ToString() + " descriptors");
  }
  const pb::Keypoints& k = features.keypoints();
  const size_t n = size_t(k.x_size());
  const std::pair<const char*, int> arrays[] = {{"y", k.y_size()},
                                                {"size", k.size_size()},
                                                {"angle", k.angle_size()},
                                                {"response", k.response_size()},
                                                {"octave", k.octave_size()}};
  for (const auto& [name, size] : arrays) {
    if (size_t(size) != n) {
      return Status::InvalidArgument("frame.features.keypoints." + std::string(name) + " has " +
                                     std::to_string(size) + " values for " + std::to_string(n) +
                                     " keypoints (x); every array needs one per keypoint");
    }
  }
  if (n > kMaxClientFeatures) {
    return Status::InvalidArgument("frame.features has " + std::to_string(n) +
                                   " keypoints; at most " + std::to_string(kMaxClientFeatures));
  }
  if (features.descriptors().size() != n * format.size_bytes) {
    return Status::InvalidArgument("frame.features.descriptors has " +
                                   std::to_string(features.descriptors().size()) + " bytes; " +
                                   std::to_string(n) + " keypoints need " +
                                   std::to_string(n * format.size_bytes));
  }
  FeatureSet out;
  out.image_size = cv::Size(int(std::min<uint32_t>(features.image_width(), kMaxImageSide)),
                            int(std::min<uint32_t>(features.image_height(), kMaxImageSide)));
  out.keypoints.reserve(n);
  for (size_t i = 0; i < n; ++i) {
    const int j = int(i);
    if (!Finite(k.x(j)) || !Finite(k.y(j)) || !Finite(k.size(j)) || !Finite(k.angle(j)) ||
        !Finite(k.response(j))) {
      return Status::InvalidArgument(
          "frame.features.keypoints has a non-finite value at keypoint " + std::to_string(i));
    }
    out.keypoints.emplace_back(k.x(j), k.y(j), k.size(j), k.angle(j), k.response(j), k.octave(j));
  }
  out.descriptors.create(int(n), format.cols(), format.cv_type());
  if (n > 0)
    std::memcpy(out.descriptors.data, features.descriptors().data(), n * format.size_bytes);
  return out;
}

Status DecodeIntrinsics(const pb::CameraIntrinsics& in, CameraIntrinsics* out) {
  out->fx = in.fx();
  out->fy = in.fy();
  out->cx = in.cx();
  out->cy = in.cy();
  out->distortion.assign(in.distortion().begin(), in.distortion().end());
  RECOG_ASSIGN_OR_RETURN(out->lens, LensFromProto(in.lens(), "frame.intrinsics"));
  const Status valid = out->Validate();
  if (!valid.ok()) return valid.WithContext("frame.intrinsics", StatusCode::kInvalidArgument);
  return Status::Ok();
}

// A depth image: a 16-bit single-channel PNG, or raw 16-bit or float values.
Status DecodeDepth(const pb::DepthImage& in, PixelBudget& budget, DecodedFrame* out) {
  switch (in.content_case()) {
    case pb::DepthImage::kEncoded: {
      const std::string& bytes = in.encoded();
      if (bytes.empty()) return Status::InvalidArgument("frame.depth.encoded is empty");
      RECOG_ASSIGN_OR_RETURN(const ImageHeader header,
                             ReadImageHeader(bytes, "frame.depth.encoded"));
      if (header.format != ImageHeader::Format::kPng) {
        return Status::InvalidArgument("frame.depth.encoded must be a 16-bit PNG, not a JPEG");
      }
      if (header.components != 1 || header.bit_depth != 16) {
        return Status::InvalidArgument(
            "frame.depth.encoded must be a 16-bit single-channel PNG (its header declares " +
            Describe(header) + "); 8-bit depth is refused");
      }
      RECOG_RETURN_IF_ERROR(budget.Take(header, "frame.depth.encoded", 2));
      const cv::Mat buffer(1, int(bytes.size()), CV_8UC1, const_cast<char*>(bytes.data()));
      try {
        out->depth = cv::imdecode(buffer, cv::IMREAD_UNCHANGED);
      } catch (const cv::Exception&) {
        out->depth.release();
      }
      if (out->depth.empty()) {
        return Status::InvalidArgument("frame.depth.encoded is not a decodable PNG image (" +
                                       std::to_string(bytes.size()) + " bytes)");
      }
      if (out->depth.type() != CV_16UC1 || uint32_t(out->depth.cols) != header.width ||
          uint32_t(out->depth.rows) != header.height) {
        return Status::InvalidArgument(
            "frame.depth.encoded decodes to another size or type than its header declares");
      }
      break;
    }
    case pb::DepthImage::kRaw: {
      const pb::RawDepth& raw = in.raw();
      int type = 0;
      switch (raw.format()) {
        case pb::DEPTH_FORMAT_U16:
          type = CV_16UC1;
          break;
        case pb::DEPTH_FORMAT_F32:
          type = CV_32FC1;
          break;
        default:
          return Status::InvalidArgument("frame.depth.raw.format must be U16 or F32");
      }
      RECOG_RETURN_IF_ERROR(
          budget.Take(raw.width(), raw.height(), "frame.depth.raw", CV_ELEM_SIZE(type)));
      const uint64_t expected = uint64_t(raw.width()) * raw.height() * CV_ELEM_SIZE(type);
      if (raw.data().size() != expected) {
        return Status::InvalidArgument(
            "frame.depth.raw.data has " + std::to_string(raw.data().size()) + " bytes; " +
            std::to_string(raw.width()) + "x" + std::to_string(raw.height()) + " needs " +
            std::to_string(expected));
      }
      out->depth =
          cv::Mat(int(raw.height()), int(raw.width()), type, const_cast<char*>(raw.data().data()))
              .clone();
      break;
    }
    case pb::DepthImage::CONTENT_NOT_SET:
      return Status::InvalidArgument("frame.depth has no content: set encoded or raw");
  }
  if (!Finite(in.scale()) || in.scale() < 0) {
    return Status::InvalidArgument(
        "frame.depth.scale must be finite and >= 0 (0 = 1000 per metre)");
  }
  out->depth_scale = 1.0 / (in.scale() == 0 ? 1000.0 : in.scale());
  return Status::Ok();
}

Status DecodeRight(const pb::StereoRight& in, PixelBudget& budget, DecodedFrame* out) {
  if (!Finite(in.baseline_m()) || in.baseline_m() <= 0) {
    return Status::InvalidArgument("frame.right.baseline_m must be set, in metres, > 0 (got " +
                                   std::to_string(in.baseline_m()) + ")");
  }
  out->baseline_m = in.baseline_m();
  switch (in.content_case()) {
    case pb::StereoRight::kEncodedImage: {
      RECOG_ASSIGN_OR_RETURN(
          out->right, DecodeEncodedImage(in.encoded_image(), budget, "frame.right.encoded_image"));
      return Status::Ok();
    }
    case pb::StereoRight::kRawImage: {
      RECOG_ASSIGN_OR_RETURN(out->right,
                             DecodeRawImage(in.raw_image(), budget, "frame.right.raw_image"));
      return Status::Ok();
    }
    case pb::StereoRight::CONTENT_NOT_SET:
      break;
  }
  return Status::InvalidArgument("frame.right has no image: set encoded_image or raw_image");
}

std::string SizeText(cv::Size size) {
  return std::to_string(size.width) + "x" + std::to_string(size.height);
}

// Decodes the frame's depth or right image and checks that it goes with the frame.
Status DecodeStructure(const pb::Frame& frame, PixelBudget& budget, DecodedFrame* out) {
  if (frame.has_depth() && frame.has_right()) {
    return Status::InvalidArgument("a frame carries depth or a right image, not both");
  }
  const char* field = frame.has_depth() ? "frame.depth" : "frame.right";
  if (!out->intrinsics.has_value()) {
    return Status::InvalidArgument(std::string(field) + " needs frame.intrinsics (the camera " +
                                   "matrix turns its pixels into 3D points)");
  }
  for (double d : out->intrinsics->distortion) {
    if (d != 0) {
      return Status::InvalidArgument(
          std::string(field) + " needs pinhole pixels: undistort (or rectify) the image and send " +
          "frame.intrinsics without distortion");
    }
  }
  cv::Size size = out->image.size();
  if (frame.has_depth()) {
    RECOG_RETURN_IF_ERROR(DecodeDepth(frame.depth(), budget, out));
    if (!out->has_image()) {  // client features: their image size, when given
      const pb::Features& features = frame.features();
      size = features.image_width() == 0 && features.image_height() == 0
                 ? out->depth.size()
                 : cv::Size(int(features.image_width()), int(features.image_height()));
    }
    if (out->depth.size() != size) {
      return Status::InvalidArgument("frame.depth is " + SizeText(out->depth.size()) +
                                     "; it must be aligned with the " + SizeText(size) + " image");
    }
    return Status::Ok();
  }
  if (!out->has_image()) {
    return Status::InvalidArgument(
        "frame.right needs the left image (encoded_image or raw_image), not features");
  }
  RECOG_RETURN_IF_ERROR(DecodeRight(frame.right(), budget, out));
  if (out->right.size() != size) {
    return Status::InvalidArgument("frame.right is " + SizeText(out->right.size()) +
                                   "; it must be the size of the " + SizeText(size) +
                                   " left image");
  }
  return Status::Ok();
}

// INVALID_ARGUMENT naming `field` for a width x height image of zero size or beyond one image's.
Status CheckImageSize(uint64_t width, uint64_t height, const std::string& field) {
  if (width == 0 || height == 0) {
    return Status::InvalidArgument(field + " has zero size (" + std::to_string(width) + "x" +
                                   std::to_string(height) + ")");
  }
  if (width > kMaxImageSide || height > kMaxImageSide || width * height > kMaxImagePixels) {
    return Status::InvalidArgument(field + " is too large (" + std::to_string(width) + "x" +
                                   std::to_string(height) + "; at most " +
                                   std::to_string(kMaxImageSide) + " pixels a side and " +
                                   std::to_string(kMaxImagePixels >> 20) + " Mpixel)");
  }
  return Status::Ok();
}

// Bytes in MiB, rounded up: "576 MiB".
std::string MiBText(uint64_t bytes) {
  return std::to_string((bytes + (1 << 20) - 1) >> 20) + " MiB";
}

}  // namespace

// The proto's lens enum numbers the models as core's LensModel does.
static_assert(int(pb::LENS_MODEL_RADTAN) == int(LensModel::kRadialTangential) &&
              int(pb::LENS_MODEL_EQUIDISTANT) == int(LensModel::kEquidistant) &&
              int(pb::LENS_MODEL_DOUBLE_SPHERE) == int(LensModel::kDoubleSphere));

StatusOr<LensModel> LensFromProto(int lens, const std::string& field) {
  if (!pb::LensModel_IsValid(lens)) {
    return Status::InvalidArgument(field + ".lens " + std::to_string(lens) +
                                   " is not a lens model (radtan 0, equidistant 1, "
                                   "double sphere 2)");
  }
  return LensModel(lens);
}

Status PixelBudget::Take(const ImageHeader& header, const std::string& field,
                         uint32_t bytes_per_pixel) {
  RECOG_RETURN_IF_ERROR(CheckImageSize(header.width, header.height, field));
  if (header.format == ImageHeader::Format::kJpeg && header.scans > kMaxJpegScans) {
    return Status::InvalidArgument(field + " is a JPEG of " + std::to_string(header.scans) +
                                   " scans; at most " + std::to_string(kMaxJpegScans) +
                                   " (a progressive JPEG has about 10)");
  }
  return Charge(uint64_t(header.width) * header.height, MemoryToDecode(header, bytes_per_pixel),
                Describe(header), field);
}

Status PixelBudget::Take(uint64_t width, uint64_t height, const std::string& field,
                         uint32_t bytes_per_pixel) {
  RECOG_RETURN_IF_ERROR(CheckImageSize(width, height, field));
  return Charge(width * height, DecodeMemory{width * height * bytes_per_pixel, 0},
                std::to_string(width) + "x" + std::to_string(height), field);
}

Status PixelBudget::Charge(uint64_t pixels, const DecodeMemory& memory, const std::string& what,
                           const std::string& field) {
  if (memory.total() > kMaxImageDecodeBytes) {
    // Buffers larger than the image itself: libjpeg holding every coefficient of the image.
    const bool whole_coefficients = memory.decoder > memory.image;
    return Status::InvalidArgument(
        field + " (" + what + ") needs " + MiBText(memory.total()) + " to decode; at most " +
        MiBText(kMaxImageDecodeBytes) + " an image" +
        (whole_coefficients ? " (libjpeg holds every coefficient of a progressive JPEG, 2 bytes "
                              "each): send a baseline JPEG or a smaller image"
                            : ": send a smaller image"));
  }
  if (pixels > pixels_left_) {
    return Status::InvalidArgument(field + " (" + what + ") takes the call's images beyond " +
                                   std::to_string(kMaxCallPixels >> 20) +
                                   " Mpixel together; send fewer or smaller images per call");
  }
  if (memory.total() > decode_bytes_left_) {
    return Status::InvalidArgument(field + " (" + what + ", " + MiBText(memory.total()) +
                                   " to decode) takes the call's images beyond " +
                                   MiBText(max_decode_bytes_) + " of memory together (" +
                                   MiBText(max_decode_bytes_ - decode_bytes_left_) +
                                   " decoded already); send fewer or smaller images per call");
  }
  pixels_left_ -= pixels;
  decode_bytes_left_ -= memory.image;  // the decoder's buffers are freed once it has decoded
  return Status::Ok();
}

Status DecodeFrameHeader(const pb::Frame& frame, DecodedFrame* out) {
  if (frame.camera_id().size() > kMaxFrameIdBytes ||
      frame.client_frame_id().size() > kMaxFrameIdBytes) {
    return Status::InvalidArgument(
        "frame.camera_id and frame.client_frame_id are at most 128 bytes");
  }
  if (!IsValidUtf8(frame.camera_id()) || !IsValidUtf8(frame.client_frame_id())) {
    return Status::InvalidArgument("frame.camera_id and frame.client_frame_id must be UTF-8");
  }
  if (frame.has_timestamp() && (!Finite(frame.timestamp()) || frame.timestamp() < 0)) {
    return Status::InvalidArgument("frame.timestamp must be finite and >= 0");
  }
  if (frame.has_timestamp()) out->timestamp = frame.timestamp();
  out->camera_id = frame.camera_id();
  out->client_frame_id = frame.client_frame_id();
  if (frame.exclude_frame_ids_size() > kMaxExcludedFrames) {
    return Status::InvalidArgument("frame.exclude_frame_ids has " +
                                   std::to_string(frame.exclude_frame_ids_size()) +
                                   " ids; at most " + std::to_string(kMaxExcludedFrames));
  }
  for (const uint64_t id : frame.exclude_frame_ids()) {
    // An id no map can hold (frame ids are 32-bit) excludes nothing.
    if (id < kInvalidEntryId) out->excluded_frames.push_back(EntryId(id));
  }
  return Status::Ok();
}

StatusOr<DecodedFrame> DecodeFrame(const pb::Frame& frame, const DescriptorFormat& format,
                                   PixelBudget& budget, const CameraIntrinsics* camera) {
  DecodedFrame out;
  RECOG_RETURN_IF_ERROR(DecodeFrameHeader(frame, &out));
  if (frame.views_size() > 0) {
    return Status::InvalidArgument(
        "frame.views are for rig maps (MapSettings.rig); this call takes one image in the frame");
  }
  if (camera != nullptr) {
    out.intrinsics = *camera;
  } else if (frame.has_intrinsics()) {
    CameraIntrinsics intrinsics;
    RECOG_RETURN_IF_ERROR(DecodeIntrinsics(frame.intrinsics(), &intrinsics));
    out.intrinsics = std::move(intrinsics);
  }
  const auto start = std::chrono::steady_clock::now();
  switch (frame.content_case()) {
    case pb::Frame::kEncodedImage: {
      RECOG_ASSIGN_OR_RETURN(out.image, DecodeEncodedImage(frame.encoded_image(), budget));
      break;
    }
    case pb::Frame::kRawImage: {
      RECOG_ASSIGN_OR_RETURN(out.image, DecodeRawImage(frame.raw_image(), budget));
      break;
    }
    case pb::Frame::kFeatures: {
      RECOG_ASSIGN_OR_RETURN(out.features, DecodeFeatures(frame.features(), format));
      break;
    }
    case pb::Frame::CONTENT_NOT_SET:
      return Status::InvalidArgument(
          "the frame has no content: set encoded_image, raw_image or features");
  }
  if (frame.has_depth() || frame.has_right()) {
    RECOG_RETURN_IF_ERROR(DecodeStructure(frame, budget, &out));
  }
  out.decode_ms = MillisecondsSince(start);
  return out;
}

}  // namespace recog::server
