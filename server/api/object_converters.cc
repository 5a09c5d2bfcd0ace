#include "server/api/object_converters.h"

#include <algorithm>
#include <string>

#include "core/common/text.h"
#include "server/api/pose_converter.h"

namespace recog::server {

pb::ObjectType ToProto(ObjectType type) {
  return type == ObjectType::kPlanar ? pb::OBJECT_TYPE_PLANAR : pb::OBJECT_TYPE_3D;
}

void ToProto(const Detection& detection, pb::DetectedObject* out) {
  out->set_name(detection.name);
  out->set_version(detection.version);
  out->set_object_class(ToValidUtf8(detection.object_class));
  out->set_type(ToProto(detection.type));
  ToProto(detection.camera_from_object.R, detection.camera_from_object.t, out->mutable_pose());
  out->set_units(detection.units);
  out->set_inliers(uint32_t(detection.inliers));
  out->set_correspondences(uint32_t(detection.correspondences));
  out->set_reprojection_error_px(detection.reprojection_error_px);
  out->set_score(detection.score);
  for (const cv::Point2f& p : detection.outline) {
    pb::Point2* q = out->add_outline();
    q->set_x(p.x);
    q->set_y(p.y);
  }
  for (const InlierCorrespondence& c : detection.inliers_2d3d) {
    pb::InlierCorrespondence* q = out->add_inliers_2d3d();
    q->mutable_pixel()->set_x(c.pixel.x);
    q->mutable_pixel()->set_y(c.pixel.y);
    q->mutable_point()->set_x(c.point.x);
    q->mutable_point()->set_y(c.point.y);
    q->mutable_point()->set_z(c.point.z);
    q->set_point_id(c.point_id);
  }
  out->mutable_covariance()->Add(detection.covariance.begin(), detection.covariance.end());
  out->set_tracked(detection.tracked);
}

void ToProto(const ObjectExplanation& explanation, pb::ObjectExplanation* out) {
  out->set_name(explanation.name);
  switch (explanation.outcome) {
    case ObjectOutcome::kNotProposed:
      out->set_outcome(pb::OBJECT_OUTCOME_NOT_PROPOSED);
      break;
    case ObjectOutcome::kFewCorrespondences:
      out->set_outcome(pb::OBJECT_OUTCOME_FEW_CORRESPONDENCES);
      break;
    case ObjectOutcome::kFewInliers:
      out->set_outcome(pb::OBJECT_OUTCOME_FEW_INLIERS);
      break;
    case ObjectOutcome::kSuppressed:
      out->set_outcome(pb::OBJECT_OUTCOME_SUPPRESSED);
      break;
    case ObjectOutcome::kDetected:
      out->set_outcome(pb::OBJECT_OUTCOME_DETECTED);
      break;
  }
  out->set_regions(uint32_t(explanation.regions));
  out->set_best_score(explanation.best_score);
  out->set_correspondences(uint32_t(explanation.correspondences));
  out->set_inliers(uint32_t(explanation.inliers));
  out->set_min_inliers(uint32_t(explanation.min_inliers));
}

ObjectFilter FromProto(const pb::ObjectFilter& filter) {
  return {{filter.names().begin(), filter.names().end()},
          {filter.classes().begin(), filter.classes().end()}};
}

DetectionOptions FromProto(const pb::DetectionOptions& options) {
  return {options.include_inliers(), options.include_covariance()};
}

void ToProto(const ModelVersionInfo& info, pb::ModelInfo* out) {
  const ObjectMetadata& m = info.metadata;
  // Free text is checked at upload; a store written before that may hold other bytes, which
  // would make the whole answer unreadable to clients: they are replaced.
  out->set_name(m.name);
  out->set_version(m.version);
  out->set_object_class(ToValidUtf8(m.object_class));
  out->set_type(ToProto(m.type));
  for (int i = 0; i < 3; ++i) out->add_dimensions(m.dimensions[i]);
  out->set_units(ToValidUtf8(m.units));
  out->set_source(ToValidUtf8(m.source));
  for (const std::string& tag : info.tags) out->add_tags(ToValidUtf8(tag));
  out->set_sha256(info.sha256);
  out->set_size_bytes(info.size_bytes);
  out->set_created_unix_ms(info.created_unix_ms);
  out->set_num_points(info.num_points);
  out->set_num_descriptors(info.num_descriptors);
}

ModelVersionInfo FromProto(const pb::ModelInfo& info) {
  ModelVersionInfo out;
  ObjectMetadata& m = out.metadata;
  m.name = info.name();
  m.version = info.version();
  m.object_class = info.object_class();
  m.type = info.type() == pb::OBJECT_TYPE_PLANAR ? ObjectType::kPlanar : ObjectType::k3D;
  for (int i = 0; i < std::min(3, info.dimensions_size()); ++i)
    m.dimensions[i] = info.dimensions(i);
  m.units = info.units();
  m.source = info.source();
  out.tags.assign(info.tags().begin(), info.tags().end());
  out.sha256 = info.sha256();
  out.size_bytes = info.size_bytes();
  out.created_unix_ms = info.created_unix_ms();
  out.num_points = info.num_points();
  out.num_descriptors = info.num_descriptors();
  return out;
}

}  // namespace recog::server
