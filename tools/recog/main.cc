// recog: command-line tool of the recognition service. See README.md, section "The recog tool".
#include <cstdio>
#include <string>

#include <CLI/CLI.hpp>

#include "tools/recog/commands.h"

int main(int argc, char** argv) {
  CLI::App app{"recog: place and object recognition with bags of binary words"};
  app.require_subcommand(1);
  app.failure_message([](const CLI::App* failed, const CLI::Error& e) {
    return "recog " + failed->get_name() + ": " + e.what() + " (see --help)\n";
  });
  int exit_code = 0;
  recog::cli::AddVocabCommands(app, &exit_code);
  recog::cli::AddBowCommand(app, &exit_code);
  recog::cli::AddDemoCommand(app, &exit_code);
  recog::cli::AddSeqgenCommand(app, &exit_code);
  recog::cli::AddEvalCommand(app, &exit_code);
  recog::cli::AddObjectCommands(app, &exit_code);
  recog::cli::AddModelExportCommand(app, &exit_code);
  recog::cli::AddStreamCommands(app, &exit_code);
  recog::cli::AddMapsCommands(app, &exit_code);
  recog::cli::AddModelsCommands(app, &exit_code);
  recog::cli::AddAdminCommands(app, &exit_code);
  recog::cli::AddLoadCommand(app, &exit_code);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  }
  return exit_code;
}
