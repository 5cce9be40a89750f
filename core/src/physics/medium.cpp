#include <fogbeam/physics/medium.hpp>
#include <fogbeam/physics/math.hpp>
#include <fogbeam/util/overloaded.hpp>

#include <cmath>
#include <cstdio>
#include <type_traits>

namespace fogbeam {


double henyeyGreenstein(double g, double cosAlpha) noexcept {
  const double denom = 1.0 + g * g - 2.0 * g * cosAlpha;
  return kInvFourPi * (1.0 - g * g) / (denom * std::sqrt(denom));
}

double draine(double alpha, double g, double cosAlpha) noexcept {
  // Draine 2003, eq. (4); the denominator normalises the (1 + α μ²) factor against HG's
  // second moment ⟨μ²⟩ = (1 + 2g²)/3.
  return henyeyGreenstein(g, cosAlpha) * (1.0 + alpha * cosAlpha * cosAlpha) /
         (1.0 + alpha * (1.0 + 2.0 * g * g) / 3.0);
}

Result<Phase> makeHenyeyGreenstein(double g) {
  if (!std::isfinite(g) || g <= -1.0 || g >= 1.0) {
    return Error{"henyey-greenstein: g = " + std::to_string(g) + " is outside (-1, 1)"};
  }
  return Phase{HenyeyGreensteinPhase{g}};
}

Result<Phase> makeFogMie(double d) {
  if (!std::isfinite(d) || d < 5.0 || d > 50.0) {
    return Error{"fog-mie: droplet_diameter_um = " + std::to_string(d) +
                 " is outside the fitted range [5, 50] um"};
  }
  // Jendersie & d'Eon 2023, "An Approximate Mie Scattering Function for Fog and Cloud
  // Rendering", fit for 5 µm ≤ d ≤ 50 µm (d in µm).
  FogMiePhase f;
  f.diameter_um = d;
  f.g_hg = std::exp(-0.0990567 / (d - 1.67154));
  f.g_d = std::exp(-2.20679 / (d + 3.91029) - 0.428934);
  f.alpha = std::exp(3.62489 - 8.29288 / (d + 5.52825));
  f.w = std::exp(-0.599085 / (d - 0.641583) - 0.665888);
  return Phase{f};
}

PhaseIdentity phaseIdentity(const Phase& phase) noexcept {
  double a = 0.0, b = 0.0, c = 0.0;
  if (const auto* hg = std::get_if<HenyeyGreensteinPhase>(&phase)) a = hg->g;
  if (const auto* fm = std::get_if<FogMiePhase>(&phase)) {
    a = fm->diameter_um;
    b = fm->g_hg;
    c = fm->g_d;
  }
  return {phase.index(), a, b, c};
}

double evalPhase(const Phase& phase, double cosAlpha) noexcept {
  return std::visit(
      Overloaded{
          [](const IsotropicPhase&) { return kInvFourPi; },
          [&](const HenyeyGreensteinPhase& p) { return henyeyGreenstein(p.g, cosAlpha); },
          [&](const FogMiePhase& p) {
            return (1.0 - p.w) * henyeyGreenstein(p.g_hg, cosAlpha) +
                   p.w * draine(p.alpha, p.g_d, cosAlpha);
          },
      },
      phase);
}

double meanCosine(const Phase& phase) noexcept {
  return std::visit(
      Overloaded{
          [](const IsotropicPhase&) { return 0.0; },
          [](const HenyeyGreensteinPhase& p) { return p.g; },
          [](const FogMiePhase& p) {
            // Draine's mean cosine: g (1 + α (3 + 2g²)/5) / (1 + α (1 + 2g²)/3).
            const double gd = p.g_d;
            const double draineMean = gd * (1.0 + p.alpha * (3.0 + 2.0 * gd * gd) / 5.0) /
                                      (1.0 + p.alpha * (1.0 + 2.0 * gd * gd) / 3.0);
            return (1.0 - p.w) * p.g_hg + p.w * draineMean;
          },
      },
      phase);
}

std::string describe(const Phase& phase) {
  char buf[96];
  std::visit(Overloaded{
                 [&](const IsotropicPhase&) { std::snprintf(buf, sizeof buf, "isotropic"); },
                 [&](const HenyeyGreensteinPhase& p) {
                   std::snprintf(buf, sizeof buf, "henyey-greenstein(g=%g)", p.g);
                 },
                 [&](const FogMiePhase& p) {
                   std::snprintf(buf, sizeof buf, "fog-mie(d=%gum, <cos>=%.3f)", p.diameter_um,
                                 meanCosine(Phase{p}));
                 },
             },
             phase);
  return buf;
}

double extinctionFromVisibility(double visibility_m) noexcept {
  return std::log(20.0) / visibility_m;  // MOR: 5 % contrast threshold
}
double visibilityFromExtinction(double extinction_per_m) noexcept {
  return std::log(20.0) / extinction_per_m;
}

Status Medium::validate() const {
  if (!std::isfinite(extinction_per_m) || extinction_per_m <= 0.0) {
    return Error{"fog: extinction_per_m must be a finite number > 0, got " + std::to_string(extinction_per_m)};
  }
  if (!std::isfinite(albedo) || albedo < 0.0 || albedo > 1.0) {
    return Error{"fog: albedo must lie in [0, 1], got " + std::to_string(albedo)};
  }
  if (!std::isfinite(ambient_cd_m2) || ambient_cd_m2 < 0.0) {
    return Error{"fog: ambient_cd_m2 must be a finite number >= 0, got " + std::to_string(ambient_cd_m2)};
  }
  if (const auto* hg = std::get_if<HenyeyGreensteinPhase>(&phase)) {
    if (!(hg->g > -1.0 && hg->g < 1.0)) return Error{"fog: g must lie in (-1, 1), got " + std::to_string(hg->g)};
  }
  return Ok{};
}

}  // namespace fogbeam
