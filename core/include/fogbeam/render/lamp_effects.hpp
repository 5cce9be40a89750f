// fogbeam — glow and glare layers of a frame (issue 7): what single scattering misses around the
// lamps in view. Formulas and their sources: fogbeam/physics/glow.hpp; design and measurements:
// docs/airlight.md, "Beyond single scattering".
//
//  * Glow: per visible lamp, the multiply-scattered radiance around its image, a function of the
//    angle θ from it: the Narasimhan–Nayar APSF for the lamp's optical distance T = K_t R and the
//    fog's mean cosine q, minus the single scattering of the same isotropic source (which the
//    airlight layer already holds), times the albedo, faded in from T = 1.1 to `fade_in` (the
//    series' lower limit: no pop as a car comes closer). The lamp enters with its intensity
//    towards the eye. A lamp hidden behind a surface (distance buffer at its image nearer than
//    it) has no glow; pixels whose surface is nearer than the lamp get less of it (the glow
//    builds up near the lamp): weight clamp((d − R/2) / (R/2), 0, 1).
//  * Glare: per lamp in front of the eye and not hidden, the veiling luminance of the eye's
//    stray light (CIE 146:2002) for each pixel taken as the line of sight:
//    L_v = Σ E_i · f(θ_i), E_i the illuminance at the eye from lamp i's direct (attenuated)
//    light; added to the displayed image as disability glare is seen. The report gives its
//    value at the image centre and each lamp's E.
//
// Both layers are linear cd/m² per channel (lamp colour), 3 floats per pixel, row 0 at the top.
// Thread-safety: one evaluate() at a time per LampEffects.
#pragma once

#include <fogbeam/render/surface.hpp>
#include <fogbeam/scene/scene.hpp>
#include <fogbeam/util/result.hpp>
#include <fogbeam/util/thread_pool.hpp>

#include <memory>
#include <string>
#include <vector>

namespace fogbeam {

struct GlowOptions {
  bool enabled = false;
  double fade_in = 2.0;  ///< optical distance from which the glow counts fully (linear from 1.1)
};

struct GlareOptions {
  bool enabled = false;
  double age_years = 40.0;    ///< observer's age A (CIE 146:2002)
  double pigmentation = 0.5;  ///< eye pigmentation p: 0 very dark … 1 light blue eyes
};

struct LampEffectsReport {
  struct Lamp {
    std::string name;
    bool visible = false;            ///< in front of the eye and not hidden behind a surface
    double distance_m = 0.0;
    double optical_distance = 0.0;   ///< K_t R
    double intensity_cd = 0.0;       ///< towards the eye
    double eye_illuminance_lx = 0.0; ///< direct light at the eye, I e^{−K_t R} / R²
    double glow_peak_cd_m2 = 0.0;    ///< largest glow radiance around its image
    int apsf_terms = 0;              ///< Legendre terms summed (0: no glow)
  };
  std::vector<Lamp> lamps;
  double eye_illuminance_lx = 0.0;        ///< Σ over visible lamps
  double veiling_luminance_cd_m2 = 0.0;   ///< glare at the image centre
  double glow_seconds = 0.0, glare_seconds = 0.0;
};

class LampEffects {
 public:
  /// `threads`: the pool the per-pixel passes run on (shared with the airlight evaluator).
  [[nodiscard]] static Result<LampEffects> build(const Scene& scene, const GlowOptions& glow, const GlareOptions& glare,
                                                 std::shared_ptr<ThreadPool> pool);
  /// Fills `glow` and `glare` (3 floats per pixel; cleared when the effect is off) for the
  /// scene's camera, lamps and fog, with the surface pass's distances.
  void evaluate(const Scene& scene, const SurfaceBuffers& surface, std::vector<float>& glow, std::vector<float>& glare,
                LampEffectsReport& report);
  /// Switches lamp `index` (scene order) on or off for the following frames.
  void setLampEnabled(std::size_t index, bool on);
  [[nodiscard]] bool glowEnabled() const noexcept { return glow_.enabled; }
  [[nodiscard]] bool glareEnabled() const noexcept { return glare_.enabled; }

  struct Tables;  // per-frame tables (private)

 private:
  LampEffects() = default;
  GlowOptions glow_;
  GlareOptions glare_;
  std::shared_ptr<ThreadPool> pool_;
  std::vector<char> enabled_;
  std::shared_ptr<Tables> tables_;
};

}  // namespace fogbeam
