// Registration of the recog subcommands. Each Add*Command attaches a subcommand (with its options
// and --help) to the app, or to its parent command (`eval`, created by main.cc); when the
// subcommand runs it stores its exit status in *exit_code: 0 on success, 1 on bad input or failure
// (after printing one line "recog <cmd>: <reason>"). The command line itself (unknown flags,
// missing or bad values) is refused by CLI11: exit status 2. main.cc calls every one of them, in
// the order --help lists them; none depends on another having run.
#pragma once

#include <CLI/CLI.hpp>

namespace recog::cli {

void AddVocabCommands(CLI::App& app, int* exit_code);  // vocab train|info|convert
void AddBowCommand(CLI::App& app, int* exit_code);
void AddDemoCommand(CLI::App& app, int* exit_code);
void AddSeqgenCommand(CLI::App& app, int* exit_code);  // seqgen, seqgen objects|rig
// The subcommands of `recog eval`.
void AddEvalPlaceCommand(CLI::App& eval, int* exit_code);
void AddEvalObjectsCommand(CLI::App& eval, int* exit_code);
void AddEvalSequenceCommand(CLI::App& eval, int* exit_code);
// settings: the loop detector's settings table (detector_settings.h)
void AddSettingsCommand(CLI::App& app, int* exit_code);
void AddModelCommands(CLI::App& app, int* exit_code);  // model build|info|export
void AddRecognizeCommand(CLI::App& app, int* exit_code);
// The subcommands that use recogd (remote_support.h, server_flags.h); recognize too, with --server.
void AddStreamCommands(CLI::App& app, int* exit_code);  // stream
void AddQueryCommands(CLI::App& app, int* exit_code);   // query, relocalize
// maps list|create|delete|remove-frame|stats
void AddMapsCommands(CLI::App& app, int* exit_code);
void AddModelsCommands(CLI::App& app, int* exit_code);  // models push|pull|list|delete|watch
// admin health|checkpoint|verify|status|restore
void AddAdminCommands(CLI::App& app, int* exit_code);
void AddLoadCommand(CLI::App& app, int* exit_code);  // load (load_generator.h)
void AddBagCommands(CLI::App& app, int* exit_code);  // bag info|extract

}  // namespace recog::cli
