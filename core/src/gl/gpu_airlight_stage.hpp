// fogbeam — the GPU airlight stage of the GL surface pass (GlSurfacePass::setAirlight, issue 7;
// docs/airlight.md, "The GPU airlight path"): the accurate airlight method per pixel in a
// full-screen fragment shader (shaders/airlight_accurate.frag), drawn after the surface draws in
// the same context from their distance attachment, into an RGBA32F target of its own (rgb =
// airlight in cd/m² per channel; GL rows bottom-up).
//
// It owns its program (compiled on first use: a machine that never turns the stage on never
// compiles it), its target and the G-moment table of the scene's phase function, uploaded as
// hi + lo float textures (the shader rebuilds the doubles). It reads what the surface pass
// provides: the lamp records (storage-buffer binding 0) and the profile buffer texture
// (LampUpload), the distance texture and an empty vertex array for the full-screen triangle.
// Private to fogbeam_gl. Thread-safety: that of the owning GL context (one thread at a time).
#pragma once

#include "gl_object.hpp"

#include <fogbeam/gl/surface_pass.hpp>
#include <fogbeam/physics/airlight.hpp>
#include <fogbeam/physics/medium.hpp>
#include <fogbeam/scene/scene.hpp>
#include <fogbeam/util/result.hpp>

#include <optional>

namespace fogbeam::gl {

class GpuAirlightStage {
 public:
  /// What draw() reads from the surface pass (GL names of the current context).
  struct Inputs {
    GLuint profileTexture = 0;  ///< LampUpload's buffer texture (texture unit 0, GL_TEXTURE_BUFFER)
    GLuint distanceTexture = 0; ///< R32F true distance [m] of the frame's surfaces (unit 1)
    GLuint emptyVao = 0;        ///< vertex array for the attribute-less full-screen triangle
    GLuint timer = 0;           ///< GL_TIME_ELAPSED query around the draw, or 0 for none
  };

  /// Turns the stage on with `options` (or off: empty) for the frames prepared from now on.
  /// Fails when `options` are out of range (pieces 1–1024); the stage is then unchanged. A new
  /// G-table resolution (options.table) makes the next prepare() upload the table again.
  [[nodiscard]] Status configure(const std::optional<GpuAirlightOptions>& options);
  [[nodiscard]] bool enabled() const noexcept { return options_.has_value(); }

  /// Before a frame's draw (stage on): the program (first use), the target at the camera's size
  /// and the G table of the scene's phase function (when it changed). A GL context must be current.
  [[nodiscard]] Status prepare(const Scene& scene);
  /// Draws the frame's airlight into the target (stage on, after prepare() for this scene).
  /// Leaves the target's framebuffer bound (GL_FRAMEBUFFER) and depth testing off.
  void draw(const Scene& scene, const Inputs& in);
  /// The framebuffer whose colour attachment 0 holds the latest draw (for the readback).
  [[nodiscard]] GLuint framebuffer() const noexcept { return fbo_.get(); }

 private:
  // Uniform locations of airlight_accurate.frag, looked up once after linking.
  struct Uniforms {
    GLint worldFromCamera = -1, focalPrincipal = -1, lampCount = -1, extinction = -1, albedo = -1, pieces = -1;
    GLint gThetaN = -1, gKN = -1, gK0 = -1, gLogSpan = -1, gKMax = -1, phaseKind = -1, phase = -1;
  };
  [[nodiscard]] Status ensureProgram();
  [[nodiscard]] Status ensureTarget(int width, int height);
  void ensureTable(const Phase& phase);

  std::optional<GpuAirlightOptions> options_;
  Program program_;
  Uniforms uniforms_;
  Framebuffer fbo_;
  Texture target_;  // RGBA32F, the frame's size
  int width_ = 0, height_ = 0;
  // The G-moment table (GMomentTexels) as textures: moments hi and lo (RGBA32F, nθ × nK) and the
  // θ nodes hi and lo (RG32F, nθ × 1); `table_` is what they hold, made for `tablePhase_` at the
  // resolution `tableOptions_`.
  Texture gMoments_, gMomentsLo_, gTheta_;
  std::optional<GMomentTexels> table_;
  Phase tablePhase_;
  AirlightOptions tableOptions_;
};

}  // namespace fogbeam::gl
