// fogbeam — RAII owners of OpenGL objects (gl_object.hpp): the deleters and generators.
#include "gl_object.hpp"

namespace fogbeam::gl {

namespace detail {

EGLContext currentContext() noexcept { return eglGetCurrentContext(); }

void deleteBuffer(GLuint name) noexcept { glDeleteBuffers(1, &name); }
void deleteTexture(GLuint name) noexcept { glDeleteTextures(1, &name); }
void deleteFramebuffer(GLuint name) noexcept { glDeleteFramebuffers(1, &name); }
void deleteRenderbuffer(GLuint name) noexcept { glDeleteRenderbuffers(1, &name); }
void deleteProgram(GLuint name) noexcept { glDeleteProgram(name); }
void deleteShader(GLuint name) noexcept { glDeleteShader(name); }
void deleteVertexArray(GLuint name) noexcept { glDeleteVertexArrays(1, &name); }
void deleteQuery(GLuint name) noexcept { glDeleteQueries(1, &name); }
void deleteSync(GLsync sync) noexcept { glDeleteSync(sync); }

}  // namespace detail

namespace {
// One name from a glGen* call (through epoxy's dispatch, resolved at the call), owned.
template <class Owner, class Gen>
Owner generate(Gen gen) {
  GLuint name = 0;
  gen(&name);
  return Owner(name);
}
}  // namespace

Buffer genBuffer() { return generate<Buffer>([](GLuint* n) { glGenBuffers(1, n); }); }
Texture genTexture() { return generate<Texture>([](GLuint* n) { glGenTextures(1, n); }); }
Framebuffer genFramebuffer() { return generate<Framebuffer>([](GLuint* n) { glGenFramebuffers(1, n); }); }
Renderbuffer genRenderbuffer() { return generate<Renderbuffer>([](GLuint* n) { glGenRenderbuffers(1, n); }); }
VertexArray genVertexArray() { return generate<VertexArray>([](GLuint* n) { glGenVertexArrays(1, n); }); }
Query genQuery() { return generate<Query>([](GLuint* n) { glGenQueries(1, n); }); }
Sync fenceSync() { return Sync(glFenceSync(GL_SYNC_GPU_COMMANDS_COMPLETE, 0)); }

}  // namespace fogbeam::gl
