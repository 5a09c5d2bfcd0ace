#include "tools/recog/model_database.h"

#include "core/object/builder/model_builder.h"
#include "core/object/formats/model_file.h"
#include "tools/evaluation/object_evaluation.h"

namespace recog::cli {

StatusOr<std::shared_ptr<ObjectDatabase>> LoadModelDatabase(const std::vector<std::string>& paths,
                                                            const std::string& vocabulary_path,
                                                            MemoryIndexStore* store) {
  RECOG_ASSIGN_OR_RETURN(std::shared_ptr<const Vocabulary> vocabulary,
                         LoadObjectVocabulary(vocabulary_path));
  RECOG_ASSIGN_OR_RETURN(std::unique_ptr<ObjectDatabase> database,
                         ObjectDatabase::Open(store, vocabulary));
  ModelBuildOptions build;
  build.keep_images = false;
  ModelBuilder builder(vocabulary, build);
  for (const std::string& path : paths) {
    for (const ModelSource& source : FindModelSources(path)) {
      StatusOr<ObjectModel> model =
          source.roboearth ? builder.FromRoboEarth(source.path) : LoadObjectModel(source.path);
      RECOG_RETURN_IF_ERROR(model.status());
      RECOG_RETURN_IF_ERROR(database->Put(*model).status());
    }
  }
  if (database->size() == 0) return Status::InvalidArgument("--models named no object model");
  return std::shared_ptr<ObjectDatabase>(std::move(database));
}

}  // namespace recog::cli
