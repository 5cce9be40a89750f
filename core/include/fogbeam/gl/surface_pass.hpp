// fogbeam — the GL surface pass: lit surfaces through fog and the distance to them, rendered
// headless through EGL (Mesa's surfaceless platform, or an EGL device such as an NVIDIA GPU).
//
// It fills the same SurfaceBuffers as the CPU null renderer renderSurfacesCpu()
// (fogbeam/render/surface.hpp), with the same equation, per colour channel:
//
//   L_s = L(S) e^{−K_t d} + I_a (1 − e^{−K_t d})                     [cd/m²]
//   L(S) = ρ/π · Σ_lamps colour · I(w) cos(incidence) e^{−K_t r} / r²   (Lambertian, lux → cd/m²)
//
// d is the true distance along the pixel's ray (metres, +inf for sky, where L_s = I_a).
// Lighting runs in the fragment shaders, or — GlOptions::shading, by default on software
// rasterisers such as llvmpipe — on the CPU from a geometry buffer the shaders write (normal, ρ,
// distance; SurfaceShader, fogbeam/render/surface_shading.hpp), with the same equation. With the
// glow on and `[glow] surfaces`, each lamp's term includes the fog's scattered light
// (fogbeam/render/fog_light.hpp) in both: per pixel in the shaders, over an adaptive grid on the CPU.
// Geometry: the scene's infinite planes (ray–plane intersection per pixel in a full-screen
// fragment shader, in double precision) and the triangles of the scene's glTF 2.0 file
// (rasterised; glTF (x, y, z) → fogbeam (z, x, y), see docs/surface_pass.md). No shadows.
//
// This header carries no GL or EGL type; the implementation lives in core/src/gl/ (surface_pass.cpp,
// with the GPU airlight stage, the readback ring and the lamp upload in classes of their own:
// docs/surface_pass.md, "Code").
// Thread-safety: one GlSurfacePass owns one GL context; use an instance from one thread at a
// time (render() makes its context current on the calling thread). Separate instances may be
// used from separate threads.
#pragma once

#include <fogbeam/gl/options.hpp>
#include <fogbeam/physics/airlight.hpp>
#include <fogbeam/render/surface.hpp>
#include <fogbeam/scene/scene.hpp>
#include <fogbeam/util/result.hpp>

#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace fogbeam {

/// The GPU airlight stage (issue 7): the accurate airlight method per pixel in a fragment shader
/// (shaders/airlight_accurate.frag), drawn after the surfaces from their distance attachment in
/// the same context, so the airlight does not wait for a CPU round trip. Measured and spot
/// profiles are integrated in `pieces` quadratic pieces per ray (the CPU's accurate method also
/// cuts at the profile's feature lines; here the pieces are finer instead).
struct GpuAirlightOptions {
  int pieces = 64;             ///< quadratic pieces per ray, measured profiles (spot rings: pieces/8)
  AirlightOptions table{};     ///< G-moment table resolution (as AirlightMethod::Accurate)
};

/// Timings of the latest collect() (or render()), milliseconds.
struct GlSurfaceStats {
  double surface_ms = 0.0;   ///< GPU time of the surface draws (GL_TIME_ELAPSED; 0 without timer queries)
  double readback_ms = 0.0;  ///< CPU time waiting for the PBO fence, mapping and copying into SurfaceBuffers
  double airlight_ms = 0.0;  ///< GPU time of the airlight draw (GL_TIME_ELAPSED; 0 without the stage or the query)
  double submit_ms = 0.0;    ///< CPU time to upload lamps/planes and issue the draws and the readback
  double shade_ms = 0.0;     ///< CPU shading only: time lighting the geometry buffer (within readback_ms)
  std::size_t triangles = 0; ///< glTF triangles drawn
};

class GlSurfacePass {
 public:
  /// Creates the EGL display and an OpenGL 4.5 (4.3 at least) core context, compiles the shaders.
  /// Fails with a message naming the EGL/GL error (e.g. "eglInitialize failed: EGL_NOT_INITIALIZED")
  /// and, when no EGL library or display is available, says so.
  [[nodiscard]] static Result<std::unique_ptr<GlSurfacePass>> create(const GlOptions& options = {});

  ~GlSurfacePass();
  GlSurfacePass(const GlSurfacePass&) = delete;
  GlSurfacePass& operator=(const GlSurfacePass&) = delete;

  /// Renders the scene's planes and glTF meshes (loaded on first use, cached by path) and reads
  /// the result back into `out` (resized to the camera's width × height; row 0 is the top).
  /// Readback goes through a pixel-pack buffer and a fence (see submit()/collect()).
  [[nodiscard]] Status render(const Scene& scene, SurfaceBuffers& out);

  /// Pipelined use: submit() issues the draws and an asynchronous readback into one of two PBO
  /// slots; collect() waits for the oldest submitted frame and copies it into `out`. With two
  /// frames in flight (submit N+1 before collect N) the CPU never waits for the GPU to finish the
  /// frame it has just submitted. render() is submit() then collect().
  [[nodiscard]] Status submit(const Scene& scene);
  [[nodiscard]] Status collect(SurfaceBuffers& out);

  /// Turns the GPU airlight stage on (or off: `options` empty) for frames submitted from now on.
  /// Fails when `options` are out of range (pieces 1–1024).
  [[nodiscard]] Status setAirlight(const std::optional<GpuAirlightOptions>& options);
  [[nodiscard]] bool airlightEnabled() const noexcept;
  /// render()/collect() that also return the airlight of every lamp of the scene, in cd/m² per
  /// channel (3 floats per pixel, row 0 at the top): needs setAirlight() before the frame's
  /// submit(). `airlight` is resized.
  [[nodiscard]] Status render(const Scene& scene, SurfaceBuffers& out, std::vector<float>& airlight);
  [[nodiscard]] Status collect(SurfaceBuffers& out, std::vector<float>& airlight);

  /// "vendor | renderer | version | EGL platform | shading", e.g. "Mesa | llvmpipe (LLVM 15.0.6, 256
  /// bits) | 4.5 (Core Profile) Mesa 22.3.6 | EGL surfaceless | shading on the CPU".
  [[nodiscard]] std::string description() const;
  [[nodiscard]] const GlSurfaceStats& stats() const noexcept;
  /// Where this pass lights its pixels: Gpu or Cpu (GlOptions::shading, Auto resolved at create()).
  [[nodiscard]] SurfaceShading shading() const noexcept;
  /// The last failure to store the fog light's table or an annulus map in
  /// GlOptions::table_cache_dir (empty: none since the last call); the next run builds it again,
  /// nothing else is lost.
  [[nodiscard]] std::string takeTableCacheError();

  struct Impl;

 private:
  explicit GlSurfacePass(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace fogbeam
