// The object messages of recognition/v1/object.proto and repository.proto and core's object
// types: a detection and the explanation of an object's outcome, to the wire; a request's object
// filter and detection options, from it; and a model version's info in both directions (a replica
// copies its primary's versions).
#pragma once

#include "core/object/model/object_model.h"
#include "core/object/recognition/detection.h"
#include "core/object/recognition/object_recognizer.h"
#include "core/object/repository/model_repository.h"
#include "recognition/v1/object.pb.h"
#include "recognition/v1/repository.pb.h"

namespace recog::server {

namespace pb = ::recognition::v1;

// One detection (the detection carries its model's class and units).
void ToProto(const Detection& detection, pb::DetectedObject* out);
void ToProto(const ObjectExplanation& explanation, pb::ObjectExplanation* out);
pb::ObjectType ToProto(ObjectType type);
ObjectFilter FromProto(const pb::ObjectFilter& filter);
// What a request asks each detection to carry (inliers, covariance); unset = nothing extra.
DetectionOptions FromProto(const pb::DetectionOptions& options);

void ToProto(const ModelVersionInfo& info, pb::ModelInfo* out);
// The inverse of ToProto (a replica copying its primary's versions); missing dimensions are 0.
ModelVersionInfo FromProto(const pb::ModelInfo& info);

}  // namespace recog::server
