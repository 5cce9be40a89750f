#include <fogbeam/physics/photometry_io.hpp>

#include <cerrno>
#include <cstring>
#include <fstream>
#include <sstream>

namespace fogbeam {

Result<std::string> readTextFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return Error{path + ": cannot open (" + std::strerror(errno) + ")"};
  std::ostringstream ss;
  ss << in.rdbuf();
  if (in.bad()) return Error{path + ": read error"};
  return ss.str();
}

}  // namespace fogbeam
