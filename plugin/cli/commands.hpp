// fogbeam — subcommand registration. Each add*Command() adds one subcommand to the app and
// arranges for it to run when chosen; the command sets `exitCode` to its exit status.
#pragma once

#include <CLI/CLI.hpp>

namespace fogbeam::cli {

void addValidateCommand(CLI::App& app, int& exitCode);
void addProfileCommand(CLI::App& app, int& exitCode);
void addRenderCommand(CLI::App& app, int& exitCode);
void addBenchCommand(CLI::App& app, int& exitCode);
void addServeCommand(CLI::App& app, int& exitCode);
void addReplayCommand(CLI::App& app, int& exitCode);
void addSendCommand(CLI::App& app, int& exitCode);
void addViewCommand(CLI::App& app, int& exitCode);

}  // namespace fogbeam::cli
