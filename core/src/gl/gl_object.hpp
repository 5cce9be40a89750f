// fogbeam — RAII owners of OpenGL objects: buffers, textures, framebuffers, renderbuffers,
// programs, shaders, vertex arrays, queries (GLuint names) and fence syncs (GLsync).
//
// A GL name belongs to the context that created it, and glDelete* acts on whatever context is
// current on the calling thread, where the same number may name another pass's object. An owner
// therefore remembers the context current when it took its name and deletes the name only while
// that context is current again. Code that owns GL objects makes its context current before they
// are destroyed (GlSurfacePass::Impl's destructor) and keeps the context alive longer than them
// (declared before them); where the context cannot be made current (a lost display) the names
// are left to the context's own destruction, which frees them.
//
// Private to fogbeam_gl. Thread-safety: that of the owning context (one thread at a time).
#pragma once

#include "gl_headers.hpp"

#include <utility>

namespace fogbeam::gl {

namespace detail {
/// The EGL context current on the calling thread (EGL_NO_CONTEXT when none).
[[nodiscard]] EGLContext currentContext() noexcept;
// glDelete* of one object, in the current context.
void deleteBuffer(GLuint name) noexcept;
void deleteTexture(GLuint name) noexcept;
void deleteFramebuffer(GLuint name) noexcept;
void deleteRenderbuffer(GLuint name) noexcept;
void deleteProgram(GLuint name) noexcept;
void deleteShader(GLuint name) noexcept;
void deleteVertexArray(GLuint name) noexcept;
void deleteQuery(GLuint name) noexcept;
void deleteSync(GLsync sync) noexcept;
}  // namespace detail

/// Owns one GL object (`Handle` = GLuint name or GLsync; the null handle owns nothing).
/// Move-only; deletes its object on destruction or reset() when its context is current.
template <class Handle, void (*Delete)(Handle) noexcept>
class Object {
 public:
  Object() noexcept = default;
  /// Takes `handle`, created in the context current on this thread.
  explicit Object(Handle handle) noexcept
      : handle_(handle), context_(handle != Handle{} ? detail::currentContext() : EGL_NO_CONTEXT) {}
  ~Object() { reset(); }
  Object(const Object&) = delete;
  Object& operator=(const Object&) = delete;
  Object(Object&& other) noexcept
      : handle_(std::exchange(other.handle_, Handle{})), context_(std::exchange(other.context_, EGL_NO_CONTEXT)) {}
  Object& operator=(Object&& other) noexcept {
    if (this != &other) {
      reset();
      handle_ = std::exchange(other.handle_, Handle{});
      context_ = std::exchange(other.context_, EGL_NO_CONTEXT);
    }
    return *this;
  }

  /// The GL handle, for GL calls (null when empty); ownership stays here.
  [[nodiscard]] Handle get() const noexcept { return handle_; }
  explicit operator bool() const noexcept { return handle_ != Handle{}; }

  /// Deletes the object (only in its own context, see the header comment) and owns nothing.
  void reset() noexcept {
    if (handle_ != Handle{} && context_ == detail::currentContext()) Delete(handle_);
    handle_ = Handle{};
    context_ = EGL_NO_CONTEXT;
  }

 private:
  Handle handle_{};
  EGLContext context_ = EGL_NO_CONTEXT;
};

using Buffer = Object<GLuint, detail::deleteBuffer>;
using Texture = Object<GLuint, detail::deleteTexture>;
using Framebuffer = Object<GLuint, detail::deleteFramebuffer>;
using Renderbuffer = Object<GLuint, detail::deleteRenderbuffer>;
using Program = Object<GLuint, detail::deleteProgram>;
using Shader = Object<GLuint, detail::deleteShader>;
using VertexArray = Object<GLuint, detail::deleteVertexArray>;
using Query = Object<GLuint, detail::deleteQuery>;
using Sync = Object<GLsync, detail::deleteSync>;

// A new object of each kind (glGen*), owned. A GL context must be current.
[[nodiscard]] Buffer genBuffer();
[[nodiscard]] Texture genTexture();
[[nodiscard]] Framebuffer genFramebuffer();
[[nodiscard]] Renderbuffer genRenderbuffer();
[[nodiscard]] VertexArray genVertexArray();
[[nodiscard]] Query genQuery();
/// A fence after every command issued so far (glFenceSync(GL_SYNC_GPU_COMMANDS_COMPLETE)).
[[nodiscard]] Sync fenceSync();

}  // namespace fogbeam::gl
