// fogbeam — brute-force ray marching of the airlight integral: the baseline the paper's
// method is measured against in `fogbeam bench`.
//
//   L_m = ∫_0^{u_end} e^{−K_t u} Ω K_t p(cos α(u)) I(w(u)) e^{−K_t r(u)} / r(u)² du      [cd/m²]
//
// in the original variable u along the ray (docs/physics.md), by the midpoint rule with a
// fixed number of steps N over [0, u_end], u_end = min(d, u_max). u_max = ln(1e4)/K_t is
// where the view transmittance e^{−K_t u} falls below 1e-4; beyond it the integrand is
// neglected (this also bounds sky rays, d = ∞). No change of variables, no adaptivity, no
// tables: each step evaluates the phase function and the lamp's profile once. Its error
// falls as O(1/N²) once the steps resolve the lamp's 1/r² peak and the profile's cut-offs,
// which for a lamp close to the ray takes thousands of steps.
//
// Thread-safety: immutable after build(); evaluate()/evaluateRay() from any number of threads.
#pragma once

#include <fogbeam/physics/airlight.hpp>
#include <fogbeam/scene/scene.hpp>
#include <fogbeam/util/result.hpp>

#include <vector>

namespace fogbeam {

/// View transmittance below which the ray marcher stops (u_max = −ln(this)/K_t).
inline constexpr double kRayMarchMinTransmittance = 1e-4;

/// L_m of one lamp (white light, cd/m²) by the midpoint rule with `steps` ≥ 1 steps.
/// `ray.direction` must be unit length; `ray.distance_m` ≥ 0 or +inf.
[[nodiscard]] double rayMarchAirlight(const Lamp& lamp, const Medium& medium, const Ray& ray, int steps) noexcept;

/// The ray marcher over all lamps of a scene: the same "sum over lamps × colour" as
/// AirlightImageEvaluator::evaluateRay.
class RayMarchEvaluator {
 public:
  /// Errors: invalid medium, a lamp without profile, steps < 1.
  [[nodiscard]] static Result<RayMarchEvaluator> build(const Scene& scene, int steps);

  /// Sum over lamps of colour × L_m for one ray (cd/m² per channel).
  void evaluateRay(const Ray& ray, float rgb[3]) const noexcept;

  [[nodiscard]] int steps() const noexcept { return steps_; }

 private:
  RayMarchEvaluator() = default;
  std::vector<Lamp> lamps_;
  Medium medium_;
  int steps_ = 1;
};

}  // namespace fogbeam
