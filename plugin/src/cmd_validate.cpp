#include "commands.hpp"
namespace fogbeam::cli {
void addValidateCommand(CLI::App& app, int& exitCode) {
  auto* sub = app.add_subcommand("validate", "Compare the airlight methods against the reference");
  sub->callback([&exitCode] { exitCode = 2; });
}
}  // namespace fogbeam::cli
