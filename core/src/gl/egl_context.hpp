// fogbeam — a headless EGL display + OpenGL core context (RAII owner, factory returns Result).
#pragma once

#include "gl_headers.hpp"

#include <fogbeam/gl/options.hpp>
#include <fogbeam/util/result.hpp>

#include <memory>
#include <string>

namespace fogbeam::gl {

class EglContext {
 public:
  /// Picks the platform (see GlPlatform), initialises EGL and creates an OpenGL ≥ 4.3 core
  /// context with no default framebuffer (EGL_KHR_surfaceless_context, else a 1×1 pbuffer).
  [[nodiscard]] static Result<std::unique_ptr<EglContext>> create(const GlOptions& options);
  ~EglContext();
  EglContext(const EglContext&) = delete;
  EglContext& operator=(const EglContext&) = delete;

  /// Makes the context current on the calling thread (no-op when it already is).
  [[nodiscard]] Status makeCurrent();
  [[nodiscard]] const std::string& platformName() const noexcept { return platform_; }

 private:
  EglContext() = default;
  EGLDisplay display_ = EGL_NO_DISPLAY;
  EGLContext context_ = EGL_NO_CONTEXT;
  EGLSurface surface_ = EGL_NO_SURFACE;
  std::string platform_;
};

}  // namespace fogbeam::gl
