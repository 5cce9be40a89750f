// fogbeam — beyond single scattering (issue 7): the glow of multiple scattering around a lamp
// seen through fog, and the eye's disability glare.
//
// Glow. Narasimhan & Nayar, "Shedding light on the weather", CVPR 2003, give the radiance that a
// point source scatters (all orders, albedo 1, Henyey–Greenstein forward-scattering parameter
// q) towards an eye at optical distance T = K_t R from it, in the direction at angle θ from the
// source, as a Legendre series (the atmospheric point spread function, APSF):
//
//     A(T, μ) = C Σ_{m≥0} (g_m(T) + g_{m+1}(T)) P_m(μ),   μ = cos θ,
//     g_m(T) = exp(−β_m T − α_m ln T),  α_m = m + 1,  β_m = (2m + 1)/m · (1 − q^{m−1}),  g_0 = 0.
//
// The series converges where T > 1 (g_m falls as T^{−m}); below, multiple scattering is weak and
// the series meaningless. C is fixed by energy: with albedo 1 the net scattered flux through
// the sphere of radius R carries the source's power 4π I once the direct beam is gone (T ≫ 1).
// Only the m = 1 term carries net flux (∫ P_m μ dμ = 2/3 δ_m1) and g_1 = T^{−2} (β_1 = 0), so
//     4π R² · 2π · C (g_1 + g_2) · 2/3 → 4π I   gives   C = 3 I K_t² / (4π)   [cd/m² per ...]
// (Apsf::netFluxRatio checks it: 1 + e^{−β_2 T}/T, within 3e-3 of 1 from T = 10 at q = 0.85.)
//
// No double counting. The single-scattering layer is computed exactly (airlight.hpp); the glow
// added to it (render/lamp_effects.hpp, glowCurve) is λ · max(0, A − S₁): the APSF less the
// exact single scattering of the same isotropic source, scaled by λ so that single + glow carry
// the scattered power through the sphere of radius R, I (1 − e^{−T}) (albedo 1). The lamp enters
// as an isotropic source of its mean intensity over a cone about the direction of the eye (exact
// for street lamps, a stand-in for headlamps; docs/airlight.md, "Beyond single scattering").
//
// Disability glare (CIE 146:2002, the general disability glare equation): the veiling luminance
// that scattered light in the eye adds at the fovea, for a glare source at angle θ (degrees,
// 0.1°–100°) from the line of sight giving an illuminance E at the eye,
//     L_v / E = 10/θ³ + (5/θ² + 0.1 p/θ) · (1 + (A/62.5)⁴) + 0.0025 p   [cd/m² per lux],
// A the observer's age (years), p the eye pigmentation (0 very dark … 1 light blue eyes).
//
// Units: metres, radians unless stated, cd, lux, cd/m². Thread-safety: immutable after build.
#pragma once

#include <fogbeam/physics/math.hpp>
#include <fogbeam/physics/medium.hpp>
#include <fogbeam/util/result.hpp>

#include <vector>

namespace fogbeam {

/// The APSF series for one optical distance T and forward-scattering parameter q (header comment).
class Apsf {
 public:
  /// T ≥ minOpticalDistance(), q ∈ [0, 1). The coefficients are summed until they fall below
  /// `tolerance` of their running total (at most `maxTerms`); error when they do not.
  [[nodiscard]] static Result<Apsf> build(double opticalDistance, double q, double tolerance = 1e-9,
                                          int maxTerms = 4000);
  /// Below this T the series is not used (it converges as T^{−m}: 1.1 needs ~200 terms).
  [[nodiscard]] static constexpr double minOpticalDistance() noexcept { return 1.1; }

  /// Σ (g_m + g_{m+1}) P_m(μ) (dimensionless), μ = cos θ.
  [[nodiscard]] double series(double cosTheta) const noexcept;
  /// Radiance [cd/m²] that a source of intensity `intensity_cd` scatters (all orders) towards the
  /// eye at angle θ from it, in fog of extinction `kt` (1/m): 3 I K_t² / (4π) · series.
  [[nodiscard]] double radiance(double cosTheta, double intensity_cd, double kt) const noexcept {
    return 3.0 * intensity_cd * kt * kt / (4.0 * kPi) * series(cosTheta);
  }
  /// Net scattered flux through the sphere of radius R over 4π I: (g_1 + g_2) T² = 1 + e^{−β_2 T}/T.
  [[nodiscard]] double netFluxRatio() const noexcept;
  [[nodiscard]] int terms() const noexcept { return static_cast<int>(coef_.size()); }
  [[nodiscard]] double opticalDistance() const noexcept { return t_; }

 private:
  Apsf() = default;
  double t_ = 0.0, q_ = 0.0;
  std::vector<double> coef_;  // (g_m + g_{m+1}) for m = 0 … terms − 1
};

/// CIE 146:2002 general disability glare equation: veiling luminance per unit illuminance at the
/// eye, (cd/m²)/lux, for a source at `angle_deg` (clamped to [0.1°, 100°]) from the line of sight.
[[nodiscard]] double veilingLuminancePerLux(double angle_deg, double age_years, double pigmentation) noexcept;

}  // namespace fogbeam
