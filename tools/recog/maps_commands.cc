// recog maps list | create NAME [settings] | delete NAME | stats NAME |
// remove-frame NAME (--frame ID | --client-frame-id ID): the place maps of recogd,
// over the C++ client library. Each takes the ServerFlags; a failed call prints one line
// "recog maps <cmd>: CODE: message" and exits 1.
#include <algorithm>
#include <cctype>
#include <cstdio>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "client/cpp/recognition_client.h"
#include "core/place/detector_settings.h"
#include "tools/common/remote_support.h"
#include "tools/common/server_flags.h"
#include "tools/recog/commands.h"
#include "wire/map_settings_text.h"

namespace recog::cli {
namespace {

using client::RecognitionClient;
using Json = nlohmann::ordered_json;

// Prints an object's fields one per line ("key  value"), nested objects flattened.
void PrintFields(const Json& fields) {
  for (const auto& [key, value] : fields.items()) {
    if (value.is_object()) {
      PrintFields(value);
    } else {
      std::printf("%-20s %s\n", key.c_str(),
                  value.is_string() ? value.get<std::string>().c_str() : value.dump().c_str());
    }
  }
}

// A map's detector settings (the settings table's names and kinds), then its group and thumbnails.
// INTERNAL when the table names a setting MapSettings lacks (a bug).
StatusOr<Json> SettingsJson(const pb::MapSettings& settings) {
  std::vector<std::pair<std::string, std::string>> values;
  const std::string unknown = MapSettingsAsText(settings, MapDetectorSettingNames(), &values);
  if (!unknown.empty()) return Status::Internal("MapSettings and the settings table: " + unknown);
  Json out = Json::object();
  for (const auto& [name, text] : values) {
    const SettingKind kind = FindDetectorSetting(name)->kind;
    if (kind == SettingKind::kNumber) {
      out[name] = std::stod(text);
    } else if (kind == SettingKind::kCount) {
      out[name] = std::stoull(text);
    } else {
      out[name] = text;
    }
  }
  out["group"] = settings.group();
  out["keep_thumbnails"] = settings.keep_thumbnails();
  return out;
}

StatusOr<Json> MapJson(const pb::MapInfo& map) {
  RECOG_ASSIGN_OR_RETURN(Json settings, SettingsJson(map.settings()));
  return Json{{"name", map.name()},
              {"id", map.id()},
              {"frames", map.frames()},
              {"next_frame_id", map.next_frame_id()},
              {"created", UtcTime(map.created_unix_ms())},
              {"vocabulary_checksum", map.vocabulary_checksum()},
              {"settings", std::move(settings)}};
}

// One flag per setting a map keeps (the settings table: --name-with-dashes, its doc, its choices
// and the default preset's value), setting the field of the same name in *settings.
void AddMapSettingFlags(CLI::App* create, pb::MapSettings* settings) {
  const LoopDetectorParams defaults;
  for (const std::string_view name : MapDetectorSettingNames()) {
    const DetectorSetting& setting = *FindDetectorSetting(name);
    std::string flag = "--" + std::string(name);
    std::replace(flag.begin(), flag.end(), '_', '-');
    std::string doc = std::string(setting.doc);
    doc[0] = char(std::toupper(static_cast<unsigned char>(doc[0])));
    doc += "; default preset: " + DisplayDetectorSetting(setting, defaults);
    if (setting.kind == SettingKind::kPreset) doc += ":\n" + PresetHelp();
    CLI::Option* option = create->add_option_function<std::string>(
        flag,
        [settings, name, flag](const std::string& text) {
          const std::string error = SetMapSettingFromText(settings, name, text);
          if (!error.empty()) throw CLI::ValidationError(flag, error);
        },
        doc);
    if (!setting.choices.empty()) {
      std::vector<std::string> choices;
      std::string_view rest = setting.choices;
      while (!rest.empty()) {
        const size_t comma = rest.find(", ");
        choices.emplace_back(rest.substr(0, comma));
        rest = comma == std::string_view::npos ? std::string_view() : rest.substr(comma + 2);
      }
      option->check(CLI::IsMember(choices));
    }
  }
}

int RunMapsList(const ServerFlags& flags, RecognitionClient& client) {
  auto maps = client.ListMaps();
  if (!maps.ok()) return Fail("maps list", maps.status());
  if (flags.json) {
    Json out = Json::array();
    for (const pb::MapInfo& map : *maps) {
      StatusOr<Json> json = MapJson(map);
      if (!json.ok()) return Fail("maps list", json.status());
      out.push_back(*std::move(json));
    }
    std::printf("%s\n", out.dump(2).c_str());
    return 0;
  }
  std::printf("%-32s %10s  %s\n", "NAME", "FRAMES", "CREATED");
  for (const pb::MapInfo& map : *maps) {
    std::printf("%-32s %10llu  %s\n", map.name().c_str(), (unsigned long long)map.frames(),
                UtcTime(map.created_unix_ms()).c_str());
  }
  return 0;
}

// Prints a map's description (maps create, maps stats, named `command` in a failure): the exit
// status.
int PrintMap(const ServerFlags& flags, const pb::MapInfo& map, const char* command) {
  StatusOr<Json> json = MapJson(map);
  if (!json.ok()) return Fail(command, json.status());
  if (flags.json) {
    std::printf("%s\n", json->dump(2).c_str());
  } else {
    PrintFields(*json);
  }
  return 0;
}

}  // namespace

void AddMapsCommands(CLI::App& app, int* exit_code) {
  CLI::App* maps = app.add_subcommand("maps", "Manage the place maps of recogd");
  maps->require_subcommand(1);
  auto list_flags = std::make_shared<ServerFlags>();
  ConnectCommand(
      maps->add_subcommand("list", "List the maps"), list_flags.get(), exit_code,
      [list_flags](RecognitionClient& client) { return RunMapsList(*list_flags, client); });

  struct CreateMapArgs {
    ServerFlags server;
    std::string name;
    pb::MapSettings settings;  // only the options given are set
  };
  auto create_args = std::make_shared<CreateMapArgs>();
  CLI::App* create =
      maps->add_subcommand("create", "Create an empty map; unset settings take the server's");
  create->add_option("name", create_args->name, "Map name (1-128 of A-Z a-z 0-9 . _ -)")
      ->required();
  pb::MapSettings* settings = &create_args->settings;
  AddMapSettingFlags(create, settings);
  create->add_option_function<std::string>(
      "--group", [settings](const std::string& v) { settings->set_group(v); },
      "Map group (a fleet's maps, a robot's sessions) that queries search together "
      "(recog stream --search-group)");
  create->add_flag_callback(
      "--keep-thumbnails", [settings] { settings->set_keep_thumbnails(true); },
      "Keep a small JPEG of each frame for the web console (6-11 KB a frame)");
  ConnectCommand(create, &create_args->server, exit_code, [create_args](RecognitionClient& client) {
    auto map = client.CreateMap(create_args->name, create_args->settings);
    if (!map.ok()) return Fail("maps create", map.status());
    return PrintMap(create_args->server, *map, "maps create");
  });

  struct NamedArgs {
    ServerFlags server;
    std::string name;
  };
  auto delete_args = std::make_shared<NamedArgs>();
  CLI::App* delete_map = maps->add_subcommand("delete", "Delete a map and its frames");
  delete_map->add_option("name", delete_args->name, "Map name")->required();
  ConnectCommand(
      delete_map, &delete_args->server, exit_code, [delete_args](RecognitionClient& client) {
        auto frames = client.DeleteMap(delete_args->name);
        if (!frames.ok()) return Fail("maps delete", frames.status());
        if (delete_args->server.json) {
          std::printf(
              "%s\n",
              Json({{"name", delete_args->name}, {"frames_deleted", *frames}}).dump(2).c_str());
        } else {
          std::printf("deleted map %s (%llu frame%s)\n", delete_args->name.c_str(),
                      (unsigned long long)*frames, *frames == 1 ? "" : "s");
        }
        return 0;
      });

  struct RemoveFrameArgs {
    ServerFlags server;
    std::string name, client_frame_id;
    std::optional<uint64_t> frame_id;
  };
  auto remove_args = std::make_shared<RemoveFrameArgs>();
  CLI::App* remove_frame = maps->add_subcommand(
      "remove-frame", "Remove frames from a map (keyframe culling): never a candidate again");
  remove_frame->add_option("name", remove_args->name, "Map name")->required();
  CLI::Option* by_id =
      remove_frame->add_option("--frame", remove_args->frame_id, "The frame's id in the map");
  CLI::Option* by_client =
      remove_frame->add_option("--client-frame-id", remove_args->client_frame_id,
                               "Every frame added with this client frame id");
  by_id->excludes(by_client);
  ConnectCommand(
      remove_frame, &remove_args->server, exit_code, [remove_args](RecognitionClient& client) {
        if (!remove_args->frame_id.has_value() && remove_args->client_frame_id.empty()) {
          return Fail("maps remove-frame",
                      Status::InvalidArgument("give --frame or --client-frame-id"));
        }
        auto removed =
            remove_args->frame_id.has_value()
                ? client.RemoveFrame(remove_args->name, *remove_args->frame_id)
                : client.RemoveFramesByClientId(remove_args->name, remove_args->client_frame_id);
        if (!removed.ok()) return Fail("maps remove-frame", removed.status());
        if (remove_args->server.json) {
          std::printf(
              "%s\n",
              Json({{"name", remove_args->name}, {"removed_frames", *removed}}).dump(2).c_str());
        } else {
          std::printf("removed from map %s:", remove_args->name.c_str());
          for (uint64_t id : *removed) std::printf(" frame %llu", (unsigned long long)id);
          std::printf("\n");
        }
        return 0;
      });

  auto stats_args = std::make_shared<NamedArgs>();
  CLI::App* stats = maps->add_subcommand("stats", "Describe a map: frames, settings, vocabulary");
  stats->add_option("name", stats_args->name, "Map name")->required();
  ConnectCommand(stats, &stats_args->server, exit_code, [stats_args](RecognitionClient& client) {
    auto map = client.GetMap(stats_args->name);
    if (!map.ok()) return Fail("maps stats", map.status());
    return PrintMap(stats_args->server, *map, "maps stats");
  });
}

}  // namespace recog::cli
