#include "core/object/recognition/object_database.h"

#include <cmath>
#include <numeric>

#include "core/geometry/correspondences.h"
#include "core/object/formats/model_file.h"

namespace recog {
namespace {

constexpr size_t kOutlinePoints = 300;

// The face whose rectangle lies nearest to `p` (planar objects).
uint32_t NearestFace(const std::vector<PlanarFace>& faces, const cv::Point3f& p) {
  uint32_t best = 0;
  double best_distance = INFINITY;
  for (uint32_t f = 0; f < faces.size(); ++f) {
    const cv::Point3d q = faces[f].object_from_face.Inverse().Apply(cv::Point3d(p));
    const double dx = std::max({0.0, -q.x, q.x - faces[f].width});
    const double dy = std::max({0.0, -q.y, q.y - faces[f].height});
    const double distance = std::hypot(dx, dy, q.z);
    if (distance < best_distance) {
      best_distance = distance;
      best = f;
    }
  }
  return best;
}

}  // namespace

ObjectDatabase::ObjectDatabase(std::unique_ptr<Database> index) : index_(std::move(index)) {}

StatusOr<std::unique_ptr<ObjectDatabase>> ObjectDatabase::Open(
    IndexStore* store, std::shared_ptr<const Vocabulary> vocabulary, const std::string& map_name) {
  const uint32_t levels_up = vocabulary->info().depth > 0 ? vocabulary->info().depth - 1 : 0;
  StatusOr<std::unique_ptr<Database>> index = Database::Open(store, map_name, vocabulary);
  if (index.status().code() == StatusCode::kNotFound) {
    index = Database::Create(store, map_name, vocabulary, ScoringType::kBhattacharyya, levels_up);
  }
  RECOG_RETURN_IF_ERROR(index.status());
  if (TraitsOf((*index)->info().config.scoring).normalization != BowNormalization::kL1) {
    return Status::FailedPrecondition("map '" + map_name + "' is not an object map");
  }
  std::unique_ptr<ObjectDatabase> database(new ObjectDatabase(std::move(*index)));
  RECOG_RETURN_IF_ERROR(store->ScanEntries(
      database->index_->info().id, 0, kEntryAllParts, [&](EntryRecord& record) -> Status {
        RECOG_ASSIGN_OR_RETURN(std::shared_ptr<const IndexedObject> object, database->Load(record));
        database->by_name_[object->metadata.name] = object->id;
        database->by_id_[object->id] = std::move(object);
        return Status::Ok();
      }));
  return database;
}

int ObjectDatabase::direct_levels_up() const {
  return int(index_->info().config.direct_index_levels_up);
}

size_t ObjectDatabase::size() const {
  std::shared_lock lock(objects_mutex_);
  return by_id_.size();
}

StatusOr<std::shared_ptr<const IndexedObject>> ObjectDatabase::Load(EntryRecord& record) const {
  const std::string where = "object entry " + std::to_string(record.id);
  RECOG_ASSIGN_OR_RETURN(ObjectModel header,
                         DecodeObjectModel(record.metadata.user_data, where + " header"));
  if (record.points.size() != size_t(record.descriptors.rows)) {
    return Status::DataLoss(where + " has no 3D point for every descriptor");
  }
  auto object = std::make_shared<IndexedObject>();
  object->id = record.id;
  object->metadata = std::move(header.metadata);
  object->faces = std::move(header.faces);
  object->descriptors = std::move(record.descriptors);
  object->points = std::move(record.points);
  object->direct = std::move(record.direct);
  if (object->direct.num_features() != size_t(object->descriptors.rows)) {
    return Status::DataLoss(where + "'s direct index does not hold every descriptor once");
  }
  auto ordered = DescriptorsInDirectOrder(object->direct, object->descriptors);
  if (!ordered.ok()) return Status::DataLoss(where + ": " + ordered.status().message());
  object->direct_descriptors = std::move(ordered).value();
  if (object->metadata.type == ObjectType::kPlanar) {
    object->face_of_feature.reserve(object->points.size());
    for (const cv::Point3f& p : object->points) {
      object->face_of_feature.push_back(NearestFace(object->faces, p));
    }
  }
  const size_t step = std::max<size_t>(1, object->points.size() / kOutlinePoints);
  for (size_t i = 0; i < object->points.size(); i += step) {
    object->outline_points.push_back(object->points[i]);
  }
  return std::shared_ptr<const IndexedObject>(std::move(object));
}

StatusOr<ObjectMetadata> ObjectDatabase::Put(const ObjectModel& model) {
  RECOG_RETURN_IF_ERROR(model.Validate());
  if (!(model.descriptor == index_->info().config.descriptor)) {
    return Status::InvalidArgument("object '" + model.metadata.name +
                                   "' has other descriptors than the vocabulary's");
  }
  if (model.num_features() == 0) {
    return Status::InvalidArgument("object '" + model.metadata.name + "' has no features");
  }
  std::lock_guard write_lock(write_mutex_);
  std::shared_ptr<const IndexedObject> old;
  {
    std::shared_lock lock(objects_mutex_);
    if (auto it = by_name_.find(model.metadata.name); it != by_name_.end()) {
      old = by_id_.at(it->second);
    }
  }
  ObjectModel header;
  header.metadata = model.metadata;
  if (old) header.metadata.version = std::max(model.metadata.version, old->metadata.version + 1);
  header.descriptor = model.descriptor;
  header.faces = model.faces;
  RECOG_ASSIGN_OR_RETURN(std::string header_bytes, EncodeObjectModel(header));

  BowVector bow;
  FeatureVector direct;
  RECOG_RETURN_IF_ERROR(index_->vocabulary().Transform(model.descriptors, &bow, &direct,
                                                       direct_levels_up(), BowNormalization::kL1));
  FeatureSet features;
  features.descriptors = model.descriptors;
  features.keypoints.resize(model.num_features());  // objects have no image position
  std::vector<cv::Point3f> points(model.num_features());
  for (size_t i = 0; i < points.size(); ++i) points[i] = model.points[model.point_of_feature[i]];
  EntryMetadata metadata;
  metadata.user_data = std::move(header_bytes);
  RECOG_ASSIGN_OR_RETURN(EntryId id, index_->AddConverted(bow, direct, features,
                                                          std::move(metadata), std::move(points)));
  RECOG_ASSIGN_OR_RETURN(EntryRecord record, index_->Get(id));
  RECOG_ASSIGN_OR_RETURN(std::shared_ptr<const IndexedObject> object, Load(record));
  {
    std::unique_lock lock(objects_mutex_);
    by_id_[id] = object;
    by_name_[object->metadata.name] = id;
    if (old) by_id_.erase(old->id);
  }
  if (old) RECOG_RETURN_IF_ERROR(index_->Remove(old->id));
  return object->metadata;
}

Status ObjectDatabase::Remove(const std::string& name) {
  std::lock_guard write_lock(write_mutex_);
  EntryId id = kInvalidEntryId;
  {
    std::shared_lock lock(objects_mutex_);
    auto it = by_name_.find(name);
    if (it == by_name_.end()) return Status::NotFound("no object named '" + name + "'");
    id = it->second;
  }
  RECOG_RETURN_IF_ERROR(index_->Remove(id));
  std::unique_lock lock(objects_mutex_);
  by_name_.erase(name);
  by_id_.erase(id);
  return Status::Ok();
}

std::vector<ObjectMetadata> ObjectDatabase::List() const {
  std::shared_lock lock(objects_mutex_);
  std::vector<ObjectMetadata> out;
  for (const auto& [name, id] : by_name_) out.push_back(by_id_.at(id)->metadata);
  return out;
}

StatusOr<ObjectModel> ObjectDatabase::Get(const std::string& name) const {
  std::shared_ptr<const IndexedObject> object;
  {
    std::shared_lock lock(objects_mutex_);
    auto it = by_name_.find(name);
    if (it == by_name_.end()) return Status::NotFound("no object named '" + name + "'");
    object = by_id_.at(it->second);
  }
  ObjectModel model;
  model.metadata = object->metadata;
  model.descriptor = index_->info().config.descriptor;
  model.faces = object->faces;
  model.descriptors = object->descriptors.clone();
  model.points = object->points;
  model.point_of_feature.resize(object->points.size());
  std::iota(model.point_of_feature.begin(), model.point_of_feature.end(), 0u);
  model.face_of_point = object->face_of_feature;
  return model;
}

std::shared_ptr<const IndexedObject> ObjectDatabase::Find(EntryId id) const {
  std::shared_lock lock(objects_mutex_);
  auto it = by_id_.find(id);
  return it == by_id_.end() ? nullptr : it->second;
}

}  // namespace recog
