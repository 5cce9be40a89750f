// The GL object owners of fogbeam_gl (core/src/gl/gl_object.hpp, private to the library): an
// owner deletes its object on reset() and destruction, moves hand the object on, and an owner
// whose context is not current deletes nothing, since the same name in the current context is
// another object. Skips when no EGL/OpenGL is available (FOGBEAM_REQUIRE_GL=1: failure).
#include "egl_context.hpp"
#include "gl_object.hpp"

#include <gtest/gtest.h>

#include <cstdlib>
#include <memory>
#include <string>
#include <utility>

namespace fogbeam::gl {
namespace {

// True when `why` (EglContext::create's error) is this machine lacking EGL/OpenGL, which skips
// the test unless FOGBEAM_REQUIRE_GL=1; anything else is a failure.
bool mayskip(const std::string& why) {
  const bool environment = why.rfind("no EGL available", 0) == 0 || why.rfind("could not create an OpenGL", 0) == 0 ||
                           why.rfind("EGL platform", 0) == 0;
  const char* require = std::getenv("FOGBEAM_REQUIRE_GL");
  return environment && !(require && std::string(require) == "1");
}

// `var`: a fresh context, current on this thread; skips or fails the test without one.
#define FOGBEAM_CONTEXT_OR_SKIP(var)                                                              \
  auto var##Result = EglContext::create(GlOptions{});                                             \
  if (!var##Result) {                                                                             \
    if (mayskip(var##Result.error().message)) GTEST_SKIP() << var##Result.error().message;        \
    FAIL() << var##Result.error().message;                                                        \
  }                                                                                               \
  std::unique_ptr<EglContext> var = std::move(var##Result).value()

// A buffer whose object exists (glGen only reserves a name; the first bind creates the object).
Buffer boundBuffer() {
  Buffer b = genBuffer();
  glBindBuffer(GL_ARRAY_BUFFER, b.get());
  glBindBuffer(GL_ARRAY_BUFFER, 0);
  return b;
}

TEST(GlObject, DeletesOnResetAndDestructionAndMovesOwnership) {
  FOGBEAM_CONTEXT_OR_SKIP(ctx);
  Buffer a = boundBuffer();
  const GLuint name = a.get();
  ASSERT_NE(name, 0u);
  EXPECT_EQ(glIsBuffer(name), GL_TRUE);
  Buffer b = std::move(a);
  EXPECT_FALSE(a);  // NOLINT(bugprone-use-after-move): the moved-from owner is empty by contract
  EXPECT_EQ(b.get(), name);
  a.reset();  // owns nothing: deletes nothing
  EXPECT_EQ(glIsBuffer(name), GL_TRUE);
  b.reset();
  EXPECT_FALSE(b);
  EXPECT_EQ(glIsBuffer(name), GL_FALSE);

  GLuint texName = 0;
  {
    Texture t = genTexture();
    glBindTexture(GL_TEXTURE_2D, t.get());
    glBindTexture(GL_TEXTURE_2D, 0);
    texName = t.get();
    EXPECT_EQ(glIsTexture(texName), GL_TRUE);
  }
  EXPECT_EQ(glIsTexture(texName), GL_FALSE);

  Sync fence = fenceSync();
  ASSERT_TRUE(fence);
  const GLsync handle = fence.get();
  EXPECT_EQ(glIsSync(handle), GL_TRUE);
  Sync other = std::move(fence);
  other = Sync{};  // move-assigning over an owner deletes its object
  EXPECT_EQ(glIsSync(handle), GL_FALSE);
}

TEST(GlObject, DeletesNothingWhileAnotherContextIsCurrent) {
  FOGBEAM_CONTEXT_OR_SKIP(first);
  Buffer inFirst = boundBuffer();
  const GLuint firstName = inFirst.get();
  FOGBEAM_CONTEXT_OR_SKIP(second);  // current from here
  Buffer inSecond = boundBuffer();
  const GLuint secondName = inSecond.get();
  // Fresh contexts number their buffers alike: the same name, two objects.
  inFirst.reset();
  EXPECT_EQ(glIsBuffer(secondName), GL_TRUE) << "the first context's owner deleted a buffer of the second";
  ASSERT_TRUE(first->makeCurrent().has_value());
  EXPECT_EQ(glIsBuffer(firstName), GL_TRUE) << "left to its context, which frees it when destroyed";
  ASSERT_TRUE(second->makeCurrent().has_value());
  inSecond.reset();
  EXPECT_EQ(glIsBuffer(secondName), GL_FALSE);
}

}  // namespace
}  // namespace fogbeam::gl
