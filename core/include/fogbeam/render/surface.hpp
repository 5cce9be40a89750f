// fogbeam — the surface layer of a frame: what the eye sees of lit surfaces through fog,
// and the distance to them.
//
//   L_s = L(S) e^{−K_t d} + I_a (1 − e^{−K_t d})          [cd/m², per colour channel]
//   L(S) = ρ/π · Σ_lamps colour · I(w) cos(incidence) e^{−K_t r} / r²   (Lambertian)
//
// Two producers fill the same buffers: the GL surface pass (EGL, shaders/ — fogbeam_gl) and
// renderSurfacesCpu(), the analytic "null renderer" for scenes made of planes only, which
// runs without any GL and is the oracle of the GL pass's tests.
// Thread-safety: plain buffers; renderSurfacesCpu is reentrant (calls that share a pool must
// not overlap: ThreadPool's own rule).
#pragma once

#include <fogbeam/scene/scene.hpp>

#include <vector>

namespace fogbeam {

class ThreadPool;

struct SurfaceBuffers {
  int width = 0, height = 0;
  /// Linear luminance L_s per channel (R, G, B), cd/m²; row 0 is the top of the image.
  std::vector<float> rgb;
  /// Distance along each pixel's ray to the visible surface, metres; +inf for sky.
  std::vector<float> distance;

  void resize(int w, int h);
};

/// Planes and the body quads (the bonnet; glTF is ignored): analytic ray–plane and ray–quad
/// intersection (double) and lighting
/// (lambertianLuminance's equation, double; stored as float). Shadows are not computed (the GL
/// pass has none either). Fills `out` at the camera's size (its buffers are kept when the size
/// is unchanged). `pool`: the rows are spread over its threads, and the call does not allocate
/// with up to 64 planes and 64 lamps; null: threads are started for the call (one per core).
/// The lamps' geometry and attenuation run as SIMD batches of hit pixels; the result is
/// bit-identical to the one-pixel-at-a-time definition (surface.cpp explains why;
/// tests/render/test_surface_cpu.cpp checks it on every SIMD target) and independent of `pool`.
/// Cost on the bench scene (docs/surface_pass.md, "The CPU planes renderer").
void renderSurfacesCpu(const Scene& scene, SurfaceBuffers& out, ThreadPool* pool = nullptr);

/// L(S) of one surface point for one lamp (white), without view attenuation: illuminance
/// I(w) cos(incidence) e^{−K_t r}/r² times ρ/π. `normal` is unit and faces the viewer.
[[nodiscard]] double lambertianLuminance(const Lamp& lamp, const Medium& fog, const Vec3& point, const Vec3& normal,
                                         double reflectance) noexcept;

}  // namespace fogbeam
