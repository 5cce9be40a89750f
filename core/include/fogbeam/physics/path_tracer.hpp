// fogbeam — the all-orders reference: a Monte Carlo path tracer for point lamps in a homogeneous
// fog (issue 18, first step). It answers the same question as AirlightEvaluator (the light that
// the fog scatters towards an eye along a view ray, in front of the visible surface), but for
// every scattering order, split into single (order 1), multiple (orders ≥ 2) and all.
//
// What is estimated (docs/physics.md, "All-orders reference: the path tracer"). The eye at O looks
// along the unit ω; the camera ray ends at d (the visible surface; +inf for sky) or where it meets
// the optional ground plane. The in-scattered radiance is the Neumann series of the radiative
// transfer equation (RTE) for a homogeneous medium with point lamps,
//
//     L(O, ω) = Σ_{n≥1} L_n,   L_1 = ∫_0^d e^{−K_t u} Ω K_t p(cos α) I(w) e^{−K_t r}/r² du
//                               (exactly the integral of AirlightMethod::Reference),
//
// and L_n for n ≥ 2 the same with n scattering events (medium or ground) between lamp and eye.
// Units: metres, cd, cd/m²; K_t in 1/m; luminance for white light (lamp colours enter `rgb` only).
//
// Method: backward (eye) path tracing. Every path segment (the camera ray, then each ray leaving a
// scattering vertex) connects to every lamp by next-event estimation (NEE) — point lamps cannot be
// hit — with two samples along the segment combined by the balance heuristic: the free-flight
// collision point (sampled ∝ K_t e^{−K_t s}; forced into [0, D) on the camera ray by the truncated
// exponential) and a point drawn from an even mixture of an equiangular density (pdf ∝ 1/r²
// towards that lamp), which keeps the variance finite next to a lamp where 1/r² would make NEE at
// collision points alone infinite-variance, and a density that follows the phase function of the
// point's scattering angle (the lamp's light running back along the segment: fog-mie's forward
// peak, which the equiangular density misses).
// The collision point continues the path: albedo Ω as a weight, a new direction drawn from the
// phase function (HG and isotropic exactly; fog-mie from an inverse-CDF table over the scattering
// angle, weighted by p / pdf so the estimate stays unbiased). Ground hits (z = z0, Lambertian ρ)
// connect to lamps and reflect cosine-weighted. Russian roulette (weight windows on a diffusion
// estimate of what a path can still collect) ends paths unbiasedly; a hard cap on the order
// (PathTracerOptions::max_order, 1000) ends the rest, and what the cap cuts off is estimated
// separately (`remainder`, from the diffusion approximation) rather than silently dropped.
//
// Determinism: path (stream s, sample i) draws from its own counter-based generator seeded by
// (seed, s, i), and sums are reduced in a fixed order, so results are bit-identical for any number
// of threads.
//
// Thread-safety: a PathTracer is immutable after build(); trace() and estimate() may be called
// from any number of threads at once (each ThreadPool from one thread at a time, as ThreadPool
// requires).
#pragma once

#include <fogbeam/physics/airlight.hpp>
#include <fogbeam/physics/math.hpp>
#include <fogbeam/physics/medium.hpp>
#include <fogbeam/util/result.hpp>

#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <vector>

namespace fogbeam {

class ThreadPool;

/// A Lambertian ground plane z = height_m (world frame, z up) of reflectance ρ ∈ [0, 1]. It
/// blocks: nothing propagates below it; the camera ray ends on it (its own luminance, the surface
/// term L_s, is not airlight and is not counted); scattered paths that meet it reflect diffusely.
struct GroundPlane {
  double height_m = 0.0;
  double reflectance = 0.0;  ///< ρ
};

struct PathTracerOptions {
  /// Largest scattering order traced (medium and ground events count alike). Orders above it are
  /// not in single/multiple/all; their expected sum is estimated in `remainder`. 1 gives single
  /// scattering only (cheap: the camera segment alone).
  int max_order = 1000;
  /// Roulette is not applied before this many events (low orders carry most of the light).
  int roulette_start = 4;
  /// Weight window: a path whose weight times its diffusion estimate of the light it can still
  /// collect falls below this fraction of the largest such value along the path is rouletted.
  double roulette_fraction = 0.25;
  /// Fog-mie (and tabulated) phase sampling: nodes of the inverse-CDF table over the scattering
  /// angle (θ = π u², u uniform: dense at the forward peak).
  int phase_table_nodes = 4096;
  /// Sample HG and isotropic phases through the same table as fog-mie (tests the table).
  bool tabulate_all_phases = false;
  /// Samples per work item of estimate(); part of what fixes the summation order (keep it fixed
  /// when comparing runs bit for bit).
  std::uint32_t batch_size = 256;
  /// Lamp-guided next-event estimation at every scattering vertex (medium and ground): besides
  /// the phase-sampled direction that continues the path, one direction drawn towards a lamp
  /// (ψ from the lamp's direction uniform in [0, π/2], pdf 1/(π² sin ψ); the lamp chosen ∝ its
  /// diffusion importance at the vertex) gets its own segment's lamp connections, and the two
  /// directions' segment connections are combined by the balance heuristic (two-sample MIS).
  /// This bounds the 1/h of a segment passing at h from a lamp; the path's continuation and its
  /// weight are untouched. false: phase-sampled segments only.
  bool lamp_guiding = true;
};

/// A counter-based generator (SplitMix64, Steele et al. 2014): the state is a hash of
/// (seed, stream, sample), so path i of stream s always draws the same numbers.
class PathRng {
 public:
  PathRng(std::uint64_t seed, std::uint64_t stream, std::uint64_t sample) noexcept;
  [[nodiscard]] std::uint64_t next() noexcept;
  /// Uniform in [0, 1).
  [[nodiscard]] double uniform() noexcept { return static_cast<double>(next() >> 11) * 0x1.0p-53; }

 private:
  std::uint64_t state_;
};

/// One path's contributions, in cd/m² (luminance for white light).
struct PathSample {
  double single = 0.0;     ///< order 1
  double multiple = 0.0;   ///< orders 2 … max_order
  double remainder = 0.0;  ///< diffusion estimate of orders above max_order (0 when roulette ended the path)
  Vec3 rgb{0.0};           ///< orders 1 … max_order with lamp colours (linear RGB)
  int events = 0;          ///< scattering events generated (for cost reports)

  PathSample& operator*=(double s) noexcept {
    single *= s;
    multiple *= s;
    remainder *= s;
    rgb *= s;
    return *this;
  }
};

/// Mean and standard error of the mean of one quantity.
struct McEstimate {
  double mean = 0.0;
  double std_error = 0.0;
};

struct RadianceEstimate {
  McEstimate single;     ///< order 1: compare with AirlightMethod::Reference
  McEstimate multiple;   ///< orders 2 … max_order
  McEstimate all;        ///< orders 1 … max_order
  McEstimate remainder;  ///< estimated orders above max_order (diffusion closure; approximate)
  McEstimate total;      ///< all + remainder (per path, so its error accounts for correlation)
  Vec3 rgb{0.0};         ///< mean of `all` per channel with lamp colours
  std::uint64_t samples = 0;
  double mean_events = 0.0;  ///< mean scattering events per path
};

class PathTracer {
 public:
  /// Errors: invalid medium (K_t must be > 0), a lamp without profile, ground reflectance outside
  /// [0, 1], options out of range. Lamps below or on the ground plane light nothing.
  [[nodiscard]] static Result<PathTracer> build(std::vector<Lamp> lamps, const Medium& medium,
                                                std::optional<GroundPlane> ground = std::nullopt,
                                                const PathTracerOptions& options = {});

  /// One path for the view ray (origin O, unit direction ω, distance_m = d ≥ 0 or +inf).
  [[nodiscard]] PathSample trace(const Ray& ray, PathRng& rng) const;

  /// `samples` paths per ray; ray j uses stream `first_stream + j` of `seed`. Work is spread over
  /// `pool` (nullptr: the calling thread) in batches of options().batch_size samples.
  [[nodiscard]] std::vector<RadianceEstimate> radiance(std::span<const Ray> rays, std::uint64_t samples,
                                                       std::uint64_t seed, ThreadPool* pool = nullptr,
                                                       std::uint64_t first_stream = 0) const;

  /// The general form, for estimators of derived quantities (fluxes, ring means): `path(s, i, rng)`
  /// returns the contribution of sample i of stream s, drawing from `rng` (seeded by
  /// (seed, s, i)), e.g. a random view direction and then trace(). Deterministic for any pool.
  using PathFunction = std::function<PathSample(std::uint64_t stream, std::uint64_t sample, PathRng& rng)>;
  [[nodiscard]] std::vector<RadianceEstimate> estimate(std::uint64_t streams, std::uint64_t samples,
                                                       std::uint64_t seed, ThreadPool* pool,
                                                       const PathFunction& path) const;

  /// The diffusion approximation's fluence of all lamps at x divided by 4π (cd/m²): Σ Φ_ℓ
  /// e^{−r/L} / (4π D max(r, 1/K_t)) / (4π), D = 1/(3 K_t (1 − Ω g)), L = √(D / (K_t (1 − Ω))).
  /// Used as the importance of roulette and as the remainder closure; ignores the ground.
  [[nodiscard]] double diffusionRadiance(const Vec3& x) const noexcept;

  [[nodiscard]] const Medium& medium() const noexcept { return medium_; }
  [[nodiscard]] const std::vector<Lamp>& lamps() const noexcept { return lamps_; }
  [[nodiscard]] const std::optional<GroundPlane>& ground() const noexcept { return ground_; }
  [[nodiscard]] const PathTracerOptions& options() const noexcept { return options_; }

  /// A scattering direction drawn from the phase function about `forward` (unit), with the weight
  /// p / pdf (1 for HG and isotropic sampled exactly). Exposed for tests.
  struct PhaseDraw {
    Vec3 direction;
    double weight;
  };
  [[nodiscard]] PhaseDraw samplePhase(const Vec3& forward, PathRng& rng) const noexcept;
  /// The density (1/sr) with which samplePhase draws a direction at angle α from `forward`, given
  /// cos α and sin α ≥ 0 (the phase function itself for HG and isotropic; the inverse-CDF table's
  /// density for fog-mie). For estimators that combine phase sampling with other strategies.
  [[nodiscard]] double phaseSamplingPdf(double cosAngle, double sinAngle) const noexcept;
  /// The density (1/sr) with which the lamp-guided NEE at x draws the unit direction w: the
  /// lamps' mixture of 1 / (π² sin ψ) over the hemisphere towards each (ψ the angle from it),
  /// +inf exactly towards a lit lamp (sin ψ rounds to 0), 0 where no lamp guides. Exposed for
  /// tests. Thread-safe (const).
  [[nodiscard]] double guideDensity(const Vec3& x, const Vec3& w) const noexcept;

 private:
  [[nodiscard]] double phasePdf(const Vec3& forward, const Vec3& w) const noexcept;
  [[nodiscard]] double guideWeight(std::size_t lamp, const Vec3& x) const noexcept;
  [[nodiscard]] double guideWeightSum(const Vec3& x) const noexcept;  // Σ_ℓ guideWeight(ℓ, x)
  [[nodiscard]] double guidePdf(const Vec3& x, const Vec3& w, double weightSum) const noexcept;
  [[nodiscard]] Vec3 sampleGuide(const Vec3& x, double weightSum, PathRng& rng) const noexcept;
  struct PhaseTable;  // inverse CDF over the scattering angle (path_tracer.cpp)
  struct AngleTable;  // ∫ p(cos α) dα, NEE's phase-angle strategy (path_tracer.cpp)
  PathTracer() = default;
  std::vector<Lamp> lamps_;
  std::vector<Mat3> lampFromWorld_;
  std::vector<double> lampFlux_;  // Φ_ℓ in lm, for the diffusion estimate
  std::vector<char> lampLit_;     // lamp above the ground (or no ground)
  std::size_t guidedLamps_ = 0;   // lit lamps with flux > 0 (guiding targets)
  Medium medium_;
  std::optional<GroundPlane> ground_;
  PathTracerOptions options_;
  std::shared_ptr<const PhaseTable> phaseTable_;
  std::shared_ptr<const AngleTable> angleTable_;
  double hgG_ = 0.0;
  int phaseKind_ = 0;  // 0 isotropic, 1 HG analytic, 2 table
  double diffusionD_ = 0.0, diffusionInvL_ = 0.0;
};

}  // namespace fogbeam
