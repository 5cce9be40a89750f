// fogbeam — luminous intensity distributions of lamps.
//
// Every profile answers I(w) in candela for a unit direction w in the *lamp frame*:
// +x is the photometric axis, +y left, +z up (docs/physics.md). Tabulated data are
// interpolated bilinearly between measured angles; directions outside the measured
// range give 0 cd.
//
// Angular conventions of tabulated data (docs/photometry.md has figures):
//  * Type C (EULUMDAT, IES type 1): γ is the angle from +x (γ = 0 on the axis, the
//    "nadir" of a luminaire that is aimed down with pitch = 90°); the C plane angle turns
//    about +x, C = 0 towards +y, C = 90° towards +z:
//        w = (cos γ, sin γ cos C, sin γ sin C).
//  * Type B (IES type 2, the usual headlamp goniometer): the polar axis is the lamp's
//    horizontal y axis. V (vertical angle) tilts the measuring plane about y, positive
//    towards +z; H (horizontal angle) is measured inside that plane, positive to the
//    lamp's right (−y), as on ECE H–V screen charts:
//        w = (cos H cos V, −sin H, cos H sin V).
//  * Type A (IES type 3): the polar axis is z. H turns the plane about z, positive to
//    the right (−y); V is the elevation inside the plane:
//        w = (cos V cos H, −cos V sin H, sin V).
// In all three, H = V = 0 (or γ = 0) lies on +x.
//
// Thread-safety: profiles are immutable after construction; evaluate from any thread.
#pragma once

#include <fogbeam/physics/math.hpp>
#include <fogbeam/util/result.hpp>

#include <cstdint>
#include <memory>
#include <string>
#include <utility>
#include <variant>
#include <vector>

namespace fogbeam {

/// The same intensity in every direction.
struct IsotropicProfile {
  double intensity_cd = 0.0;
};

/// A spot: full `peak_cd` within `inner` of the axis, falling linearly in angle to zero at
/// `outer` (radians, 0 ≤ inner < outer ≤ π). The convention of common physically based
/// renderers (pbrt-v4's smoothstep aside, the linear-in-angle falloff of the reference data).
struct SpotProfile {
  double peak_cd = 0.0;
  double inner = 0.0;  ///< radians
  double outer = 0.0;  ///< radians
};

/// The enumerators' order is their code in the GPU shaders (TYPE_*, SYM_* in
/// shaders/common_photometry.glsl) and the CPU shading kernel (render/surface_shading.hpp):
/// static_cast<int> gives it.
enum class PhotometricType { A, B, C };

/// How the plane angles of a tabulated profile are completed by symmetry.
enum class PlaneSymmetry {
  None,          ///< data cover the full range (type C: 0–360°, A/B: −90…90°)
  Rotational,    ///< one plane (type C): the same in every plane
  Quadrant,      ///< type C 0–90°: mirrored about the 0–180° and 90–270° planes
  Half0To180,    ///< type C 0–180°: mirrored about the 0–180° plane
  Half90To270,   ///< type C 90–270°: mirrored about the 90–270° plane
  MirrorH,       ///< types A/B 0–90° horizontal angles: I(−H, V) = I(H, V)
};

/// A grid of measured intensities. Angles in radians, ascending.
/// `horizontal` / `vertical` keep the file's meaning (IES: H planes, V angles; type C: C, γ),
/// `candela[ih * vertical.size() + iv]` is the intensity at (horizontal[ih], vertical[iv]),
/// already multiplied by every file factor (candela multiplier, ballast, lumens scaling).
struct TabulatedProfile {
  PhotometricType type = PhotometricType::C;
  PlaneSymmetry symmetry = PlaneSymmetry::None;
  std::vector<double> horizontal;  ///< radians
  std::vector<double> vertical;    ///< radians
  std::vector<double> candela;     ///< cd

  /// Where the data came from, for reports: "IES LM-63-2002", "EULUMDAT", "CSV grid".
  std::string format;
  std::string source;  ///< file path or generator description
  /// Descriptive keywords from the file ([MANUFAC], [TEST], EULUMDAT header fields…), in order.
  std::vector<std::pair<std::string, std::string>> keywords;

  /// Checks sizes, ordering and ranges (angles within the type's domain, finite, ≥ 0 cd).
  [[nodiscard]] Status validate() const;

  /// Optional O(1) lookup of the grid cell of an angle: `first[b]` is the last grid index
  /// whose angle is ≤ the start of bucket b (buckets of width ≤ half the finest spacing).
  /// Built by buildIndex() (makeProfile calls it); atAngles falls back to binary search
  /// without it. Derived data: not part of the profile's meaning.
  struct AxisIndex {
    double lo = 0.0, scale = 0.0;  ///< bucket = (angle − lo) · scale
    std::vector<std::uint32_t> first;
  };
  AxisIndex horizontalIndex, verticalIndex;
  void buildIndex();
  /// Bilinear interpolation at file angles (h, v) in radians after symmetry folding; 0 outside.
  [[nodiscard]] double atAngles(double h, double v) const noexcept;
};

/// File angles (h, v) in radians of a lamp-frame unit direction, for the type's convention.
struct FileAngles {
  double h;
  double v;
};
[[nodiscard]] FileAngles anglesFromDirection(PhotometricType type, const Vec3& w) noexcept;
[[nodiscard]] Vec3 directionFromAngles(PhotometricType type, double h, double v) noexcept;

/// A lamp's intensity distribution: a closed set of models (pbrt style: a variant,
/// no virtual call in hot loops).
class Profile {
 public:
  using Model = std::variant<IsotropicProfile, SpotProfile, TabulatedProfile>;

  explicit Profile(Model model) : model_(std::move(model)) {}

  /// I(w) in cd for a unit lamp-frame direction w.
  [[nodiscard]] double intensity(const Vec3& w) const noexcept;
  /// I(cos ψ_i u + sin ψ_i v) in cd for i < n, into out[i]: the profile along the great circle
  /// through u towards v (lamp frame, u ⟂ v unit vectors), ψ in radians. The values of
  /// intensity() up to the last bits of the direction's angles: for tabulated data the
  /// trigonometry runs on a SIMD vector of samples at a time (a moving lamp's spokes sample
  /// ~120 points per circle). Thread-safe.
  void intensitiesOnCircle(const Vec3& u, const Vec3& v, const double* psi, std::size_t n, double* out) const;
  [[nodiscard]] const Model& model() const noexcept { return model_; }

  /// Total luminous flux Φ = ∮ I dω in lumens (numerical for tabulated data).
  [[nodiscard]] double totalFlux() const;
  /// Largest intensity (cd) and a direction where it occurs (lamp frame).
  struct Peak {
    double intensity_cd;
    Vec3 direction;
  };
  [[nodiscard]] Peak peak() const;
  /// Half-angle (radians) of the smallest cone about +x outside which I = 0
  /// (π when the profile lights the whole sphere). Used to clip integration ranges.
  [[nodiscard]] double supportHalfAngle() const noexcept { return support_; }

  /// Kinks of I along the great circle w(θ) = cos θ·n + sin θ·t (n ⟂ t unit vectors,
  /// lamp frame) for θ ∈ (lo, hi): profile edges (spot cones, grid lines of tabulated
  /// data). Appends the θ values, unsorted. Used by the reference quadrature.
  void appendKinks(const Vec3& n, const Vec3& t, double lo, double hi, std::vector<double>& out) const;

  /// Like appendKinks, but only the grid lines where the slope of I changes most (at most
  /// 2 × kMaxFeatureLines lines, those whose largest second difference across the line exceeds
  /// 1 % of the peak): the cut-off of a headlamp, the edges of a beam. For spot profiles
  /// these are the two cone edges. Used by the accurate method to place its pieces.
  void appendFeatureKinks(const Vec3& n, const Vec3& t, double lo, double hi, std::vector<double>& out) const;
  static constexpr int kMaxFeatureLines = 32;

  /// A grid line on the direction sphere: the directions w with w·axis = c.
  struct Line {
    Vec3 axis;
    double c;
  };

 private:
  friend Result<std::shared_ptr<const Profile>> makeProfile(Model model);
  Model model_;
  double support_ = kPi;
  std::vector<Line> gridLines_;  // tabulated: every kink of the bilinear interpolant
  // Tabulated: the subset of the grid lines where the slope changes most, as arrays (axis x, y,
  // z and c of each line) for the SIMD crossings.
  std::vector<double> featureAx_, featureAy_, featureAz_, featureC_;
};

/// Validates and wraps a model (computes cached properties).
[[nodiscard]] Result<std::shared_ptr<const Profile>> makeProfile(Profile::Model model);

}  // namespace fogbeam
