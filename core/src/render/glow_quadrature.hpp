// fogbeam — the glow curve's angles and the rule that integrates over them (internal to
// core/src/render: lamp_effects.cpp and fog_light.cpp share them).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <vector>

namespace fogbeam::glow_quadrature {

// ∫ f(θ) dθ over the nodes θ_i of a glow curve: the trapezoid rule, the first interval [0, θ₁]
// as f(θ₁) θ₁ (f carries L sin θ, which tends to a constant as θ → 0: S₁ ∝ 1/h). f(i) is the
// integrand at node i. Shared by the flux (fluxOver) and the scattered irradiance on a surface.
template <class F>
double integrateFromApex(const std::vector<double>& theta, F&& f) {
  double sum = theta.size() > 1 ? f(std::size_t{1}) * theta[1] : 0.0;
  for (std::size_t i = 2; i < theta.size(); ++i) sum += 0.5 * (f(i - 1) + f(i)) * (theta[i] - theta[i - 1]);
  return sum;
}

// θ_i = 2 asin((i / (n − 1))²) (GlowCurve): dense near the lamp, every angle up to π.
inline double glowNodeAngle(std::size_t i, std::size_t n) {
  const double u = static_cast<double>(i) / static_cast<double>(n - 1);
  return 2.0 * std::asin(std::min(u * u, 1.0));
}

}  // namespace fogbeam::glow_quadrature
