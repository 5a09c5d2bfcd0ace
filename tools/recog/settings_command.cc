// recog settings [--markdown]: the loop detector's settings table (core/place/detector_settings.h)
// as a reader sees it: the presets and what each is for, then every setting with its value in
// each preset, its range, whether a map keeps it, and its doc. --markdown prints the table of
// docs/places.md, which tools/recog/settings_docs_test.sh compares with this output.
#include <cstdio>
#include <memory>
#include <string>

#include "core/place/detector_settings.h"
#include "tools/recog/commands.h"

namespace recog::cli {

void AddSettingsCommand(CLI::App& app, int* exit_code) {
  auto markdown = std::make_shared<bool>(false);
  CLI::App* settings = app.add_subcommand(
      "settings", "List the loop detector's settings: each preset's values, the ranges and docs");
  settings->add_flag("--markdown", *markdown, "Print markdown tables (docs/places.md's)");
  settings->callback([markdown, exit_code] {
    const std::string table = DetectorSettingsTable(*markdown ? SettingsTableFormat::kMarkdown
                                                              : SettingsTableFormat::kText);
    std::fputs(table.c_str(), stdout);
    *exit_code = 0;
  });
}

}  // namespace recog::cli
