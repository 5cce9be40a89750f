// fogbeam — homogeneous fog medium and its phase functions.
//
// Conventions (docs/physics.md): extinction K_t in 1/m, single-scattering albedo Ω
// (scattering coefficient = Ω·K_t), phase function p normalised so that
// ∫ p dω = 1 over the sphere, evaluated at cos α where α = 0 is forward scattering.
// All types here are immutable values: safe to share between threads.
#pragma once

#include <fogbeam/util/result.hpp>

#include <string>
#include <tuple>
#include <variant>

namespace fogbeam {

/// Isotropic scattering: p = 1/(4π).
struct IsotropicPhase {};

/// Henyey–Greenstein: p(μ) = (1 − g²) / (4π (1 + g² − 2gμ)^{3/2}), g ∈ (−1, 1).
struct HenyeyGreensteinPhase {
  double g = 0.0;
};

/// "fog-mie": Jendersie & d'Eon (SIGGRAPH 2023 talk) blend (1 − w)·HG(g_HG) + w·Draine(α, g_D),
/// fitted to Mie scattering by water droplets of diameter d ∈ [5, 50] µm.
/// The derived parameters are computed once by makeFogMie().
struct FogMiePhase {
  double diameter_um = 10.0;
  double g_hg = 0.0;     ///< HG lobe asymmetry
  double g_d = 0.0;      ///< Draine lobe asymmetry
  double alpha = 0.0;    ///< Draine α
  double w = 0.0;        ///< blend weight of the Draine lobe
};

using Phase = std::variant<IsotropicPhase, HenyeyGreensteinPhase, FogMiePhase>;

/// Builds a fog-mie phase for droplet diameter `diameter_um` (µm), valid in [5, 50].
[[nodiscard]] Result<Phase> makeFogMie(double diameter_um);
/// Builds an HG phase; g must lie in (−1, 1).
[[nodiscard]] Result<Phase> makeHenyeyGreenstein(double g);

/// What identifies a phase function as a key of table caches: its kind (the variant's index),
/// then HG g or the fog-mie diameter (µm), then fog-mie's derived g_hg and g_d (0 otherwise).
using PhaseIdentity = std::tuple<std::size_t, double, double, double>;
[[nodiscard]] PhaseIdentity phaseIdentity(const Phase& phase) noexcept;

/// p(cos α) in 1/sr; cosAlpha ∈ [−1, 1] with +1 forward.
[[nodiscard]] double evalPhase(const Phase& phase, double cosAlpha) noexcept;
/// Mean cosine ⟨cos α⟩ of the phase function (its "g"), for reports.
[[nodiscard]] double meanCosine(const Phase& phase) noexcept;
/// Short name: "isotropic", "henyey-greenstein(g=0.85)", "fog-mie(d=10um)".
[[nodiscard]] std::string describe(const Phase& phase);

/// Henyey–Greenstein alone, exposed for the Draine lobe and tests.
[[nodiscard]] double henyeyGreenstein(double g, double cosAlpha) noexcept;
/// Draine(α, g)(μ) = HG(g)(μ) · (1 + α μ²) / (1 + α (1 + 2 g²)/3), normalised to 1.
[[nodiscard]] double draine(double alpha, double g, double cosAlpha) noexcept;

/// Converts a meteorological optical range V (m, 5 % contrast, CIE/WMO/ASAM OSI)
/// to the extinction coefficient K_t = ln(20)/V in 1/m.
[[nodiscard]] double extinctionFromVisibility(double visibility_m) noexcept;
/// Inverse of extinctionFromVisibility.
[[nodiscard]] double visibilityFromExtinction(double extinction_per_m) noexcept;

/// A homogeneous fog.
struct Medium {
  double extinction_per_m = 0.0;  ///< K_t [1/m], > 0
  double albedo = 1.0;            ///< Ω ∈ [0, 1]
  Phase phase = IsotropicPhase{};
  double ambient_cd_m2 = 0.0;     ///< I_a: ambient fog luminance [cd/m²], ≥ 0

  /// Checks ranges; the message names the offending field.
  [[nodiscard]] Status validate() const;
};

}  // namespace fogbeam
