// fogbeam — what a Lambertian ground under the lamps and the eye does to the multiply scattered
// light of the multiple-scattering tables (issue 18; docs/physics.md, "The ground").
//
// The tables (multiple_scattering.hpp) hold the light of orders ≥ 2 around an isotropic lamp in
// *infinite* fog. A road under the eye and the lamp changes it: light that would have scattered
// in the fog below the road is absorbed (1 − ρ of it) or sent back up diffusely (ρ). Close to the
// lamp's image, at small optical distances, little changes (the light there has turned a few
// degrees at most); far from the lamp in thick fog, where the light has diffused, a dark road
// removes most of it (measured: a lamp at K_t R = 8, HG g = 0.75, a road of ρ = 0.1 1.2 m below
// K_t = 0.06 /m: the path tracer's light over the same pixels is 0.22–0.35 of infinite fog's) and
// snow adds to it.
//
// What is tabulated: per phase function, the factor
//
//     C(T, θ, ρ) = ⟨L_ms with the ground⟩ / ⟨glow of the tables, as the glow layer draws it⟩
//
// over rings θ ∈ [θ_lo, θ_hi) about the lamp's direction, T = K_t R, ρ the ground's Lambertian
// reflectance; the numerator from fogbeam's path tracer (orders 2 … max_order, the ground a
// scattering event like the fog's), the denominator the tables' f(T, θ) times the glow layer's
// occlusion weight for rays that end on the ground (glowOcclusionWeight), both over the same
// rays, uniform in solid angle within the ring. The glow layer multiplies its curve by C
// (interpolated: linear in ρ, in log T, and in log θ between the rings' centres √(θ_lo θ_hi);
// held beyond the first and last node of each), through a cubic in log θ fitted over the rings
// per (ρ, T) by weighted least squares (the path tracer's nodes are noisy and heavy-tailed).
//
// What it assumes (each checked against the path tracer in `fogbeam validate --path-tracer`,
// docs/airlight.md "The ground"): a flat ground; the eye and the lamp at the same optical height
// H = K_t h above it, tabulated at H = 0.03, 0.09, 0.27 (a car's eye and lamps are 0.02–0.12
// optical depths above the road in fog, a street lamp's head 0.2–0.8; where they differ, the
// glow takes their mean height); the ring mean for every pixel of the ring (above and below the
// lamp alike, as the tables' emission shares); albedo 1 (the factor is applied at every albedo);
// an isotropic lamp (measured lamps take the factor of their optical distance as their glow
// takes the tables').
//
// Thread-safety: a built or parsed table is immutable; const members may be called from any
// number of threads. build() runs on `pool` (one build per pool at a time, as ThreadPool requires).
#pragma once

#include <fogbeam/physics/medium.hpp>
#include <fogbeam/util/result.hpp>

#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

namespace fogbeam {

class MultipleScatteringTable;
class ThreadPool;

/// The glow layer's occlusion weight for a pixel whose surface is `d` metres away and a lamp `R`
/// metres away: a lamp's multiply scattered light along a view ray gathers about the lamp, so
/// surfaces nearer than R/2 see none of it and surfaces beyond R all of it (lamp_effects.hpp).
[[nodiscard]] inline double glowOcclusionWeight(double d, double R) noexcept {
  const double from = 0.5 * R;
  return d <= from ? 0.0 : d >= R ? 1.0 : (d - from) / (R - from);
}

struct GroundCorrectionOptions {
  std::vector<double> optical_distances;  ///< T nodes, ascending, > 0
  std::vector<double> ring_edges_deg;     ///< ring edges, ascending, in (0, 180]: rings between neighbours
  std::vector<double> reflectances;       ///< ρ nodes, ascending, in [0, 1)
  std::vector<double> heights_optical;    ///< H = K_t h of the eye and the lamp above the ground, ascending, > 0
  std::uint64_t paths = 30000;            ///< path-tracer paths per (T, ρ, ring), ≥ 2
  std::uint64_t seed = 1;
  /// The tables' denominator over each ring: strata in cos θ × azimuth (deterministic).
  int quadrature = 96;
  /// Defaults: T 0.5 … 16 by ×2, rings 0.25–0.5–1–…–128–180°, ρ 0, 0.1, 0.3, 0.8, H 0.03, 0.09, 0.27.
  [[nodiscard]] static GroundCorrectionOptions defaults();
};

class GroundCorrectionTable {
 public:
  /// Estimates C for `phase` against `ms` (the infinite-fog table of the same phase function).
  /// `progress` (may be empty) is called after each (ρ, T) with a line to print.
  [[nodiscard]] static Result<GroundCorrectionTable> build(const Phase& phase, const MultipleScatteringTable& ms,
                                                           const GroundCorrectionOptions& options, ThreadPool* pool,
                                                           const std::function<void(const std::string&)>& progress = {});
  [[nodiscard]] static Result<GroundCorrectionTable> load(const std::filesystem::path& path);
  /// Errors name `source`, the line and what was expected.
  [[nodiscard]] static Result<GroundCorrectionTable> parse(std::string_view text, const std::string& source);
  [[nodiscard]] Status save(const std::filesystem::path& path) const;
  /// (1 − w) a + w b node by node (HG g between two shipped tables); the nodes must match.
  [[nodiscard]] static Result<GroundCorrectionTable> blend(const GroundCorrectionTable& a, const GroundCorrectionTable& b,
                                                           double w, const Phase& phase);

  /// C(T, θ, ρ, H) (header comment): θ in radians, ρ in [0, 1], H = K_t h the optical height of the
  /// eye and the lamp over the ground (their mean where they differ). ≥ 0. Applied from T = kFullFrom,
  /// faded in linearly in log T from 1 at kFadeFrom: a lamp nearer than ~14 heights over the road
  /// (H/T > 0.07) sees the ground, and the patch its light makes there, at angles that depend on
  /// its own height, which the table's single height does not follow (at T = 0.125 the table's
  /// lamp lights the road 30° below itself: rings 16–128° gain ×1.5–2.4 with ρ = 0.1, ×6–14 with
  /// ρ = 0.8); there the glow stays infinite fog's.
  [[nodiscard]] double factor(double opticalDistance, double theta, double reflectance,
                              double heightOptical) const noexcept;
  static constexpr double kFadeFrom = 0.5, kFullFrom = 1.0;
  /// factor() at n angles theta[k] (radians; fastest ascending) for one (T, ρ, H), into out[k]:
  /// the same values (the rings' centres once, then linear in log θ).
  void factors(double opticalDistance, double reflectance, double heightOptical, const double* theta, std::size_t n,
               double* out) const noexcept;

  [[nodiscard]] const Phase& phase() const noexcept { return phase_; }
  [[nodiscard]] const std::vector<double>& opticalDistances() const noexcept { return t_; }
  [[nodiscard]] const std::vector<double>& ringEdges() const noexcept { return edges_; }  ///< radians
  [[nodiscard]] const std::vector<double>& reflectances() const noexcept { return rho_; }
  [[nodiscard]] const std::vector<double>& heightsOptical() const noexcept { return h_; }
  [[nodiscard]] std::uint64_t paths() const noexcept { return paths_; }
  /// Node (H index × reflectances().size() + ρ index, T index, ring index): the factor and its
  /// standard error (the path tracer's),
  /// and the value the glow reads there (a weighted cubic in log θ over the rings: smooth()).
  [[nodiscard]] double node(std::size_t r, std::size_t i, std::size_t j) const noexcept { return c_[index(r, i, j)]; }
  [[nodiscard]] double nodeStdError(std::size_t r, std::size_t i, std::size_t j) const noexcept {
    return se_[index(r, i, j)];
  }
  [[nodiscard]] double nodeFitted(std::size_t r, std::size_t i, std::size_t j) const noexcept {
    return fit_[index(r, i, j)];
  }

 private:
  GroundCorrectionTable() = default;
  [[nodiscard]] std::size_t index(std::size_t r, std::size_t i, std::size_t j) const noexcept {
    return (r * t_.size() + i) * (edges_.size() - 1) + j;
  }
  [[nodiscard]] double atRho(std::size_t r, double logT, double logTheta) const noexcept;
  void smooth();  // fit_ from c_ and se_ (ground_correction.cpp)
  Phase phase_;
  std::vector<double> t_, edges_, rho_, h_, logH_, centresLog_;
  std::vector<double> c_, se_, fit_;
  std::uint64_t paths_ = 0, seed_ = 0;
};

/// The ground correction shipped with fogbeam for `phase` (config/multiple_scattering/*.gnd,
/// embedded in the library; HG g between two shipped ones blended linearly in g), or nullptr.
/// Parsed once, shared; thread-safe.
[[nodiscard]] std::shared_ptr<const GroundCorrectionTable> shippedGroundCorrection(const Phase& phase);

}  // namespace fogbeam
