// Registration of the recog subcommands. Each Add*Command attaches a subcommand (with its options
// and --help) to the app; when the subcommand runs it stores its exit status in *exit_code:
// 0 on success, 1 on bad input or failure (after printing one line "recog <cmd>: <reason>"). The
// command line itself (unknown flags, missing or bad values) is refused by CLI11: exit status 2.
#pragma once

#include <CLI/CLI.hpp>

namespace recog::cli {

void AddVocabCommands(CLI::App& app, int* exit_code);
void AddBowCommand(CLI::App& app, int* exit_code);
void AddDemoCommand(CLI::App& app, int* exit_code);
void AddSeqgenCommand(CLI::App& app, int* exit_code);
void AddEvalCommand(CLI::App& app, int* exit_code);
void AddObjectCommands(CLI::App& app, int* exit_code);  // model build|info, recognize
// model export; call after AddObjectCommands, which adds "model".
void AddModelExportCommand(CLI::App& app, int* exit_code);
void AddEvalObjectsCommand(CLI::App& eval, int* exit_code);
// The subcommands that use recogd (remote_support.h, server_flags.h).
void AddStreamCommands(CLI::App& app, int* exit_code);  // stream, query
void AddMapsCommands(CLI::App& app, int* exit_code);    // maps list|create|delete|stats
void AddModelsCommands(CLI::App& app, int* exit_code);  // models push|pull|list|delete|watch
void AddAdminCommands(CLI::App& app, int* exit_code);   // admin health|checkpoint|restore
void AddLoadCommand(CLI::App& app, int* exit_code);     // load (load_generator.h)

}  // namespace recog::cli
