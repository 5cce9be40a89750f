// fogbeam — near-field lamps: a lamp with a finite emitting aperture (issue 7).
//
// A headlamp is a point lamp only from a few metres on: its lens is 0.1–0.3 m across, and a ray
// that passes 0.3 m from it sees light arrive from directions that differ by tens of degrees
// across the lens. Here a lamp's face is a rectangle or a disc in the lamp frame's y–z plane
// (perpendicular to the photometric axis +x, centred on Lamp::position_m), and its profile is
// the far-field intensity distribution I(w) spread uniformly over the face: every area element
// dA at offset q emits I(w)·dA/A towards w. The airlight of such a lamp is the mean over the
// face of the point lamp's airlight,
//
//   L_A(ray) = (1/A) ∫_A L_point(ray; S + worldFromLamp·(0, q_y, q_z)) dA,          (1)
//
// which a quadrature rule turns into Σ_i w_i L_point(ray; S_i) with Σ w_i = 1: the lamp becomes
// N point lamps with the same profile and colour × w_i (expandAperture), and every renderer
// that sums point lamps (the image evaluator, the GL and CPU surface passes) renders (1).
//
// The rules (apertureSamples), and why not a uniform grid: as a function of the offset q, the
// point lamp's airlight is smooth wherever the ray stays clear of the face (its Taylor series in
// q/h converges, h being the ray's distance from the lamp). The point lamp is the 1-point rule,
// exact for degree ≤ 1, so its error is second order, ~⟨q²⟩/h² (≈ 4 % for a 0.2 m wide lens at
// h = 0.3 m). A uniform midpoint grid of n per axis only divides that second-order term by n²;
// a Gauss rule of n per axis is exact up to degree 2n − 1 and leaves an error of order
// (a/h)^{2n} (a = the half-size), i.e. far below the airlight method's own error at n = 3.
//  * Rectangle: the Gauss–Legendre product rule, n × n points, exact for every monomial
//    y^j z^k with j, k ≤ 2n − 1.
//  * Disc (radius R): polar, Gauss–Legendre in s = r²/R² ∈ [0, 1] with n_r = ⌈n/2⌉ nodes times
//    n_φ = 2n equally spaced angles φ_j = 2π (j + ½)/n_φ. The area element is r dr dφ = ½ R² ds dφ,
//    so in (s, φ) the uniform density is constant and the Gauss–Legendre weights need no
//    Jacobian. A polynomial of total degree D in (y, z) has on each ring the Fourier modes
//    r^m e^{imφ}, |m| ≤ D, whose angular mean the equal-angle rule gets exactly for |m| < n_φ,
//    and whose m = 0 part is a polynomial of degree ≤ D/2 in s, exact when D/2 ≤ 2 n_r − 1.
//    So the rule is exact for total degree ≤ 2n − 1, like the rectangle's (n = 1: the centre).
//    (Gauss in r with the weight r would waste nodes: the m = 0 part is even in r.)
// Weights are not all equal (e.g. 25, 40 and 64 /324 for n = 3), so the image evaluator, which
// merges vehicle lamps' view tables only when their colours are equal, keeps one merged table
// per distinct weight (3 for a pair of n = 3 rectangles) instead of one.
//
// The reference for tests and `fogbeam validate` (ApertureAirlight::reference): the same rules
// with kReferenceApertureSamples (24) per axis, each point by the Reference method (adaptive
// Gauss–Kronrod along the ray): the "fine quadrature over the aperture" of issue 7.
//
// Units: metres; weights are dimensionless. Thread-safety: plain functions and values; an
// ApertureAirlight is immutable after build() and may be evaluated from any number of threads.
#pragma once

#include <fogbeam/physics/airlight.hpp>
#include <fogbeam/physics/medium.hpp>
#include <fogbeam/util/result.hpp>

#include <cstddef>
#include <string_view>
#include <vector>

namespace fogbeam {

enum class ApertureShape { Point, Rectangle, Disc };
[[nodiscard]] std::string_view toString(ApertureShape s);

/// Default points per axis (scene key `aperture_samples`): 3 × 3 for a rectangle, 2 rings × 6
/// angles for a disc; exact to degree 5 (module comment).
inline constexpr int kDefaultApertureSamples = 3;
/// Largest `samples` apertureSamples accepts (the scene and service files allow [1, 8]).
inline constexpr int kMaxApertureSamples = 64;
/// Points per axis of the reference quadrature over the aperture.
inline constexpr int kReferenceApertureSamples = 24;

/// The emitting face of a lamp, in the lamp frame's y–z plane, centred on the lamp's position.
struct Aperture {
  ApertureShape shape = ApertureShape::Point;
  double width_m = 0.0;   ///< rectangle: extent along the lamp's +y; disc: the diameter. Metres, > 0.
  double height_m = 0.0;  ///< rectangle: extent along the lamp's +z, metres, > 0; disc: unused
  int samples = kDefaultApertureSamples;  ///< points per axis n, [1, kMaxApertureSamples]; unused for Point

  /// Sizes finite and > 0 for Rectangle (both) and Disc (width_m); samples in range.
  [[nodiscard]] Status validate() const;
};

/// One point of an aperture's rule: its offset along the lamp's +y and +z (metres) and its
/// weight (Σ over the rule = 1).
struct ApertureSample {
  double y_m = 0.0;
  double z_m = 0.0;
  double weight = 1.0;
};

/// The quadrature rule of the module comment: Point → the centre with weight 1; Rectangle →
/// n × n Gauss–Legendre points (rows along +z, y fastest); Disc → ⌈n/2⌉ rings (inner first) ×
/// 2n angles, except n = 1 → the centre. `a` must be valid (asserted).
[[nodiscard]] std::vector<ApertureSample> apertureSamples(const Aperture& a);
/// apertureSamples(a).size(), without computing the rule.
[[nodiscard]] std::size_t apertureSampleCount(const Aperture& a) noexcept;

/// The point lamps that stand for `lamp` with aperture `a`, in apertureSamples order: the same
/// profile (the same shared_ptr, so they share airlight tables and GL uploads), the same
/// orientation, position_m + worldFromLamp·(0, y, z), color × weight (so the total intensity is
/// the lamp's). A Point aperture gives {lamp}.
[[nodiscard]] std::vector<Lamp> expandAperture(const Lamp& lamp, const Aperture& a);

/// Airlight of a lamp with an aperture: Σ_i w_i L_i(ray) over expandAperture's point lamps,
/// each by one AirlightMethod, in cd/m² for white light (like AirlightEvaluator::evaluate).
class ApertureAirlight {
 public:
  /// Errors: invalid aperture, invalid medium, lamp without profile.
  [[nodiscard]] static Result<ApertureAirlight> build(const Lamp& lamp, const Aperture& a, const Medium& medium,
                                                      AirlightMethod method, const AirlightOptions& options = {});
  /// The reference quadrature over the aperture: `a`'s shape and size with `samplesPerAxis`
  /// points per axis (576 for the default 24), each by AirlightMethod::Reference. A Point
  /// aperture gives the point lamp's reference. Slow: one Reference evaluation per point.
  [[nodiscard]] static Result<ApertureAirlight> reference(const Lamp& lamp, const Aperture& a, const Medium& medium,
                                                          int samplesPerAxis = kReferenceApertureSamples,
                                                          const AirlightOptions& options = {});

  /// L in cd/m² along `ray` (unit direction, distance_m ≥ 0 or +inf).
  [[nodiscard]] double evaluate(const Ray& ray) const noexcept;
  /// The number of point lamps summed.
  [[nodiscard]] std::size_t size() const noexcept { return lamps_.size(); }

 private:
  ApertureAirlight() = default;
  std::vector<AirlightEvaluator> lamps_;
  std::vector<double> weights_;
};

}  // namespace fogbeam
