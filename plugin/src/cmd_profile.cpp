#include "commands.hpp"
namespace fogbeam::cli {
void addProfileCommand(CLI::App& app, int& exitCode) {
  auto* sub = app.add_subcommand("profile", "Describe a lamp intensity file and chart it as PNG");
  sub->callback([&exitCode] { exitCode = 2; });
}
}  // namespace fogbeam::cli
