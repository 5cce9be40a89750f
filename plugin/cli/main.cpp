// fogbeam — the single executable. Subcommands: validate, profile (issue 2), render, bench
// (issue 3), serve, replay, view, send (issue 5).
#include "commands.hpp"

#include <CLI/CLI.hpp>

int main(int argc, char** argv) {
  CLI::App app{"fogbeam: real-time headlight beams in fog for driving simulators"};
  app.require_subcommand(1);
  app.set_version_flag("--version", std::string("fogbeam 0.1.0"));
  int exitCode = 0;
  fogbeam::cli::addValidateCommand(app, exitCode);
  fogbeam::cli::addProfileCommand(app, exitCode);
  fogbeam::cli::addRenderCommand(app, exitCode);
  fogbeam::cli::addBenchCommand(app, exitCode);
  fogbeam::cli::addServeCommand(app, exitCode);
  fogbeam::cli::addReplayCommand(app, exitCode);
  fogbeam::cli::addSendCommand(app, exitCode);
  fogbeam::cli::addViewCommand(app, exitCode);
  CLI11_PARSE(app, argc, argv);
  return exitCode;
}
