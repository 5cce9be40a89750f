// fogbeam — the airlight layer as a GLSL full-screen pass (shaders/airlight_tables.frag): the
// same per-pixel table formula as the CPU SIMD kernels (fogbeam/render/airlight_kernels.hpp),
// evaluated by the GPU (or by llvmpipe where there is none) from the same tables.
//
// Inputs: the camera, the tables and lamp parameters of an AirlightImageEvaluator after its
// evaluate() for the same frame (fastPathView()), and the surface pass's distance buffer.
// Output: RGB airlight per pixel in cd/m², row 0 at the top. Lamps the CPU evaluates per ray
// (spots, world-fixed measured profiles, the last pixels at a vehicle lamp's image) are not
// in the tables: render() refuses a view that is not `complete`, and the guard discs read the
// finest inset table instead.
//
// Used by `fogbeam bench` to compare the CPU path with a GPU shader on the same frame.
// Thread-safety: one instance owns one GL context; use it from one thread at a time.
#pragma once

#include <fogbeam/gl/surface_pass.hpp>
#include <fogbeam/render/airlight_image.hpp>
#include <fogbeam/render/surface.hpp>
#include <fogbeam/scene/scene.hpp>
#include <fogbeam/util/result.hpp>

#include <memory>
#include <string>
#include <vector>

namespace fogbeam {

/// Timings of the latest GlAirlightPass::render(), milliseconds.
struct GlAirlightStats {
  double upload_ms = 0.0;    ///< distance texture (every frame) and tables (when they changed)
  double draw_ms = 0.0;      ///< wall time of the full-screen draw up to glFinish()
  double gpu_timer_ms = 0.0; ///< GL_TIME_ELAPSED of the draw where supported (see airlight_pass.cpp)
  double readback_ms = 0.0;  ///< glReadPixels of the RGBA32F result and the row flip
  double table_upload_ms = 0.0;  ///< part of upload_ms spent on tables
};

class GlAirlightPass {
 public:
  [[nodiscard]] static Result<std::unique_ptr<GlAirlightPass>> create(const GlOptions& options = {});
  ~GlAirlightPass();
  GlAirlightPass(const GlAirlightPass&) = delete;
  GlAirlightPass& operator=(const GlAirlightPass&) = delete;

  /// Renders the airlight of `view` for `camera` over `surface.distance` into `rgb`
  /// (3 floats per pixel, resized). Errors: incomplete view, too many lamps or tables for the
  /// shader's arrays (32 isotropic lamps, 6 view tables), GL failures by name.
  [[nodiscard]] Status render(const Camera& camera, const AirlightImageEvaluator::FastPathView& view,
                              const SurfaceBuffers& surface, std::vector<float>& rgb);

  [[nodiscard]] std::string description() const;
  [[nodiscard]] const GlAirlightStats& stats() const noexcept;

  struct Impl;

 private:
  explicit GlAirlightPass(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace fogbeam
