// fogbeam — the one header that includes OpenGL and EGL (Filament's gl_headers.h does the same).
// Every GL/EGL entry point goes through libepoxy, which loads libEGL / libGL at run time, so the
// surface pass links no GL library directly and can report "no EGL" instead of failing to load.
// Private to fogbeam_gl: never include it from a public header.
#pragma once

#include <epoxy/egl.h>  // IWYU pragma: export
#include <epoxy/gl.h>   // IWYU pragma: export

#include <string>

namespace fogbeam::gl {

/// "EGL_BAD_CONFIG", … ; "EGL error 0x…" for unknown codes.
[[nodiscard]] std::string eglErrorName(EGLint code);
/// "GL_INVALID_OPERATION", … ; "GL error 0x…" for unknown codes.
[[nodiscard]] std::string glErrorName(GLenum code);
/// "<what> failed: EGL_BAD_…" from eglGetError().
[[nodiscard]] std::string eglFailure(const std::string& what);
/// Drains glGetError(); returns "" when there was none, else "<where>: GL_INVALID_ENUM, …".
[[nodiscard]] std::string glErrors(const std::string& where);

}  // namespace fogbeam::gl
