// fogbeam — GLSL sources of the GL passes: embedded at build time from shaders/, or read
// from $FOGBEAM_SHADER_DIR at run time when that variable is set (shader development).
#pragma once

#include "gl_headers.hpp"
#include "gl_object.hpp"

#include <fogbeam/util/result.hpp>

#include <cstddef>
#include <string>

namespace fogbeam::gl {

struct EmbeddedShader {
  const char* name;  ///< file name in shaders/, e.g. "surface_plane.frag"
  const char* text;
};
extern const EmbeddedShader kEmbeddedShaders[];
extern const std::size_t kEmbeddedShaderCount;

/// The source of shader `name` with every `#include "file"` line replaced by that file's text
/// (recursively; a file is included once). Errors name the file and the missing include.
[[nodiscard]] Result<std::string> shaderSource(const std::string& name);

/// Compiles two shaders from the library and links them; errors carry the info log.
/// A GL context must be current; the program belongs to it.
[[nodiscard]] Result<Program> linkProgram(const std::string& vert, const std::string& frag);

}  // namespace fogbeam::gl
