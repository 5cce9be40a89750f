#include "shader_library.hpp"

#include <algorithm>

#include <cstdlib>
#include <fstream>
#include <set>
#include <sstream>

namespace fogbeam::gl {

namespace {

Result<std::string> rawSource(const std::string& name) {
  if (const char* dir = std::getenv("FOGBEAM_SHADER_DIR"); dir != nullptr && *dir != '\0') {
    const std::string path = std::string(dir) + "/" + name;
    std::ifstream in(path, std::ios::binary);
    if (!in) return Error{path + ": cannot open shader (FOGBEAM_SHADER_DIR is set)"};
    std::ostringstream ss;
    ss << in.rdbuf();
    return ss.str();
  }
  for (std::size_t i = 0; i < kEmbeddedShaderCount; ++i)
    if (name == kEmbeddedShaders[i].name) return std::string(kEmbeddedShaders[i].text);
  return Error{name + ": no such embedded shader (shaders/ at build time)"};
}

Status expand(const std::string& name, std::set<std::string>& seen, std::string& out) {
  auto text = rawSource(name);
  if (!text) return text.error();
  std::istringstream lines(*text);
  std::string line;
  int lineNo = 0;
  while (std::getline(lines, line)) {
    ++lineNo;
    const auto first = line.find_first_not_of(" \t");
    if (first != std::string::npos && line.compare(first, 8, "#include") == 0) {
      const auto q0 = line.find('"', first), q1 = q0 == std::string::npos ? q0 : line.find('"', q0 + 1);
      if (q1 == std::string::npos) return fileError(name, static_cast<std::size_t>(lineNo), "expected #include \"file\"");
      const std::string inc = line.substr(q0 + 1, q1 - q0 - 1);
      if (seen.insert(inc).second) {
        if (Status s = expand(inc, seen, out); !s)
          return fileError(name, static_cast<std::size_t>(lineNo), "in #include \"" + inc + "\": " + s.error().message);
      }
      // Keep the including file's line numbers in compiler messages.
      out += "#line " + std::to_string(lineNo + 1) + "\n";
      continue;
    }
    out += line;
    out += '\n';
  }
  return Ok{};
}

}  // namespace

Result<std::string> shaderSource(const std::string& name) {
  std::set<std::string> seen{name};
  std::string out;
  if (Status s = expand(name, seen, out); !s) return s.error();
  return out;
}

namespace {

Result<Shader> compileShader(GLenum stage, const std::string& name) {
  auto src = shaderSource(name);
  if (!src) return src.error();
  Shader sh(glCreateShader(stage));
  const char* text = src->c_str();
  glShaderSource(sh.get(), 1, &text, nullptr);
  glCompileShader(sh.get());
  GLint ok = GL_FALSE;
  glGetShaderiv(sh.get(), GL_COMPILE_STATUS, &ok);
  if (ok != GL_TRUE) {
    GLint len = 0;
    glGetShaderiv(sh.get(), GL_INFO_LOG_LENGTH, &len);
    std::string log(static_cast<std::size_t>(std::max(len, 1)), '\0');
    glGetShaderInfoLog(sh.get(), len, nullptr, log.data());
    return Error{"shader " + name + " does not compile:\n" + log};
  }
  return sh;
}

}  // namespace

Result<Program> linkProgram(const std::string& vert, const std::string& frag) {
  auto vs = compileShader(GL_VERTEX_SHADER, vert);
  if (!vs) return vs.error();
  auto fs = compileShader(GL_FRAGMENT_SHADER, frag);
  if (!fs) return fs.error();
  Program prog(glCreateProgram());
  glAttachShader(prog.get(), vs->get());
  glAttachShader(prog.get(), fs->get());
  glLinkProgram(prog.get());
  // The shaders are deleted when vs and fs go out of scope: GL keeps them while attached, and
  // frees them with the program.
  GLint ok = GL_FALSE;
  glGetProgramiv(prog.get(), GL_LINK_STATUS, &ok);
  if (ok != GL_TRUE) {
    GLint len = 0;
    glGetProgramiv(prog.get(), GL_INFO_LOG_LENGTH, &len);
    std::string log(static_cast<std::size_t>(std::max(len, 1)), '\0');
    glGetProgramInfoLog(prog.get(), len, nullptr, log.data());
    return Error{"program " + vert + " + " + frag + " does not link:\n" + log};
  }
  return prog;
}

}  // namespace fogbeam::gl
