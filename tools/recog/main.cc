// recog: command-line tool of the recognition service. See docs/cli.md.
//
// Exit status: 0 on success (and for --help, --version), 1 when a subcommand fails (bad input
// files, a failed call to recogd: one line "recog <cmd>: <reason>"), 2 when the command line is
// wrong (unknown subcommand or flag, a missing required option, a bad value: CLI11's message).

#include <CLI/CLI.hpp>

#include "recog_build_info.h"
#include "tools/recog/commands.h"

namespace {

constexpr int kUsageError = 2;

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"recog: place and object recognition with bags of binary words"};
  app.require_subcommand(1);
  app.failure_message([](const CLI::App* failed, const CLI::Error& e) {
    return "recog " + failed->get_name() + ": " + e.what() + " (see --help)\n";
  });
  app.set_version_flag("--version", recog::build_info::VersionLine("recog"));
  int exit_code = 0;
  // Every subcommand is registered here, in the order --help lists them (commands.h); `eval` is
  // only a group, whose subcommands each have a file.
  recog::cli::AddVocabCommands(app, &exit_code);
  recog::cli::AddBowCommand(app, &exit_code);
  recog::cli::AddDemoCommand(app, &exit_code);
  recog::cli::AddSeqgenCommand(app, &exit_code);
  CLI::App* eval = app.add_subcommand("eval", "Evaluate recognition against ground truth");
  eval->require_subcommand(1);
  recog::cli::AddEvalPlaceCommand(*eval, &exit_code);
  recog::cli::AddEvalObjectsCommand(*eval, &exit_code);
  recog::cli::AddEvalSequenceCommand(*eval, &exit_code);
  recog::cli::AddSettingsCommand(app, &exit_code);
  recog::cli::AddModelCommands(app, &exit_code);
  recog::cli::AddRecognizeCommand(app, &exit_code);
  recog::cli::AddStreamCommands(app, &exit_code);
  recog::cli::AddQueryCommands(app, &exit_code);
  recog::cli::AddMapsCommands(app, &exit_code);
  recog::cli::AddModelsCommands(app, &exit_code);
  recog::cli::AddAdminCommands(app, &exit_code);
  recog::cli::AddLoadCommand(app, &exit_code);
  recog::cli::AddBagCommands(app, &exit_code);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    // --help and --version are ParseErrors with exit code 0 (CLI11 prints them); every other one is
    // a usage error, whatever CLI11's own code for it (105-114).
    const int code = app.exit(e);
    return code == 0 ? 0 : kUsageError;
  }
  return exit_code;
}
