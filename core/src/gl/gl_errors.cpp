// fogbeam — EGL and GL error codes by name (gl_errors.hpp).
#include "gl_errors.hpp"

#include <cstdio>

namespace fogbeam::gl {

namespace {
std::string hex(const char* prefix, unsigned code) {
  char buf[48];
  std::snprintf(buf, sizeof buf, "%s 0x%04X", prefix, code);
  return buf;
}
}  // namespace

std::string eglErrorName(EGLint code) {
  switch (code) {
    case EGL_SUCCESS: return "EGL_SUCCESS";
    case EGL_NOT_INITIALIZED: return "EGL_NOT_INITIALIZED";
    case EGL_BAD_ACCESS: return "EGL_BAD_ACCESS";
    case EGL_BAD_ALLOC: return "EGL_BAD_ALLOC";
    case EGL_BAD_ATTRIBUTE: return "EGL_BAD_ATTRIBUTE";
    case EGL_BAD_CONTEXT: return "EGL_BAD_CONTEXT";
    case EGL_BAD_CONFIG: return "EGL_BAD_CONFIG";
    case EGL_BAD_CURRENT_SURFACE: return "EGL_BAD_CURRENT_SURFACE";
    case EGL_BAD_DISPLAY: return "EGL_BAD_DISPLAY";
    case EGL_BAD_SURFACE: return "EGL_BAD_SURFACE";
    case EGL_BAD_MATCH: return "EGL_BAD_MATCH";
    case EGL_BAD_PARAMETER: return "EGL_BAD_PARAMETER";
    case EGL_BAD_NATIVE_PIXMAP: return "EGL_BAD_NATIVE_PIXMAP";
    case EGL_BAD_NATIVE_WINDOW: return "EGL_BAD_NATIVE_WINDOW";
    case EGL_CONTEXT_LOST: return "EGL_CONTEXT_LOST";
    case EGL_BAD_DEVICE_EXT: return "EGL_BAD_DEVICE_EXT";
    default: return hex("EGL error", static_cast<unsigned>(code));
  }
}

std::string glErrorName(GLenum code) {
  switch (code) {
    case GL_NO_ERROR: return "GL_NO_ERROR";
    case GL_INVALID_ENUM: return "GL_INVALID_ENUM";
    case GL_INVALID_VALUE: return "GL_INVALID_VALUE";
    case GL_INVALID_OPERATION: return "GL_INVALID_OPERATION";
    case GL_INVALID_FRAMEBUFFER_OPERATION: return "GL_INVALID_FRAMEBUFFER_OPERATION";
    case GL_OUT_OF_MEMORY: return "GL_OUT_OF_MEMORY";
    case GL_STACK_UNDERFLOW: return "GL_STACK_UNDERFLOW";
    case GL_STACK_OVERFLOW: return "GL_STACK_OVERFLOW";
    case GL_CONTEXT_LOST: return "GL_CONTEXT_LOST";
    default: return hex("GL error", code);
  }
}

std::string eglFailure(const std::string& what) { return what + " failed: " + eglErrorName(eglGetError()); }

std::string glErrors(const std::string& where) {
  std::string names;
  for (int guard = 0; guard < 16; ++guard) {  // a lost context may report errors forever
    const GLenum e = glGetError();
    if (e == GL_NO_ERROR) break;
    if (!names.empty()) names += ", ";
    names += glErrorName(e);
    if (e == GL_CONTEXT_LOST) break;
  }
  return names.empty() ? std::string() : where + ": " + names;
}

}  // namespace fogbeam::gl
