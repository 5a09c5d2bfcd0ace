// ObjectDatabase: the shared repository of object models that recognition queries (thesis
// §5.4.3, Figure 5.9).
//
// It is one map of the place database machinery (index/database.h) whose entries are objects
// instead of frames: each model's bag of words (tf-idf over all its descriptors, L1-normalised,
// scored by BC matching) goes into the inverted index, and its direct index holds, for every
// descriptor, the nearest vocabulary node at level 1 of the trees (thesis §5.4.4.3). The entry's
// features are the model's descriptors with their 3D points; the metadata and faces travel in the
// entry's user data as a header-only model file (model_file.h). Whatever the store persists
// (memory or RocksDB) survives a restart: Open() reloads every object.
//
// Recognition needs the descriptors, points and direct index of the best candidate at once, so
// every object is also kept decoded in memory (about 80 bytes a descriptor: its descriptor twice,
// once in the model's order and once node by node for the direct index) and handed out as an
// immutable shared snapshot: replacing or removing a model never disturbs a recognition that is
// using the old one.
//
// Names are unique. Put() adds a model, or replaces the one of the same name (the new one is
// indexed before the old one is removed, so the object never disappears; its version becomes the
// old version + 1). Thread safety: every method may be called from any thread; writers are
// serialised.
#pragma once

#include <map>
#include <memory>
#include <mutex>
#include <shared_mutex>
#include <string>
#include <vector>

#include "core/common/status.h"
#include "core/index/database.h"
#include "core/object/model/object_model.h"

namespace recog {

// What recognition uses of one object.
struct IndexedObject {
  EntryId id = kInvalidEntryId;
  ObjectMetadata metadata;
  std::vector<PlanarFace> faces;
  cv::Mat descriptors;                      // one row per feature
  std::vector<cv::Point3f> points;          // 3D point of each feature (object frame)
  std::vector<uint32_t> face_of_feature;    // planar objects: the face of each feature
  FeatureVector direct;                     // level-1 node -> features
  cv::Mat direct_descriptors;               // the descriptors node by node, in direct's order
  std::vector<cv::Point3f> outline_points;  // a few hundred model points for the outline
};

class ObjectDatabase {
 public:
  static constexpr char kDefaultMapName[] = "objects";

  // Opens map `map_name` of `store`, creating it for `vocabulary` when absent, and loads every
  // object. FAILED_PRECONDITION when the map was made with another vocabulary.
  static StatusOr<std::unique_ptr<ObjectDatabase>> Open(
      IndexStore* store, std::shared_ptr<const Vocabulary> vocabulary,
      const std::string& map_name = kDefaultMapName);

  // Adds or replaces a model; returns its stored metadata (with the version it got).
  // INVALID_ARGUMENT for an invalid model or one with other descriptors than the vocabulary's.
  StatusOr<ObjectMetadata> Put(const ObjectModel& model);
  // NOT_FOUND when there is no such object.
  Status Remove(const std::string& name);
  // Every object's metadata, by name.
  std::vector<ObjectMetadata> List() const;
  // The stored model (points, descriptors, faces, metadata; training views are not stored).
  StatusOr<ObjectModel> Get(const std::string& name) const;

  // Snapshot of an indexed object by entry id (null when absent).
  std::shared_ptr<const IndexedObject> Find(EntryId id) const;
  const Database& index() const { return *index_; }
  const Vocabulary& vocabulary() const { return index_->vocabulary(); }
  // The direct-index level as `levels_up` for Vocabulary::Transform (depth - 1: level 1).
  int direct_levels_up() const;
  size_t size() const;

 private:
  explicit ObjectDatabase(std::unique_ptr<Database> index);
  // Decodes an entry into an IndexedObject.
  StatusOr<std::shared_ptr<const IndexedObject>> Load(EntryRecord& record) const;

  std::unique_ptr<Database> index_;
  std::mutex write_mutex_;
  mutable std::shared_mutex objects_mutex_;  // guards the two maps
  std::map<EntryId, std::shared_ptr<const IndexedObject>> by_id_;
  std::map<std::string, EntryId> by_name_;
};

}  // namespace recog
