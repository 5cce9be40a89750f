// fogbeam — an upper bound of one lamp's single-scattering airlight over the rays that pass at
// least a given angle from it: which pixels a distant or dim moving lamp can still light.
//
// In the paper's variable (Lecocq et al. 2001, eq. 3) a ray from the eye O whose closest point
// to the lamp S lies at h = D sin γ (D = |S − O|, γ the angle between the ray and the direction
// from O to S) sees the lamp's light as
//
//     L = (K_s / h) ∫_{θ0}^{θd} p(π/2 + θ) I(ω(θ)) e^{−K_t (u(θ) + r(θ))} dθ,   θ0 = γ − π/2,
//
// θ the angle at S between the ray's perpendicular and the point, u and r the point's distances
// to the eye and the lamp, and π/2 + θ the scattering angle there (γ at the eye, growing along
// the ray). With I ≤ I_max, u + r ≥ D (triangle inequality) and the ray running on to θ = π/2,
//
//     L ≤ K_s I_max e^{−K_t D} / (D sin γ) · P(γ),   P(γ) = ∫_γ^π p(α) dα,
//
// for every ray at angle γ or more from the lamp's direction, whatever its length, the
// profile's shape and the fog's phase function. P is the phase function's tail integral in
// the scattering angle (not in solid angle): it falls with γ for every phase, so the bound
// holds in γ's whole range once P/sin γ is made non-increasing (a suffix maximum; it rises
// towards γ = π only for phases that scatter back). The bound is what a lamp contributes at
// most outside a cone about its image: AirlightImageEvaluator leaves a moving lamp out of the
// pixels beyond the cone where the bound falls below its share of a stated luminance, and out
// of the frame when the cone misses the view.
//
// Units: radians, metres, cd, 1/m; bounds in cd/m² (white light).
// Thread-safety: immutable after construction; any number of threads may read one.
#pragma once

#include <fogbeam/physics/medium.hpp>

#include <vector>

namespace fogbeam {

class AirlightBound {
 public:
  /// Tabulates P(γ)/sin γ for `phase` on kIntervals intervals of [0, π] (~1 ms).
  explicit AirlightBound(const Phase& phase);

  static constexpr int kIntervals = 4096;

  /// The factor K_s I_max e^{−K_t D} / D (cd/m² per unit of scale()), for a lamp of peak
  /// intensity `peakCd` at `distance_m` from the eye in fog of extinction `kt` (1/m) and albedo
  /// `albedo`. +inf when distance_m ≤ 0 (the eye at the lamp: no bound).
  [[nodiscard]] static double factor(double peakCd, double distance_m, double kt, double albedo) noexcept;
  /// The bound over rays at angle ≥ gamma (radians) from the lamp's direction, per unit factor:
  /// max over γ' ≥ gamma of P(γ')/sin γ' (1/rad·… dimensionless; +inf at gamma = 0).
  [[nodiscard]] double scale(double gamma) const noexcept;
  /// The smallest tabulated angle γ (radians) beyond which factor · scale(γ) ≤ limit: the half-angle
  /// of the cone outside which the lamp adds at most `limit` cd/m² to any ray. π + 1 when no
  /// such angle exists (the lamp may add more than `limit` somewhere on every side); at least
  /// π / kIntervals (the bound is infinite at the lamp's image).
  [[nodiscard]] double coneHalfAngle(double factor, double limit) const noexcept;

 private:
  // suffix_[k]: the bound of P(γ)/sin γ over γ ∈ [k Δ, π], Δ = π / kIntervals.
  std::vector<double> suffix_;
};

}  // namespace fogbeam
