// fogbeam — GlAirlightPass (fogbeam/gl/airlight_pass.hpp): uploads the fast path's tables as
// textures (F table: R32F 2D; isotropic lamps' sky tables: R32F 2D, one row per lamp; view
// tables: RG32F 3D, x = distance node), the distance buffer as an R32F texture, draws one
// full-screen triangle into an RGBA32F target and reads it back.
#include <fogbeam/gl/airlight_pass.hpp>

#include "egl_context.hpp"
#include "gl_headers.hpp"
#include "shader_library.hpp"

#include <algorithm>
#include <array>
#include <chrono>
#include <cstddef>
#include <cstring>
#include <limits>
#include <string>
#include <tuple>

namespace fogbeam {

namespace {

using Clock = std::chrono::steady_clock;
double msSince(Clock::time_point t0) { return std::chrono::duration<double, std::milli>(Clock::now() - t0).count(); }

constexpr int kMaxIso = 32;   // airlight_tables.frag: kMaxIso
constexpr int kMaxView = 6;   // airlight_tables.frag: kMaxView

// What a texture was uploaded from: re-upload when any differs.
using TableKey = std::tuple<const float*, std::size_t, int, int, int>;

}  // namespace

struct GlAirlightPass::Impl {
  std::unique_ptr<gl::EglContext> egl;
  std::string description;
  GlAirlightStats stats;
  bool timerQuery = false;
  GLuint program = 0, vao = 0, fbo = 0, colorTex = 0, distanceTex = 0, isoTex = 0, skyTex = 0, query = 0;
  std::vector<float> sky;  // the isotropic lamps' sky tables, one row each
  std::array<GLuint, kMaxView> viewTex{};
  std::array<TableKey, kMaxView> viewKey{};
  TableKey isoKey{};
  int width = 0, height = 0;
  std::vector<float> readback;

  ~Impl() {
    if (!egl || !egl->makeCurrent()) return;
    glDeleteProgram(program);
    glDeleteVertexArrays(1, &vao);
    glDeleteFramebuffers(1, &fbo);
    glDeleteTextures(1, &colorTex);
    glDeleteTextures(1, &distanceTex);
    glDeleteTextures(1, &isoTex);
    glDeleteTextures(1, &skyTex);
    glDeleteTextures(kMaxView, viewTex.data());
    if (query) glDeleteQueries(1, &query);
  }

  GLint loc(const char* name) const { return glGetUniformLocation(program, name); }

  Status ensureTarget(int w, int h) {
    if (w == width && h == height) return Ok{};
    glDeleteTextures(1, &colorTex);
    glDeleteTextures(1, &distanceTex);
    glGenTextures(1, &colorTex);
    glBindTexture(GL_TEXTURE_2D, colorTex);
    glTexStorage2D(GL_TEXTURE_2D, 1, GL_RGBA32F, w, h);
    glGenTextures(1, &distanceTex);
    glBindTexture(GL_TEXTURE_2D, distanceTex);
    glTexStorage2D(GL_TEXTURE_2D, 1, GL_R32F, w, h);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
    glBindFramebuffer(GL_FRAMEBUFFER, fbo);
    glFramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_2D, colorTex, 0);
    if (glCheckFramebufferStatus(GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE)
      return Error{"airlight framebuffer (RGBA32F) incomplete"};
    width = w;
    height = h;
    readback.resize(static_cast<std::size_t>(w) * static_cast<std::size_t>(h) * 4);
    if (std::string e = gl::glErrors("airlight target " + std::to_string(w) + "x" + std::to_string(h)); !e.empty())
      return Error{e};
    return Ok{};
  }
};

GlAirlightPass::GlAirlightPass(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
GlAirlightPass::~GlAirlightPass() = default;

Result<std::unique_ptr<GlAirlightPass>> GlAirlightPass::create(const GlOptions& options) {
  auto impl = std::make_unique<Impl>();
  auto ctx = gl::EglContext::create(options);
  if (!ctx) return ctx.error();
  impl->egl = std::move(ctx).value();
  auto str = [](GLenum e) {
    const auto* s = reinterpret_cast<const char*>(glGetString(e));
    return std::string(s ? s : "?");
  };
  impl->description = str(GL_VENDOR) + " | " + str(GL_RENDERER) + " | " + str(GL_VERSION) + " | EGL " +
                      impl->egl->platformName();
  impl->timerQuery = epoxy_gl_version() >= 33 || epoxy_has_gl_extension("GL_ARB_timer_query");
  auto prog = gl::linkProgram("surface_fullscreen.vert", "airlight_tables.frag");
  if (!prog) return prog.error();
  impl->program = *prog;
  glGenVertexArrays(1, &impl->vao);
  glGenFramebuffers(1, &impl->fbo);
  glGenTextures(1, &impl->isoTex);
  glGenTextures(1, &impl->skyTex);
  glGenTextures(kMaxView, impl->viewTex.data());
  if (impl->timerQuery) glGenQueries(1, &impl->query);
  if (std::string e = gl::glErrors("GL airlight pass set-up"); !e.empty()) return Error{e};
  return std::unique_ptr<GlAirlightPass>(new GlAirlightPass(std::move(impl)));
}

std::string GlAirlightPass::description() const { return impl_->description; }
const GlAirlightStats& GlAirlightPass::stats() const noexcept { return impl_->stats; }

Status GlAirlightPass::render(const Camera& camera, const AirlightImageEvaluator::FastPathView& view,
                              const SurfaceBuffers& surface, std::vector<float>& rgb) {
  Impl& m = *impl_;
  if (!view.complete) return Error{"GL airlight pass: some lamps are evaluated per ray on the CPU (spot or world-fixed "
                                   "measured profiles); the shader only has the table formula"};
  const std::size_t nIso = view.isoLamps ? view.isoLamps->size() : 0;
  std::vector<const kernels::ViewTable*> tables;
  if (view.viewTables)
    for (const auto& t : *view.viewTables)
      if (!t.data.empty()) tables.push_back(&t);
  if (nIso > kMaxIso) return Error{"GL airlight pass: " + std::to_string(nIso) + " isotropic lamps, at most 32"};
  if (tables.size() > kMaxView)
    return Error{"GL airlight pass: " + std::to_string(tables.size()) + " view tables, at most " +
                 std::to_string(kMaxView)};
  if (nIso > 0 && !view.isoTable) return Error{"GL airlight pass: isotropic lamps without an F table"};
  if (Status s = m.egl->makeCurrent(); !s) return s;
  const int w = camera.width, h = camera.height;
  if (Status s = m.ensureTarget(w, h); !s) return s;
  m.stats = {};

  const auto tUp = Clock::now();
  // Tables, when they changed (the view tables are rebuilt only when the rig or fog changes).
  const auto tTables = Clock::now();
  if (view.isoTable) {
    const kernels::IsoTable& t = *view.isoTable;
    const TableKey key{t.data.data(), t.data.size(), t.nK, t.nZ, 0};
    if (key != m.isoKey) {
      glBindTexture(GL_TEXTURE_2D, m.isoTex);
      glTexImage2D(GL_TEXTURE_2D, 0, GL_R32F, t.nZ, t.nK, 0, GL_RED, GL_FLOAT, t.data.data());
      // texelFetch only, one level: without this the texture is incomplete (mipmapped default).
      glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
      glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
      m.isoKey = key;
    }
  }
  for (std::size_t v = 0; v < tables.size(); ++v) {
    const kernels::ViewTable& t = *tables[v];
    const TableKey key{t.data.data(), t.data.size(), t.nA, t.nB, t.nX};
    if (key == m.viewKey[v]) continue;
    glBindTexture(GL_TEXTURE_3D, m.viewTex[v]);
    glTexImage3D(GL_TEXTURE_3D, 0, GL_RG32F, t.nX, t.nA, t.nB, 0, GL_RG, GL_FLOAT, t.data.data());
    glTexParameteri(GL_TEXTURE_3D, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
    glTexParameteri(GL_TEXTURE_3D, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
    m.viewKey[v] = key;
  }
  // The sky tables change with every move of eye or lamp: uploaded every frame (4 KiB a lamp).
  // A lamp without one (sky rays through the F table) gets a row of NaN, which the shader
  // recognises.
  const std::size_t skyRow = 2 * static_cast<std::size_t>(kernels::kIsoSkyNodes);
  m.sky.assign(skyRow * std::max<std::size_t>(nIso, 1), std::numeric_limits<float>::quiet_NaN());
  for (std::size_t l = 0; l < nIso; ++l)
    if (const float* t = (*view.isoLamps)[l].sky) std::copy_n(t, skyRow, m.sky.data() + l * skyRow);
  glBindTexture(GL_TEXTURE_2D, m.skyTex);
  glTexImage2D(GL_TEXTURE_2D, 0, GL_R32F, static_cast<GLsizei>(skyRow), static_cast<GLsizei>(std::max<std::size_t>(nIso, 1)),
               0, GL_RED, GL_FLOAT, m.sky.data());
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
  m.stats.table_upload_ms = msSince(tTables);
  // Distances: row 0 of the texture is image row 0 (the shader flips gl_FragCoord.y).
  glPixelStorei(GL_UNPACK_ALIGNMENT, 4);
  glBindTexture(GL_TEXTURE_2D, m.distanceTex);
  glTexSubImage2D(GL_TEXTURE_2D, 0, 0, 0, w, h, GL_RED, GL_FLOAT, surface.distance.data());
  if (std::string e = gl::glErrors("GL airlight upload"); !e.empty()) return Error{e};
  m.stats.upload_ms = msSince(tUp);

  // Uniforms.
  glUseProgram(m.program);
  const double f = camera.focalLengthPixels();
  const Vec2 principal = camera.principalPoint();  // (w/2, h/2) unless off-axis
  glUniform2f(m.loc("uPrincipal"), static_cast<float>(principal.x), static_cast<float>(principal.y));
  glUniform1f(m.loc("uInvF"), static_cast<float>(1.0 / f));
  glUniform1i(m.loc("uHeight"), h);
  glUniform1i(m.loc("uIsoCount"), static_cast<GLint>(nIso));
  if (view.isoTable) {
    glUniform1i(m.loc("uIsoNK"), view.isoTable->nK);
    glUniform1i(m.loc("uIsoNZ"), view.isoTable->nZ);
    glUniform1f(m.loc("uIsoK0"), view.isoTable->k0);
    glUniform1f(m.loc("uIsoUScale"), view.isoTable->uScale);
    glUniform1i(m.loc("uIsoSkyNodes"), kernels::kIsoSkyNodes);
  }
  for (std::size_t l = 0; l < nIso; ++l) {
    const kernels::IsoLamp& L = (*view.isoLamps)[l];
    const std::string i = "[" + std::to_string(l) + "]";
    glUniform4f(m.loc(("uIsoPos" + i).c_str()), L.pos[0], L.pos[1], L.pos[2], L.kt);
    glUniform3f(m.loc(("uIsoWeight" + i).c_str()), L.weight[0], L.weight[1], L.weight[2]);
    glUniform3f(m.loc(("uIsoDir" + i).c_str()), L.dir[0], L.dir[1], L.dir[2]);
  }
  glUniform1i(m.loc("uViewCount"), static_cast<GLint>(tables.size()));
  for (std::size_t v = 0; v < tables.size(); ++v) {
    const kernels::ViewTable& t = *tables[v];
    const std::string i = "[" + std::to_string(v) + "]";
    glUniform4f(m.loc(("uViewGrid" + i).c_str()), t.a0, t.b0, t.invStep, t.distanceScale);
    glUniform3i(m.loc(("uViewSize" + i).c_str()), t.nA, t.nB, t.nX);
    // The per-ray guard disc of the CPU path reads the finest inset here (inner radius 0).
    const bool finest = v + 1 == tables.size() || tables[v + 1]->guardA != t.guardA || tables[v + 1]->innerR2 >= 1e30f ||
                        tables[v + 1]->outerR2 >= 1e30f;
    const float inner = (finest && t.outerR2 < 1e30f) ? -1.0f : t.innerR2;
    glUniform4f(m.loc(("uViewGuard" + i).c_str()), t.guardA, t.guardB, inner, t.outerR2);
    glUniform3f(m.loc(("uViewWeight" + i).c_str()), t.weight[0], t.weight[1], t.weight[2]);
  }
  glActiveTexture(GL_TEXTURE0);
  glBindTexture(GL_TEXTURE_2D, m.distanceTex);
  glActiveTexture(GL_TEXTURE1);
  glBindTexture(GL_TEXTURE_2D, m.isoTex);
  glActiveTexture(GL_TEXTURE2 + kMaxView);
  glBindTexture(GL_TEXTURE_2D, m.skyTex);
  for (std::size_t v = 0; v < kMaxView; ++v) {
    glActiveTexture(GL_TEXTURE2 + static_cast<GLenum>(v));
    glBindTexture(GL_TEXTURE_3D, m.viewTex[v]);
  }
  glActiveTexture(GL_TEXTURE0);

  // Draw.
  const auto tDraw = Clock::now();
  glBindFramebuffer(GL_FRAMEBUFFER, m.fbo);
  glViewport(0, 0, w, h);
  glDisable(GL_DEPTH_TEST);
  glBindVertexArray(m.vao);
  if (m.timerQuery) glBeginQuery(GL_TIME_ELAPSED, m.query);
  glDrawArrays(GL_TRIANGLES, 0, 3);
  if (m.timerQuery) glEndQuery(GL_TIME_ELAPSED);
  glFinish();
  m.stats.draw_ms = msSince(tDraw);
  if (m.timerQuery) {
    // Reported beside the wall time, not instead of it: llvmpipe's GL_TIME_ELAPSED covers only
    // part of its rasterisation (5 ms against 780 ms of wall time at 1080p here).
    GLuint64 ns = 0;
    glGetQueryObjectui64v(m.query, GL_QUERY_RESULT, &ns);
    m.stats.gpu_timer_ms = static_cast<double>(ns) * 1e-6;
  }
  if (std::string e = gl::glErrors("GL airlight draw"); !e.empty()) return Error{e};

  // Readback (synchronous: the bench times it on its own) and flip rows to top-down.
  const auto tRead = Clock::now();
  glPixelStorei(GL_PACK_ALIGNMENT, 4);
  glReadBuffer(GL_COLOR_ATTACHMENT0);
  glReadPixels(0, 0, w, h, GL_RGBA, GL_FLOAT, m.readback.data());
  const auto W = static_cast<std::size_t>(w), H = static_cast<std::size_t>(h);
  rgb.resize(3 * W * H);
  for (std::size_t j = 0; j < H; ++j) {
    const float* src = m.readback.data() + (H - 1 - j) * W * 4;
    float* dst = rgb.data() + j * W * 3;
    for (std::size_t i = 0; i < W; ++i) {
      dst[3 * i] = src[4 * i];
      dst[3 * i + 1] = src[4 * i + 1];
      dst[3 * i + 2] = src[4 * i + 2];
    }
  }
  m.stats.readback_ms = msSince(tRead);
  if (std::string e = gl::glErrors("GL airlight readback"); !e.empty()) return Error{e};
  return Ok{};
}

}  // namespace fogbeam
