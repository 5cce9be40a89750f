#include <fogbeam/render/raymarch.hpp>

#include <algorithm>
#include <cmath>
#include <string>

namespace fogbeam {

double rayMarchAirlight(const Lamp& lamp, const Medium& medium, const Ray& ray, int steps) noexcept {
  const double sigma_t = medium.extinction_per_m;
  if (steps < 1 || !(sigma_t > 0.0) || !lamp.profile) return 0.0;
  const double uMax = -std::log(kRayMarchMinTransmittance) / sigma_t;
  const double uEnd = std::min(ray.distance_m, uMax);
  if (!(uEnd > 0.0)) return 0.0;
  const Mat3 lampFromWorld = glm::transpose(lamp.worldFromLamp);
  const double du = uEnd / steps;
  double sum = 0.0;
  for (int s = 0; s < steps; ++s) {
    const double u = (s + 0.5) * du;
    const Vec3 x = ray.origin + u * ray.direction;
    const Vec3 toX = x - lamp.position_m;
    const double r2 = glm::dot(toX, toX);
    if (!(r2 > 0.0)) continue;  // the sample sits on the lamp: the integrand is singular there
    const double r = std::sqrt(r2);
    const Vec3 w = toX / r;                        // world direction of the light leaving the lamp
    const double cosAlpha = -glm::dot(w, ray.direction);
    const double intensity = lamp.profile->intensity(lampFromWorld * w);
    if (intensity <= 0.0) continue;
    sum += std::exp(-sigma_t * (u + r)) * evalPhase(medium.phase, cosAlpha) * intensity / r2;
  }
  return medium.albedo * sigma_t * sum * du;
}

Result<RayMarchEvaluator> RayMarchEvaluator::build(const Scene& scene, int steps) {
  if (steps < 1) return Error{"ray marcher: step count must be ≥ 1, got " + std::to_string(steps)};
  if (Status s = scene.fog.validate(); !s) return Error{s.error().message};
  RayMarchEvaluator e;
  e.medium_ = scene.fog;
  e.steps_ = steps;
  for (const SceneLamp& sl : scene.lamps) {
    if (!sl.lamp.profile) return Error{sl.name + ": lamp has no profile"};
    e.lamps_.push_back(sl.lamp);
  }
  return e;
}

void RayMarchEvaluator::evaluateRay(const Ray& ray, float rgb[3]) const noexcept {
  double acc[3] = {0.0, 0.0, 0.0};
  for (const Lamp& lamp : lamps_) {
    const double l = rayMarchAirlight(lamp, medium_, ray, steps_);
    for (int c = 0; c < 3; ++c) acc[c] += l * lamp.color[c];
  }
  for (int c = 0; c < 3; ++c) rgb[c] = static_cast<float>(acc[c]);
}

}  // namespace fogbeam
