// fogbeam_lampgen — writes the shipped lamp files (config/lamps/*.ies) from the parametric
// models in lamp_models.hpp, or checks that the shipped files still match them.
//
//   fogbeam_lampgen --out-dir config/lamps     regenerate the files
//   fogbeam_lampgen --check config/lamps       exit 1 naming the first file that differs
#include <fogbeam/physics/ies_writer.hpp>
#include <fogbeam/util/files.hpp>

#include "lamp_models.hpp"


#include <CLI/CLI.hpp>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

namespace {

// 1-based line of the first differing character, for the drift message.
std::size_t firstDifferingLine(const std::string& a, const std::string& b) {
  std::size_t line = 1;
  for (std::size_t i = 0; i < a.size() && i < b.size(); ++i) {
    if (a[i] != b[i]) return line;
    if (a[i] == '\n') ++line;
  }
  return line;
}

int writeAll(const std::string& dir) {
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) {
    std::fprintf(stderr, "fogbeam_lampgen: cannot create %s (%s)\n", dir.c_str(), ec.message().c_str());
    return 1;
  }
  for (const auto& lamp : fogbeam::lamps::shippedLamps()) {
    const std::string path = (std::filesystem::path(dir) / lamp.file_name).string();
    const std::string text = fogbeam::writeIes(lamp.profile);
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out.write(text.data(), static_cast<std::streamsize>(text.size()));
    out.close();
    if (!out) {
      std::fprintf(stderr, "fogbeam_lampgen: cannot write %s\n", path.c_str());
      return 1;
    }
    std::printf("wrote %s (%zu bytes, %zu x %zu angles)\n", path.c_str(), text.size(),
                lamp.profile.horizontal.size(), lamp.profile.vertical.size());
  }
  return 0;
}

int checkAll(const std::string& dir) {
  int status = 0;
  for (const auto& lamp : fogbeam::lamps::shippedLamps()) {
    const std::string path = (std::filesystem::path(dir) / lamp.file_name).string();
    const std::string expected = fogbeam::writeIes(lamp.profile);
    const auto actual = fogbeam::readTextFile(path);
    if (!actual) {
      std::fprintf(stderr, "fogbeam_lampgen: %s\n", actual.error().message.c_str());
      status = 1;
    } else if (*actual != expected) {
      std::fprintf(stderr,
                   "fogbeam_lampgen: %s differs from the generator output (first difference on line %zu); "
                   "regenerate with: fogbeam_lampgen --out-dir %s\n",
                   path.c_str(), firstDifferingLine(*actual, expected), dir.c_str());
      status = 1;
    }
  }
  if (status == 0) std::printf("all lamp files in %s match the generator\n", dir.c_str());
  return status;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "fogbeam_lampgen: writes the shipped lamp files (low_beam.ies, high_beam.ies, front_fog.ies, "
      "tail_lamp.ies; IES LM-63-2002, type B, absolute candela) from the parametric models in "
      "plugin/cli/lamp_models.hpp, or checks shipped files against them."};
  std::string outDir;
  std::string checkDir;
  auto* outOpt = app.add_option("--out-dir", outDir, "Directory to write the four .ies files into (created if missing)");
  auto* checkOpt = app.add_option("--check", checkDir,
                                  "Directory whose .ies files must equal the generator output byte for byte; "
                                  "exit status 1 names the first file that differs");
  outOpt->excludes(checkOpt);
  app.require_option(1);
  CLI11_PARSE(app, argc, argv);
  return outDir.empty() ? checkAll(checkDir) : writeAll(outDir);
}
