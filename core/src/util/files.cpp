// fogbeam — whole text files and the paths configuration files name (files.hpp).
#include <fogbeam/util/files.hpp>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <system_error>

namespace fogbeam {

namespace fs = std::filesystem;

Result<std::string> readTextFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return Error{path + ": cannot open (" + std::strerror(errno) + ")"};
  std::ostringstream ss;
  ss << in.rdbuf();
  if (in.bad()) return Error{path + ": read error"};
  return ss.str();
}

std::string resolvePath(const std::string& baseDir, const std::string& relative) {
  const fs::path p(relative);
  if (p.is_absolute() || baseDir.empty()) return p.lexically_normal().string();
  return (fs::path(baseDir) / p).lexically_normal().string();
}

std::string checkFile(const std::string& path) {
  std::error_code ec;
  const fs::file_status st = fs::status(path, ec);
  // A relative path (a file named relative to a configuration given by a relative path) is
  // named as the directory it was looked for in makes it: "nope.ies" alone does not say where.
  std::string shown = path;
  if (const fs::path p(path); p.is_relative()) {
    std::error_code aec;
    const fs::path abs = fs::absolute(p, aec);
    if (!aec) shown = abs.lexically_normal().string();
  }
  if (ec || !fs::exists(st)) return "file not found: " + shown;
  if (!fs::is_regular_file(st)) return "not a regular file: " + shown;
  return {};
}

}  // namespace fogbeam
