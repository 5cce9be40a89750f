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
  if (ec || !fs::exists(st)) return "file not found: " + path;
  if (!fs::is_regular_file(st)) return "not a regular file: " + path;
  return {};
}

}  // namespace fogbeam
