// fogbeam — single-scattered light ("airlight") along one view ray, from one point lamp.
//
//   L_m = ∫_0^d e^{−K_t u} Ω K_t p(cos α(u)) I(w(u)) e^{−K_t r(u)} / r(u)² du      [cd/m²]
//
// rewritten with the equiangular variable θ of Lecocq et al. 2001, eq. (3):
//
//   L_m = Ω K_t e^{−K_t p} / h · ∫_{θ0}^{θd} G(K_t h, θ) I(w(θ)) dθ,
//   G(k, θ) = exp(−k (1 + sin θ)/cos θ) · p(−sin θ),   w(θ) = cos θ·n + sin θ·ω,
//
// where p is the foot of the lamp's perpendicular on the ray, h the lamp's distance to the
// ray and n the unit vector from the lamp to that foot (docs/physics.md).
//
// Three evaluators share one signature (AirlightEvaluator::evaluate):
//  * Reference — adaptive Gauss–Kronrod (Boost.Math) in θ, split at every kink of the
//    integrand (profile edges, grid lines, the phase peak); relative accuracy ~1e-9.
//  * Seed      — the paper as written: G ≈ c0 + c1 θ + c2 θ² (Taylor at θ = 0, c_j tabulated
//    in k = K_t h), moments ∫ θ^j I dθ from cumulative tables along great circles of the
//    lamp's direction sphere (closed form for isotropic lamps).
//  * Accurate  — product integration, the converse of the seed: the phase peak and the
//    exponential are integrated exactly through tables of ∫ θ^j G dθ over (k, θ), while I is
//    interpolated (piecewise quadratic) between samples placed at the profile's own
//    breakpoints. docs/airlight.md gives the design and the measured errors.
//
// Thread-safety: an evaluator is immutable after build(); evaluate() may be called from any
// number of threads at once. Tables are shared (shared_ptr) between evaluators with the same
// medium or the same profile.
#pragma once

#include <fogbeam/physics/math.hpp>
#include <fogbeam/physics/medium.hpp>
#include <fogbeam/physics/profile.hpp>
#include <fogbeam/util/result.hpp>

#include <cmath>
#include <cstddef>
#include <memory>
#include <string>
#include <string_view>

namespace fogbeam {

namespace detail {
struct AirlightTables;  // core/src/physics/airlight_tables.hpp
}

/// A point lamp in the world frame.
struct Lamp {
  Vec3 position_m{0.0};
  Mat3 worldFromLamp{1.0};  ///< columns: the lamp's +x (photometric axis), +y, +z in world
  std::shared_ptr<const Profile> profile;
  glm::dvec3 color{1.0};    ///< linear RGB weights; luminance is reported for white (1,1,1)
};

/// A view ray: origin (eye), unit direction, and the distance to the visible surface in
/// metres (+infinity for sky).
struct Ray {
  Vec3 origin{0.0};
  Vec3 direction{1.0, 0.0, 0.0};
  double distance_m = 0.0;
};

enum class AirlightMethod { Reference, Seed, Accurate };
[[nodiscard]] std::string_view toString(AirlightMethod m);
[[nodiscard]] Result<AirlightMethod> parseAirlightMethod(std::string_view s);

/// Memory and build-time figures of an evaluator's tables.
struct TableStats {
  std::size_t bytes = 0;       ///< memory held by the tables this evaluator uses
  double build_seconds = 0.0;  ///< wall time spent building them (0 when reused)
};

/// Table resolutions; the defaults are the ones validated in docs/airlight.md.
struct AirlightOptions {
  double reference_rel_tol = 1e-10;  ///< Reference: relative tolerance of each GK piece
  // Accurate: G-moment table over (k, θ) and I sampling.
  int g_table_theta = 1024;          ///< θ nodes, clustered at ±π/2
  int g_table_k = 192;               ///< k nodes on a log scale
  double g_table_k_max = 2000.0;     ///< largest tabulated K_t·h; beyond it, direct quadrature
  int accurate_segments = 48;        ///< I samples per ray for tabulated profiles
  int accurate_spot_segments = 6;    ///< quadratic pieces per spot transition ring
  // Seed: Taylor coefficients over k, great-circle tables.
  int seed_k_nodes = 512;
  double seed_circle_step_deg = 2.0;  ///< plane-orientation and along-circle step
};

/// One lamp in one medium, with one method.
class AirlightEvaluator {
 public:
  /// Builds (or reuses from an internal cache keyed by medium/profile) the tables the
  /// method needs. Errors: invalid medium, lamp without profile.
  [[nodiscard]] static Result<AirlightEvaluator> build(const Lamp& lamp, const Medium& medium,
                                                       AirlightMethod method,
                                                       const AirlightOptions& options = {});

  /// In-scattered luminance L_m in cd/m² (for white light; multiply by lamp.color per channel).
  /// `ray.direction` must be unit length; `ray.distance_m` ≥ 0 or +inf.
  [[nodiscard]] double evaluate(const Ray& ray) const noexcept;

  /// L_m along one ray up to each of `n` distances (metres, ascending, +inf allowed), written
  /// to out[0..n). `ray.distance_m` is ignored. The accurate method does this in one pass
  /// (the distances become breakpoints of its product integration), which is what the image
  /// evaluator's view tables are built from; other methods call evaluate() per distance.
  void evaluateCumulative(const Ray& ray, const double* distances, std::size_t n, double* out) const;

  /// Moves the lamp (a vehicle's lamp follows its vehicle every frame); tables are kept.
  /// Not thread-safe with evaluate().
  void setPose(const Vec3& position_m, const Mat3& worldFromLamp) noexcept;

  /// Another fog with the same phase function (its tables depend on the phase alone, the
  /// extinction and albedo enter per ray): a fog that changes every frame keeps the evaluator.
  /// Errors: an invalid medium, or another phase function (then build a new evaluator).
  /// Not thread-safe with evaluate().
  [[nodiscard]] Status setMedium(const Medium& medium);

  [[nodiscard]] AirlightMethod method() const noexcept { return method_; }
  [[nodiscard]] const TableStats& stats() const noexcept { return stats_; }
  [[nodiscard]] const Lamp& lamp() const noexcept { return lamp_; }
  [[nodiscard]] const Medium& medium() const noexcept { return medium_; }
  [[nodiscard]] const AirlightOptions& options() const noexcept { return options_; }

 private:
  friend class PencilAirlight;  // shares the accurate method's G-moment table
  AirlightEvaluator() = default;
  Lamp lamp_;
  Medium medium_;
  AirlightMethod method_ = AirlightMethod::Reference;
  AirlightOptions options_;
  Mat3 lampFromWorld_{1.0};
  std::shared_ptr<const detail::AirlightTables> tables_;
  TableStats stats_;
};

/// The geometry of eq. (3) for one ray and lamp: exposed for tests and the image evaluator.
struct RayLampGeometry {
  double p;       ///< (S − O)·ω, metres
  double h;       ///< lamp distance to the ray line, metres (> 0; clamped at 1e-9)
  Vec3 n;         ///< unit vector from the lamp towards the ray's foot point (world)
  double theta0;  ///< atan(−p/h), the eye
  double thetaD;  ///< atan((d − p)/h), the visible surface (π/2 for d = ∞)
};
[[nodiscard]] RayLampGeometry rayLampGeometry(const Ray& ray, const Vec3& lampPosition) noexcept;

/// G(k, θ) of eq. (3) for a phase function.
[[nodiscard]] double integrandG(const Phase& phase, double k, double theta) noexcept;
/// G's two factors at θ, neither of which depends on k: G(k, θ) = e^{−k · exponent} · phase with
/// phase = p(−sin θ) and exponent = tan(π/4 + θ/2) (→ ∞ as θ → π/2). integrandG is exactly
/// integrandGFrom(k, integrandGFactors(phase, θ)), so a table over many k computes these once.
struct GFactors {
  double phase;
  double exponent;
};
[[nodiscard]] GFactors integrandGFactors(const Phase& phase, double theta) noexcept;
/// G(k, θ) from its factors at θ (k ≥ 0; G(0, θ) = phase, also where exponent is infinite).
[[nodiscard]] inline double integrandGFrom(double k, const GFactors& f) noexcept {
  return k == 0.0 ? f.phase : std::exp(-k * f.exponent) * f.phase;
}

/// The accurate method's cumulative G moments T_q(k, θ) = ∫_{−π/2}^{θ} θ'^q G(k, θ') dθ' for one
/// phase function, in float, as the GPU path uploads them (docs/airlight.md, "GPU path"). The
/// same table (and cache) as AirlightMethod::Accurate with `options`.
struct GMomentTexels {
  int nTheta = 0, nK = 0;
  double k0 = 0.0;       ///< k scale: row coordinate u = log1p(k/k0) / logSpan · (nK − 1)
  double logSpan = 0.0;  ///< log1p(kMax/k0)
  double kMax = 0.0;     ///< largest tabulated k
  std::vector<float> theta;   ///< the θ nodes (radians), nTheta
  std::vector<float> texels;  ///< per k row, per θ node: T_0, T_1, T_2, G (nK × nTheta × 4)
  // The double values are hi + lo (lo = value − hi, float): the GPU rebuilds them in double.
  std::vector<float> thetaLo, texelsLo;
};
[[nodiscard]] GMomentTexels gMomentTexels(const Phase& phase, const AirlightOptions& options = {});

}  // namespace fogbeam
