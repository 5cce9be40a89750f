// fogbeam — EGL and GL error codes by name, for error messages ("eglInitialize failed:
// EGL_NOT_INITIALIZED", "surface pass draw/readback: GL_INVALID_OPERATION").
// Private to fogbeam_gl.
#pragma once

#include "gl_headers.hpp"

#include <string>

namespace fogbeam::gl {

/// "EGL_BAD_CONFIG", … ; "EGL error 0x…" for unknown codes.
[[nodiscard]] std::string eglErrorName(EGLint code);
/// "GL_INVALID_OPERATION", … ; "GL error 0x…" for unknown codes.
[[nodiscard]] std::string glErrorName(GLenum code);
/// "<what> failed: EGL_BAD_…" from eglGetError().
[[nodiscard]] std::string eglFailure(const std::string& what);
/// Drains glGetError() of the current context; returns "" when there was none, else
/// "<where>: GL_INVALID_ENUM, …".
[[nodiscard]] std::string glErrors(const std::string& where);

}  // namespace fogbeam::gl
