// fogbeam — the surface layer of a frame: what the eye sees of lit surfaces through fog,
// and the distance to them.
//
//   L_s = L(S) e^{−K_t d} + I_a (1 − e^{−K_t d})          [cd/m², per colour channel]
//   L(S) = ρ/π · Σ_lamps colour · I(w) cos(incidence) e^{−K_t r} / r²   (Lambertian)
//
// Two producers fill the same buffers: the GL surface pass (EGL, shaders/ — fogbeam_gl) and
// renderSurfacesCpu(), the analytic "null renderer" for scenes made of planes only, which
// runs without any GL and is the oracle of the GL pass's tests.
// Thread-safety: plain buffers; renderSurfacesCpu is reentrant.
#pragma once

#include <fogbeam/scene/scene.hpp>

#include <vector>

namespace fogbeam {

struct SurfaceBuffers {
  int width = 0, height = 0;
  /// Linear luminance L_s per channel (R, G, B), cd/m²; row 0 is the top of the image.
  std::vector<float> rgb;
  /// Distance along each pixel's ray to the visible surface, metres; +inf for sky.
  std::vector<float> distance;

  void resize(int w, int h);
};

/// Planes only (glTF is ignored): analytic ray–plane intersection and lighting, multi-threaded.
/// Shadows are not computed (the GL pass has none either).
void renderSurfacesCpu(const Scene& scene, SurfaceBuffers& out);

/// L(S) of one surface point for one lamp (white), without view attenuation: illuminance
/// I(w) cos(incidence) e^{−K_t r}/r² times ρ/π. `normal` is unit and faces the viewer.
[[nodiscard]] double lambertianLuminance(const Lamp& lamp, const Medium& fog, const Vec3& point, const Vec3& normal,
                                         double reflectance) noexcept;

}  // namespace fogbeam
