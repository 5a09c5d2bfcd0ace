// recog model export: writes an object model file back out as a RoboEarth folder, e.g. to inspect
// it with RoboEarth tools or to rebuild it with other options.
#include <cstdio>
#include <memory>
#include <string>

#include "core/object/formats/model_file.h"
#include "core/object/formats/roboearth.h"
#include "tools/recog/commands.h"

namespace recog::cli {
namespace {

int Fail(const Status& status) {
  std::fprintf(stderr, "recog model export: %s\n", status.ToString().c_str());
  return 1;
}

int RunModelExport(const std::string& path, const std::string& dir) {
  auto model = LoadObjectModel(path);
  if (!model.ok()) return Fail(model.status());
  if (Status s = ExportRoboEarthFolder(*model, dir); !s.ok()) return Fail(s);
  std::printf("%s: %zu views, %zu points -> %s\n", model->metadata.name.c_str(),
              model->views.size(), model->points.size(), dir.c_str());
  return 0;
}

}  // namespace

void AddModelExportCommand(CLI::App& app, int* exit_code) {
  // "model" is registered by AddObjectCommands; export joins its build and info.
  CLI::App* model = app.get_subcommand("model");
  auto path = std::make_shared<std::string>();
  auto dir = std::make_shared<std::string>();
  CLI::App* export_command =
      model->add_subcommand("export", "Write an object model file as a RoboEarth folder");
  export_command->add_option("file", *path, "Model file (.robj)")->required();
  export_command
      ->add_option("--roboearth", *dir, "Folder to create (missing or empty) for the model")
      ->required();
  export_command->callback([path, dir, exit_code] { *exit_code = RunModelExport(*path, *dir); });
}

}  // namespace recog::cli
