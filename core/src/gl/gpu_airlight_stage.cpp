// fogbeam — the GPU airlight stage of the GL surface pass (gpu_airlight_stage.hpp).
#include "gpu_airlight_stage.hpp"

#include "gl_errors.hpp"
#include "shader_library.hpp"

#include <glm/gtc/type_ptr.hpp>

#include <string>
#include <variant>
#include <vector>

namespace fogbeam::gl {

namespace {

// Same phase function (same kind and parameters): the G-moment table depends on nothing else.
bool samePhase(const Phase& a, const Phase& b) {
  if (a.index() != b.index()) return false;
  if (const auto* x = std::get_if<HenyeyGreensteinPhase>(&a)) return x->g == std::get<HenyeyGreensteinPhase>(b).g;
  if (const auto* x = std::get_if<FogMiePhase>(&a)) return x->diameter_um == std::get<FogMiePhase>(b).diameter_um;
  return true;
}

bool sameTableResolution(const AirlightOptions& a, const AirlightOptions& b) {
  return a.g_table_theta == b.g_table_theta && a.g_table_k == b.g_table_k && a.g_table_k_max == b.g_table_k_max;
}

// A float texture read with texelFetch only: one level, no filtering (without the parameters
// the default mipmapped minification makes it incomplete).
void uploadTexels(GLuint tex, GLenum internal, GLenum format, int w, int h, const std::vector<float>& data) {
  glBindTexture(GL_TEXTURE_2D, tex);
  glTexImage2D(GL_TEXTURE_2D, 0, static_cast<GLint>(internal), w, h, 0, format, GL_FLOAT, data.data());
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
}

}  // namespace

Status GpuAirlightStage::configure(const std::optional<GpuAirlightOptions>& options) {
  if (options && (options->pieces < 1 || options->pieces > 1024))
    return Error{"GPU airlight: pieces must be in 1..1024, got " + std::to_string(options->pieces)};
  options_ = options;
  return Ok{};
}

Status GpuAirlightStage::prepare(const Scene& scene) {
  if (Status s = ensureProgram(); !s) return s;
  if (Status s = ensureTarget(scene.camera.width, scene.camera.height); !s) return s;
  ensureTable(scene.fog.phase);
  if (std::string e = glErrors("GPU airlight set-up"); !e.empty()) return Error{e};
  return Ok{};
}

Status GpuAirlightStage::ensureProgram() {
  if (program_) return Ok{};
  auto prog = linkProgram("surface_fullscreen.vert", "airlight_accurate.frag");
  if (!prog) return prog.error();
  program_ = std::move(prog).value();
  const GLuint p = program_.get();
  Uniforms& u = uniforms_;
  u.worldFromCamera = glGetUniformLocation(p, "uWorldFromCamera");
  u.focalPrincipal = glGetUniformLocation(p, "uFocalPrincipal");
  u.lampCount = glGetUniformLocation(p, "uLampCount");
  u.extinction = glGetUniformLocation(p, "uExtinction");
  u.albedo = glGetUniformLocation(p, "uAlbedo");
  u.pieces = glGetUniformLocation(p, "uPieces");
  u.gThetaN = glGetUniformLocation(p, "uGThetaN");
  u.gKN = glGetUniformLocation(p, "uGKN");
  u.gK0 = glGetUniformLocation(p, "uGK0");
  u.gLogSpan = glGetUniformLocation(p, "uGLogSpan");
  u.gKMax = glGetUniformLocation(p, "uGKMax");
  u.phaseKind = glGetUniformLocation(p, "uPhaseKind");
  u.phase = glGetUniformLocation(p, "uPhase");
  fbo_ = genFramebuffer();
  gMoments_ = genTexture();
  gMomentsLo_ = genTexture();
  gTheta_ = genTexture();
  return Ok{};
}

Status GpuAirlightStage::ensureTarget(int width, int height) {
  if (width == width_ && height == height_) return Ok{};
  target_ = genTexture();
  glBindTexture(GL_TEXTURE_2D, target_.get());
  glTexStorage2D(GL_TEXTURE_2D, 1, GL_RGBA32F, width, height);
  glBindFramebuffer(GL_FRAMEBUFFER, fbo_.get());
  glFramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_2D, target_.get(), 0);
  if (glCheckFramebufferStatus(GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE)
    return Error{"airlight framebuffer (RGBA32F) incomplete"};
  width_ = width;
  height_ = height;
  return Ok{};
}

void GpuAirlightStage::ensureTable(const Phase& phase) {
  if (table_ && samePhase(tablePhase_, phase) && sameTableResolution(tableOptions_, options_->table)) return;
  table_ = gMomentTexels(phase, options_->table);
  uploadTexels(gMoments_.get(), GL_RGBA32F, GL_RGBA, table_->nTheta, table_->nK, table_->texels);
  uploadTexels(gMomentsLo_.get(), GL_RGBA32F, GL_RGBA, table_->nTheta, table_->nK, table_->texelsLo);
  std::vector<float> theta(2 * table_->theta.size());
  for (std::size_t j = 0; j < table_->theta.size(); ++j) {
    theta[2 * j] = table_->theta[j];
    theta[2 * j + 1] = table_->thetaLo[j];
  }
  uploadTexels(gTheta_.get(), GL_RG32F, GL_RG, table_->nTheta, 1, theta);
  tablePhase_ = phase;
  tableOptions_ = options_->table;
}

void GpuAirlightStage::draw(const Scene& scene, const Inputs& in) {
  const Camera& cam = scene.camera;
  const Uniforms& u = uniforms_;
  glBindFramebuffer(GL_FRAMEBUFFER, fbo_.get());
  const GLenum target = GL_COLOR_ATTACHMENT0;
  glDrawBuffers(1, &target);
  glViewport(0, 0, cam.width, cam.height);
  glDisable(GL_DEPTH_TEST);
  glUseProgram(program_.get());
  const glm::mat3 worldFromCamera(cam.worldFromCamera);
  glUniformMatrix3fv(u.worldFromCamera, 1, GL_FALSE, glm::value_ptr(worldFromCamera));
  // (f, cx, H − cy): the principal point in GL window coordinates (y up from the bottom).
  const Vec2 principal = cam.principalPoint();
  glUniform3f(u.focalPrincipal, static_cast<float>(cam.focalLengthPixels()), static_cast<float>(principal.x),
              static_cast<float>(cam.height - principal.y));
  glUniform1i(u.lampCount, static_cast<GLint>(scene.lamps.size()));
  glUniform1f(u.extinction, static_cast<float>(scene.fog.extinction_per_m));
  glUniform1f(u.albedo, static_cast<float>(scene.fog.albedo));
  glUniform1i(u.pieces, options_->pieces);
  glUniform1i(u.gThetaN, table_->nTheta);
  glUniform1i(u.gKN, table_->nK);
  glUniform1f(u.gK0, static_cast<float>(table_->k0));
  glUniform1f(u.gLogSpan, static_cast<float>(table_->logSpan));
  glUniform1f(u.gKMax, static_cast<float>(table_->kMax));
  int kind = 0;
  float phase[4] = {0, 0, 0, 0};
  if (const auto* hg = std::get_if<HenyeyGreensteinPhase>(&scene.fog.phase)) {
    kind = 1;
    phase[0] = static_cast<float>(hg->g);
  } else if (const auto* fm = std::get_if<FogMiePhase>(&scene.fog.phase)) {
    kind = 2;
    phase[0] = static_cast<float>(fm->g_hg);
    phase[1] = static_cast<float>(fm->g_d);
    phase[2] = static_cast<float>(fm->alpha);
    phase[3] = static_cast<float>(fm->w);
  }
  glUniform1i(u.phaseKind, kind);
  glUniform4fv(u.phase, 1, phase);
  // Texture units as bound in airlight_accurate.frag and common_photometry.glsl.
  glActiveTexture(GL_TEXTURE0);
  glBindTexture(GL_TEXTURE_BUFFER, in.profileTexture);
  glActiveTexture(GL_TEXTURE1);
  glBindTexture(GL_TEXTURE_2D, in.distanceTexture);
  glActiveTexture(GL_TEXTURE2);
  glBindTexture(GL_TEXTURE_2D, gMoments_.get());
  glActiveTexture(GL_TEXTURE3);
  glBindTexture(GL_TEXTURE_2D, gTheta_.get());
  glActiveTexture(GL_TEXTURE4);
  glBindTexture(GL_TEXTURE_2D, gMomentsLo_.get());
  glActiveTexture(GL_TEXTURE0);
  if (in.timer != 0) glBeginQuery(GL_TIME_ELAPSED, in.timer);
  glBindVertexArray(in.emptyVao);
  glDrawArrays(GL_TRIANGLES, 0, 3);
  if (in.timer != 0) glEndQuery(GL_TIME_ELAPSED);
  glBindVertexArray(0);
}

}  // namespace fogbeam::gl
