// fogbeam — the multiply scattered light around an isotropic point lamp in homogeneous fog, as a
// table over (optical distance, angle from the lamp, albedo), estimated once per phase function
// by the same physics as the all-orders path tracer (issue 18; docs/physics.md, "Multiple
// scattering tables").
//
// What is tabulated. An isotropic lamp of intensity I [cd] at distance R [m] from the eye, in an
// infinite homogeneous fog of extinction K_t [1/m], albedo Ω and phase function p. The radiance
// [cd/m²] that reaches the eye along a sky ray at angle θ from the lamp's direction, carried by
// light scattered n ≥ 2 times, is by dimensional analysis (lengths scale with 1/K_t, radiance
// with I/length²)
//
//     L_ms(R, θ) = I K_t² f(T, θ; Ω, p),   T = K_t R,
//
// and f is what the table holds (dimensionless), on nodes T_i × θ_j × Ω_a. Order 1 is left out:
// the airlight layer computes it exactly. Orders above `max_order` are left out as the path
// tracer's `all` leaves them (its `remainder`); they matter only for Ω = 1 far from the lamp.
//
// How it is estimated (reciprocity turns one path into every table entry). Put the eye at the
// origin looking along +z with K_t = 1 (lengths in optical depths) and one unit lamp at every node
// (T_i, θ_j): S = T_i (sin θ_j, 0, cos θ_j). A backward path starts on the camera ray, scatters at
// free-flight distances and turns by the phase function; the segment that leaves its n-th
// scattering vertex x along ω carries order n + 1 from every lamp, and its expected value given
// the path is the single-scattering integral of that lamp along the whole ray (x, ω):
// e^{−p}/h · [T_0(h, π/2) − T_0(h, θ0)] with the accurate method's cumulative G moments (eq. 3 of
// docs/physics.md, p and h the lamp's position along and distance from the ray). So each vertex
// adds a deterministic value to every lamp's entry, and the albedo enters as the weight Ω^{n+1},
// tallied for every Ω node in the same paths. Paths end by Russian roulette on the distance from
// the lamps (unbiased) or at `max_order`.
//
// Thread-safety: a built or loaded table is immutable; all const members may be called from any
// number of threads. build() runs on `pool` (one build per pool at a time, as ThreadPool requires).
#pragma once

#include <fogbeam/physics/medium.hpp>
#include <fogbeam/util/result.hpp>

#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

namespace fogbeam {

class ThreadPool;

struct MultipleScatteringOptions {
  /// T = K_t R nodes, ascending, > 0 (default: 1/32, 1/16, 1/8, then 0.25 … 16 at √2).
  std::vector<double> optical_distances;
  /// θ nodes in radians, ascending in (0, π] (default: 0.1°, 0.2°, 0.35°, 0.5° … 22.6° at √2, then to 180°).
  std::vector<double> angles_rad;
  /// Ω nodes, ascending in (0, 1] (default: 0.7, 0.8, 0.85, 0.9, 0.94, 0.97, 0.99, 1).
  std::vector<double> albedos;
  /// Emission bins: edges of the angle η at the lamp between the direction a node's light left it
  /// and the direction to the eye, degrees, ascending from 0 to 180 (default 0, 3, 8, 15, 30, 60,
  /// 100, 140, 160, 170, 176, 180: narrow at both ends, where a headlamp seen head-on or from
  /// behind puts its beam). Each node then also holds the share of its light per bin (at the largest
  /// albedo node), which makes the table usable for measured lamps (effectiveIntensity). Empty:
  /// isotropic lamps only.
  std::vector<double> emission_edges_deg;
  std::uint64_t paths = 80000;
  std::uint64_t seed = 1;
  /// Largest scattering order counted (as PathTracerOptions::max_order).
  int max_order = 1000;
  /// Paths per work item; part of what fixes the summation order (results are bit-identical for
  /// any pool size with the same batch size).
  std::uint32_t batch_size = 64;
  /// The defaults above, filled in.
  [[nodiscard]] static MultipleScatteringOptions defaults();
};

class MultipleScatteringTable {
 public:
  /// Estimates the table for `phase` (header comment). Errors: nodes empty, unsorted or out of
  /// range; paths < 2 (the standard error needs two); max_order < 2.
  [[nodiscard]] static Result<MultipleScatteringTable> build(const Phase& phase, const MultipleScatteringOptions& options,
                                                             ThreadPool* pool = nullptr);
  /// Reads a table written by save(). Errors name the file, the line and what was expected.
  [[nodiscard]] static Result<MultipleScatteringTable> load(const std::filesystem::path& path);
  /// The same from text; `source` names it in errors (a file name).
  [[nodiscard]] static Result<MultipleScatteringTable> parse(std::string_view text, const std::string& source);
  /// (1 − w) a + w b node by node, for the phase `phase` (a table between two estimated ones, e.g.
  /// an HG g between two shipped g). Errors when the nodes differ.
  [[nodiscard]] static Result<MultipleScatteringTable> blend(const MultipleScatteringTable& a,
                                                             const MultipleScatteringTable& b, double w,
                                                             const Phase& phase);
  /// Writes the table as text (header lines, then one line per node: mean and standard error).
  [[nodiscard]] Status save(const std::filesystem::path& path) const;

  /// f(T, θ, Ω) (header comment), interpolated: linear in log f over log T, log θ and Ω between
  /// nodes. θ below the first node takes the first node's value (the lamp's image: single
  /// scattering and the direct light dominate there); T below the first node, above the last
  /// node, Ω outside the nodes: clamped to the nearest node (below the first T node f still grows
  /// slowly as T falls: held, it is 0–15 % low at T ≥ 0.1 with the shipped tables, up to 40 % at
  /// T = 0.05 and θ = 90°). θ in radians.
  [[nodiscard]] double value(double opticalDistance, double theta, double albedo) const noexcept;
  /// Whether the table holds emission fractions (MultipleScatteringOptions::emission_edges_deg).
  [[nodiscard]] bool hasEmissionBins() const noexcept { return !fractions_.empty(); }
  /// Bin edges in radians (empty without bins).
  [[nodiscard]] const std::vector<double>& emissionEdges() const noexcept { return edges_; }
  /// The shares of the light of orders ≥ 2 reaching the eye at (T, θ) that left the lamp in each
  /// emission bin (sum 1; bilinear in log T, log θ between nodes, clamped at the ends), written to
  /// out[0 … bins). For a measured lamp of intensity I(u), the light is then
  ///     L_ms = K_t² f(T, θ, Ω) Σ_k share_k Ī_k,
  /// Ī_k the mean of I over the annulus of bin k about the lamp's direction to the eye: exact for
  /// the mean over every ring of pixels at θ about the lamp's image (the azimuthal mean over the
  /// ring sees only the azimuthal mean of I), a ring-symmetric stand-in pixel by pixel. The shares
  /// are those of the largest albedo node (for Ω < 1 the low orders, emitted closer to the eye's
  /// direction, weigh a little more). No-op without bins.
  void emissionShares(double opticalDistance, double theta, double* out) const noexcept;
  /// Whether the table holds the emission's first azimuthal harmonic (tables built since
  /// 2026-11-27; older files have none).
  [[nodiscard]] bool hasEmissionHarmonics() const noexcept { return !harmonics_.empty(); }
  /// The first azimuthal harmonic of where the light of each bin left the lamp, as a share of all
  /// the light of orders ≥ 2 at (T, θ): h_k = ⟨share of bin k × cos Δφ⟩, Δφ the azimuth about
  /// the lamp–eye line of the direction the light left the lamp in, from the azimuth of the eye's
  /// ray (the side of the line the ray's scatterers lie on). |h_k| ≤ share_k; 0 for light that
  /// forgot which side it left on, share_k for order 1 (which leaves towards the ray). For a
  /// lamp whose intensity on annulus k is Ī_k + Ī₁_k · ê (ê the unit azimuth vector about the
  /// lamp's direction to the eye, Ī₁_k = 2 ⟨I ê⟩ over the annulus),
  ///     L_ms = K_t² f(T, θ, Ω) Σ_k (share_k Ī_k + h_k Ī₁_k · ω̂⊥),
  /// ω̂⊥ the unit part of the eye's ray ⊥ to the line. Bilinear in log T, log θ between nodes,
  /// clamped at the ends; at the largest albedo node, as the shares. No-op without harmonics.
  void emissionHarmonics(double opticalDistance, double theta, double* out) const noexcept;
  /// L_ms in cd/m² for a lamp of `intensity_cd` at `distance_m` in fog of extinction `kt` (1/m).
  [[nodiscard]] double radiance(double intensity_cd, double kt, double distance_m, double theta,
                                double albedo) const noexcept {
    return intensity_cd * kt * kt * value(kt * distance_m, theta, albedo);
  }

  /// Node values: index (a, i, j) = (albedo, T, θ) → (a · nT + i) · nθ + j.
  [[nodiscard]] double nodeMean(std::size_t a, std::size_t i, std::size_t j) const noexcept { return mean_[index(a, i, j)]; }
  [[nodiscard]] double nodeStdError(std::size_t a, std::size_t i, std::size_t j) const noexcept {
    return stderr_[index(a, i, j)];
  }
  [[nodiscard]] const std::vector<double>& opticalDistances() const noexcept { return t_; }
  [[nodiscard]] const std::vector<double>& angles() const noexcept { return theta_; }
  [[nodiscard]] const std::vector<double>& albedos() const noexcept { return albedo_; }
  [[nodiscard]] const Phase& phase() const noexcept { return phase_; }
  [[nodiscard]] std::uint64_t paths() const noexcept { return paths_; }
  [[nodiscard]] int maxOrder() const noexcept { return maxOrder_; }
  [[nodiscard]] double meanEvents() const noexcept { return meanEvents_; }
  [[nodiscard]] double buildSeconds() const noexcept { return buildSeconds_; }

 private:
  MultipleScatteringTable() = default;
  [[nodiscard]] std::size_t index(std::size_t a, std::size_t i, std::size_t j) const noexcept {
    return (a * t_.size() + i) * theta_.size() + j;
  }
  [[nodiscard]] double valueAtAlbedo(std::size_t a, double T, double theta) const noexcept;
  // A per-(T, θ, bin) array at (T, θ): bilinear in log T, log θ, clamped at the ends.
  void binsAt(const std::vector<double>& perBin, double opticalDistance, double theta, double* out) const noexcept;
  Phase phase_;
  std::vector<double> t_, theta_, albedo_;
  std::vector<double> mean_, stderr_;
  std::vector<double> logT_, logTheta_;
  std::vector<double> edges_;      // emission bin edges, radians
  std::vector<double> fractions_;  // (T, θ, bin) shares at the largest albedo
  std::vector<double> harmonics_;  // (T, θ, bin) first azimuthal harmonics, same albedo (may be empty)
  std::uint64_t paths_ = 0;
  std::uint64_t seed_ = 0;
  int maxOrder_ = 0;
  double meanEvents_ = 0.0;
  double buildSeconds_ = 0.0;
};

/// "hg-0.850", "fog-mie-10.0um", "isotropic": the file stem of a phase function's table.
[[nodiscard]] std::string multipleScatteringTableName(const Phase& phase);

/// The table shipped with fogbeam for `phase` (config/multiple_scattering/, embedded in the
/// library): an HG g between two shipped ones is blended linearly in g from its neighbours (0.75,
/// 0.80, 0.85, 0.90); fog-mie at a shipped droplet diameter (10 µm). nullptr for any other phase
/// (build one with MultipleScatteringTable::build or `fogbeam tables`). Parsed once, shared;
/// thread-safe.
[[nodiscard]] std::shared_ptr<const MultipleScatteringTable> shippedMultipleScatteringTable(const Phase& phase);
/// Names of the embedded tables (file stems), for reports and tests.
[[nodiscard]] std::vector<std::string> shippedMultipleScatteringTableNames();

}  // namespace fogbeam
