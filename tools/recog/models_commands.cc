// recog models push | pull | list | delete | watch: the object model repository of recogd, over
// the C++ client library. Each takes the ServerFlags; a failed call prints one line
// "recog models <cmd>: CODE: message" and exits 1.
#include <condition_variable>
#include <cstdio>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <nlohmann/json.hpp>

#include "client/cpp/recognition_client.h"
#include "core/object/builder/model_builder.h"
#include "core/object/formats/model_file.h"
#include "tools/common/remote_support.h"
#include "tools/common/server_flags.h"
#include "tools/evaluation/object_evaluation.h"
#include "tools/recog/commands.h"

namespace recog::cli {
namespace {

using client::RecognitionClient;
using Json = nlohmann::ordered_json;

std::string TypeLabel(pb::ObjectType type) {
  return type == pb::OBJECT_TYPE_3D ? "3D" : EnumLabel(pb::ObjectType_Name(type), "OBJECT_TYPE_");
}

Json ModelJson(const pb::ModelInfo& model) {
  return {{"name", model.name()},
          {"version", model.version()},
          {"class", model.object_class()},
          {"type", TypeLabel(model.type())},
          {"dimensions", std::vector<double>(model.dimensions().begin(), model.dimensions().end())},
          {"units", model.units()},
          {"source", model.source()},
          {"tags", std::vector<std::string>(model.tags().begin(), model.tags().end())},
          {"sha256", model.sha256()},
          {"size_bytes", model.size_bytes()},
          {"created", UtcTime(model.created_unix_ms())},
          {"points", model.num_points()},
          {"descriptors", model.num_descriptors()}};
}

// "box v2: 3D, class 'box', 1234 points, 56789 bytes".
std::string ModelLine(const pb::ModelInfo& model) {
  return model.name() + " v" + std::to_string(model.version()) + ": " + TypeLabel(model.type()) +
         ", class '" + model.object_class() + "', " + std::to_string(model.num_points()) +
         " points, " + std::to_string(model.size_bytes()) + " bytes";
}

struct PushArgs {
  ServerFlags server;
  std::string path, name, vocabulary;
  std::vector<std::string> tags;
};

int RunModelsPush(const PushArgs& args, RecognitionClient& client) {
  const std::vector<ModelSource> sources = FindModelSources(args.path);
  if (sources.empty()) {
    return Fail("models push",
                Status::InvalidArgument("'" + args.path +
                                        "' holds no model file (.robj) nor RoboEarth folder"));
  }
  if (!args.name.empty() && sources.size() > 1) {
    return Fail("models push",
                Status::InvalidArgument("--name needs a single model; '" + args.path + "' holds " +
                                        std::to_string(sources.size())));
  }
  std::unique_ptr<ModelBuilder> builder;  // made for the first RoboEarth folder
  Json pushed = Json::array();
  for (const ModelSource& source : sources) {
    client::Result<pb::ModelInfo> info = grpc::Status(grpc::StatusCode::INTERNAL, "unset");
    if (source.roboearth) {
      if (builder == nullptr) {
        auto vocabulary = LoadObjectVocabulary(args.vocabulary);
        if (!vocabulary.ok()) return Fail("models push", vocabulary.status());
        builder = std::make_unique<ModelBuilder>(*vocabulary);
      }
      StatusOr<ObjectModel> model = builder->FromRoboEarth(source.path);
      if (!model.ok()) return Fail("models push", model.status());
      StatusOr<std::string> bytes = EncodeObjectModel(*model);
      if (!bytes.ok()) return Fail("models push", bytes.status());
      info = client.UploadModel(*bytes, args.name, args.tags);
    } else {
      info = client.UploadModelFile(source.path, args.name, args.tags);
    }
    if (!info.ok()) return Fail("models push", info.status());
    if (args.server.json) {
      pushed.push_back(ModelJson(*info));
    } else {
      std::printf("pushed %s (from %s)\n", ModelLine(*info).c_str(), source.path.c_str());
    }
  }
  if (args.server.json) std::printf("%s\n", pushed.dump(2).c_str());
  return 0;
}

struct PullArgs {
  ServerFlags server;
  std::string name, output;
  uint32_t version = 0;
};

int RunModelsPull(const PullArgs& args, RecognitionClient& client) {
  auto info = client.DownloadModel(args.name, args.version, args.output);
  if (!info.ok()) return Fail("models pull", info.status());
  if (args.server.json) {
    Json out = ModelJson(*info);
    out["file"] = args.output;
    std::printf("%s\n", out.dump(2).c_str());
  } else {
    std::printf("pulled %s -> %s\n", ModelLine(*info).c_str(), args.output.c_str());
  }
  return 0;
}

struct ListModelsArgs {
  ServerFlags server;
  client::ModelFilter filter;
};

int RunModelsList(const ListModelsArgs& args, RecognitionClient& client) {
  auto models = client.ListModels(args.filter);
  if (!models.ok()) return Fail("models list", models.status());
  if (args.server.json) {
    Json out = Json::array();
    for (const pb::ModelInfo& model : *models) out.push_back(ModelJson(model));
    std::printf("%s\n", out.dump(2).c_str());
    return 0;
  }
  std::printf("%-32s %7s %-16s %-7s %8s %10s  %s\n", "NAME", "VERSION", "CLASS", "TYPE", "POINTS",
              "BYTES", "TAGS");
  for (const pb::ModelInfo& model : *models) {
    std::string tags;
    for (const std::string& tag : model.tags()) tags += (tags.empty() ? "" : ",") + tag;
    std::printf("%-32s %7u %-16s %-7s %8u %10llu  %s\n", model.name().c_str(), model.version(),
                model.object_class().c_str(), TypeLabel(model.type()).c_str(), model.num_points(),
                (unsigned long long)model.size_bytes(), tags.c_str());
  }
  return 0;
}

struct WatchArgs {
  ServerFlags server;
  std::string prefix;
  size_t count = 0;
};

// Prints every change until --count changes were seen (0: until the stream ends or the process
// is interrupted).
int RunModelsWatch(const WatchArgs& args, RecognitionClient& client) {
  std::mutex mutex;
  std::condition_variable changed;
  size_t seen = 0;
  bool ended = false;
  const auto on_change = [&](const pb::WatchModelsResponse& event) {
    std::lock_guard lock(mutex);
    if (args.count > 0 && seen >= args.count) return;
    const std::string change = EnumLabel(pb::ModelChange_Name(event.change()), "MODEL_CHANGE_");
    if (args.server.json) {
      std::printf("%s\n", Json({{"change", change},
                                {"sequence", event.sequence()},
                                {"model", ModelJson(event.model())}})
                              .dump()
                              .c_str());
    } else {
      std::printf("%s %s\n", change.c_str(), ModelLine(event.model()).c_str());
    }
    std::fflush(stdout);
    ++seen;
    changed.notify_all();
  };
  std::unique_ptr<client::ModelWatch> watch = client.WatchModels(args.prefix, on_change);
  grpc::Status end;
  std::thread waiter([&] {
    end = watch->Wait();
    std::lock_guard lock(mutex);
    ended = true;
    changed.notify_all();
  });
  bool enough = false;
  {
    std::unique_lock lock(mutex);
    changed.wait(lock, [&] { return ended || (args.count > 0 && seen >= args.count); });
    enough = args.count > 0 && seen >= args.count;
  }
  if (enough) watch->Cancel();
  waiter.join();
  return enough ? 0 : Fail("models watch", end);
}

}  // namespace

void AddModelsCommands(CLI::App& app, int* exit_code) {
  CLI::App* models = app.add_subcommand("models", "Manage the object model repository of recogd");
  models->require_subcommand(1);
  auto push_args = std::make_shared<PushArgs>();
  CLI::App* push = models->add_subcommand(
      "push",
      "Upload models as new versions: a .robj file, a RoboEarth model folder (converted "
      "here), or a folder of those");
  push->add_option("path", push_args->path, "Model file, RoboEarth folder, or folder of them")
      ->required();
  push->add_option("--name", push_args->name,
                   "Name to store the model under (default: the name inside the model)");
  push->add_option("--tag", push_args->tags, "Label of the uploaded versions (repeatable)");
  push->add_option("--vocab", push_args->vocabulary,
                   "Vocabulary for RoboEarth folders (default: the bundled object one)");
  ConnectCommand(push, &push_args->server, exit_code, [push_args](RecognitionClient& client) {
    return RunModelsPush(*push_args, client);
  });

  auto pull_args = std::make_shared<PullArgs>();
  CLI::App* pull = models->add_subcommand("pull", "Download a version of a model (verified)");
  pull->add_option("name", pull_args->name, "Model name")->required();
  pull->add_option("--version", pull_args->version, "Version (0: the latest)")
      ->capture_default_str();
  pull->add_option("-o,--output", pull_args->output, "File to write")->required();
  ConnectCommand(pull, &pull_args->server, exit_code, [pull_args](RecognitionClient& client) {
    return RunModelsPull(*pull_args, client);
  });

  auto list_args = std::make_shared<ListModelsArgs>();
  CLI::App* list = models->add_subcommand("list", "List the latest version of every model");
  list->add_option("--prefix", list_args->filter.name_prefix, "Only names starting with this");
  list->add_option("--class", list_args->filter.object_class, "Only this object class");
  list->add_option("--tag", list_args->filter.tag, "Only models with this tag");
  ConnectCommand(list, &list_args->server, exit_code, [list_args](RecognitionClient& client) {
    return RunModelsList(*list_args, client);
  });

  struct NamedArgs {
    ServerFlags server;
    std::string name;
  };
  auto delete_model_args = std::make_shared<NamedArgs>();
  CLI::App* delete_model = models->add_subcommand("delete", "Delete every version of a model");
  delete_model->add_option("name", delete_model_args->name, "Model name")->required();
  ConnectCommand(
      delete_model, &delete_model_args->server, exit_code,
      [delete_model_args](RecognitionClient& client) {
        auto versions = client.DeleteModel(delete_model_args->name);
        if (!versions.ok()) return Fail("models delete", versions.status());
        if (delete_model_args->server.json) {
          std::printf("%s\n",
                      Json({{"name", delete_model_args->name}, {"versions_deleted", *versions}})
                          .dump(2)
                          .c_str());
        } else {
          std::printf("deleted model %s (%u version%s)\n", delete_model_args->name.c_str(),
                      *versions, *versions == 1 ? "" : "s");
        }
        return 0;
      });

  auto watch_args = std::make_shared<WatchArgs>();
  CLI::App* watch = models->add_subcommand(
      "watch", "Print every upload and deletion from now on (JSON: one object per line)");
  watch->add_option("--prefix", watch_args->prefix, "Only models whose names start with this");
  watch->add_option("--count", watch_args->count, "Stop after this many changes (0: never)")
      ->capture_default_str();
  ConnectCommand(watch, &watch_args->server, exit_code, [watch_args](RecognitionClient& client) {
    return RunModelsWatch(*watch_args, client);
  });
}

}  // namespace recog::cli
