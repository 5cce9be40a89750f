// fogbeam — the accurate method for many rays from one eye: the pencil of planes through the
// eye and the lamp.
//
// Every ray from the eye O lies in one plane through the line from O to the lamp S. Within
// such a plane ("spoke") the lamp sees the ray's points along one great circle of its
// direction sphere, the same circle for every ray of the spoke; only where the ray starts
// and ends on it (θ0, θd of eq. 3, Lecocq et al. 2001) and its k = K_t h differ. So the
// intensity along the circle, which is what makes a measured profile expensive (kinks,
// trigonometric angle conversions, bilinear lookups: ~15–25 µs per ray), is sampled once per
// spoke, and each ray only integrates the spoke's piecewise-quadratic I against the exact
// G moments T_q(k, θ) of the accurate method, with all cumulative distances in one pass.
//
// Spokes sit at `spokes` evenly spaced azimuths φ about the eye→lamp axis; a ray blends the
// two spokes around its own azimuth linearly (the nearest alone moves its direction by up to
// sin α · π / spokes, α the ray's angle from the lamp's direction, which at the sharp edges
// of a low beam's pattern costs 1 % at the 95th percentile; the blend is second order). An
// image evaluator samples fewer: a plan of every 32nd spoke, halved where rays would read the
// blend of an interval's ends wrongly (coarseStep(), middleDiffers(), setLeaf()); its rays
// then blend the two ends of their interval.
// The per-spoke pieces follow the accurate method: breakpoints at the profile's feature kinks
// and the edge of its support cone, and at the multiples of `piece_deg` (shared by all spokes,
// so that a blend of two spokes costs one pass); quadratic through both ends and the middle.
// Where I is smooth, neighbouring pieces merge (`merge_tolerance`).
//
// With `kernel_expansion` (the default) a ray does not integrate the pieces against G one by
// one: the rest of eq. (3)'s integrand, which depends only on the ray's angle from the lamp's
// direction, the optical eye–lamp distance and the phase function, is expanded once per phase
// function in B-splines along the circle (core/src/physics/airlight_kernel.hpp), each spoke
// projects its pieces on that basis once, and a ray is one short dot product plus the product
// integration of the last few degrees before its far end (where that kernel drops too sharply
// for a fixed basis).
//
// Units: metres, radians inside, degrees in options, cd, cd/m².
// Thread-safety: evaluate() and evaluateCumulative() may run from any number of threads at
// once; a spoke is sampled by the first thread that needs it (the others wait for it).
// reset() and moving the lamp's evaluator must not overlap them.
#pragma once

#include <fogbeam/physics/airlight.hpp>

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

namespace fogbeam {

struct PencilOptions {
  int spokes = 1440;       ///< azimuths about the eye→lamp axis (0.25° apart)
  double piece_deg = 2.0;  ///< quadratic pieces of I along a spoke's circle, degrees
  /// Neighbouring pieces merge (on a doubling grid) where one quadratic predicts both within
  /// this fraction of the spoke's peak intensity; 0 = never.
  double merge_tolerance = 3e-4;
  /// Rays through the kernel expansion (above); false: every piece through the G moments.
  bool kernel_expansion = true;
  /// Adaptive spokes (planned by an image evaluator, see coarseStep()): a spoke between two
  /// sampled ones is left out where test rays of it (sky rays at 0.25°–128° from the lamp and
  /// rays ending at every knot of the expansion) read the blend of the two within this
  /// fraction of their own value or of 1 % of the largest such value. 0 = every spoke (needs
  /// kernel_expansion; without it every spoke is sampled).
  double spoke_tolerance = 2e-3;
};

namespace detail {
class KernelTable;
}

class PencilAirlight {
 public:
  /// `lamp` must use the accurate method and outlive this object; `eye` in world metres.
  /// Errors: another method.
  [[nodiscard]] static Result<PencilAirlight> build(const AirlightEvaluator& lamp, const Vec3& eye,
                                                    const PencilOptions& options = {});
  /// The option checks of build(), without building anything.
  [[nodiscard]] static Status validate(const PencilOptions& options);

  /// Starts over from a new eye position, and takes the lamp evaluator's current pose and fog
  /// (a moving lamp, a fog that changed: AirlightEvaluator::setMedium): spokes are sampled
  /// again as needed, unless the direction from the eye to the lamp is the same in the lamp's
  /// frame (within 1e-9: a vehicle's own lamp seen from its driver), whose spokes are kept (they
  /// do not depend on the distance or the fog); their memory is kept either way.
  void reset(const Vec3& eye);

  [[nodiscard]] int spokeCount() const noexcept { return spokeCount_; }
  /// The spoke just below the ray's azimuth about the eye→lamp axis (a ray reads it and the
  /// next one), or −1 when rays go per ray (the lamp negligible, the eye at the lamp).
  [[nodiscard]] int spokeOf(const Vec3& direction) const noexcept { return spokesOf(direction).s0; }
  /// Samples spoke s now if no ray has yet (thread-safe like evaluate()): an image evaluator
  /// samples the spokes a frame needs on all threads before its rays read them. True when this
  /// call sampled it (false: sampled before, possibly kept from an earlier frame by reset()).
  bool prepareSpoke(int s) const { return ensureSpoke(s); }

  // Adaptive spokes. An image evaluator that knows which azimuths its rays take samples every
  // coarseStep()-th spoke there, then halves each interval [a, a + w] whose middle spoke is not
  // the blend of its ends (middleDiffers), down to single spokes, and tells the pencil which
  // spokes a ray between them blends (setLeaf). Rays in azimuths without a leaf blend their
  // two neighbouring spokes as before. Where a low beam's cut-off runs along the spokes they
  // stay 0.25° apart; across smooth light one in 32 or 16 is sampled.
  /// The coarse spacing, in spokes (a power of two dividing spokeCount(); 1 = no planning).
  [[nodiscard]] int coarseStep() const noexcept;
  /// With spokes a, a + w/2 and a + w (mod spokeCount()) sampled: whether rays of the middle
  /// one would read the mean of the ends wrongly by more than spoke_tolerance (PencilOptions).
  [[nodiscard]] bool middleDiffers(int a, int w) const;
  /// Rays whose azimuth lies in spokes [a, a + w) blend spokes a and a + w (mod spokeCount()),
  /// both sampled. Not thread-safe: between the sampling passes, before rays read.
  void setLeaf(int a, int w);
  /// L_m (white light, cd/m²) along the ray from the eye in `direction` (unit) up to each of
  /// `n` ascending distances (metres, +inf allowed), into out[0..n).
  /// Falls back to the evaluator's own evaluateCumulative where the G table ends (k > k_max,
  /// rays grazing a very distant lamp) and for rays through the lamp. ≥ 0: where a spoke's
  /// quadratic pieces dip below 0 next to a profile's dark region (a CSV grid's zeros) and the
  /// ray's light is ~0, the dip is not passed on as negative light.
  void evaluateCumulative(const Vec3& direction, const double* distances, std::size_t n, double* out) const;
  /// L_m along one ray up to `distance_m` (+inf = sky).
  [[nodiscard]] double evaluate(const Vec3& direction, double distance_m) const;

  [[nodiscard]] const AirlightEvaluator& lamp() const noexcept { return *lamp_; }

 private:
  // evaluateCumulative before its clamp at 0.
  void integrateCumulative(const Vec3& direction, const double* distances, std::size_t n, double* out) const;
  struct Piece {
    double a, b;       // ψ range along the spoke's circle, radians (ψ = 0: towards the eye)
    double m;          // centre
    double i0, c1, c2; // I(ψ) = i0 + c1 (ψ − m) + c2 (ψ − m)², cd
  };
  struct SpokePair {
    int s0 = -1, s1 = -1;  // the spokes either side of the ray's azimuth (−1: none needed)
    double t = 0.0;        // weight of s1
  };
  PencilAirlight() = default;
  [[nodiscard]] SpokePair spokesOf(const Vec3& direction) const noexcept;
  /// The spokes around azimuth φ (radians, [−π, π]) about the eye→lamp axis.
  [[nodiscard]] SpokePair spokesAt(double phi) const noexcept;
  /// φ of a ray whose part perpendicular to the eye→lamp axis is `perp`.
  [[nodiscard]] double azimuthOf(const Vec3& perp) const noexcept;
  bool ensureSpoke(int s) const;  // true when this call sampled it
  void sampleSpoke(int s) const;
  void mergeSmoothPieces(std::vector<Piece>& pieces) const;
  void integrate(int s0, int s1, double t, double psiFoot, double psiEnd, const void* kWeights, const double* psi,
                 std::size_t n, double* out, double psiStart = 0.0) const;
  void projectSpoke(int s) const;
  /// The whole functions' partial sums of one ray's ends so far (expansionIntegral).
  struct ExpansionSums {
    float acc[8] = {0, 0, 0, 0, 0, 0, 0, 0};  // function r's term in lane r mod 8
    int next = 0;                              // the first function not yet added
  };
  /// ∫_0^{xEnd} (Σ_r u_r β_r) I dψ, I the blend of the pair's spokes (xEnd within the
  /// expansion's range). `whole` starts empty per ray; its ends must come in ascending order.
  [[nodiscard]] double expansionIntegral(const SpokePair& sp, const float* u, double xEnd,
                                         ExpansionSums& whole) const noexcept;

  const AirlightEvaluator* lamp_ = nullptr;
  PencilOptions options_;
  int spokeCount_ = 0;
  Vec3 eye_{0.0};
  Vec3 e0_{1, 0, 0}, e1_{0, 1, 0}, e2_{0, 0, 1};  // eye→lamp axis and two normals (world)
  Vec3 spokeAxis_{0.0};                            // e0_ in the lamp's frame when the spokes were cleared
  bool spokesValid_ = false;                       // spokeAxis_ holds the sampled spokes' axis
  double distance_ = 0.0;                          // |S − O|, metres
  double tau_ = 0.0, tauPosition_ = 0.0;           // K_t |S − O| at reset() and its kernel-table position
  double expNegTau_ = 1.0;                         // e^{−τ}, the expansion's scale (once per pencil, not per ray)
  bool negligible_ = false;
  // Per spoke: its pieces and its state (0 not sampled, 1 being sampled, 2 ready). Filled
  // lazily from const evaluation calls, hence mutable; the state orders the accesses.
  mutable std::vector<std::vector<Piece>> pieces_;
  /// Per spoke: a bound of |I| along it (cd; from its pieces), for the tail test of rays.
  mutable std::vector<double> spokeBound_;
  /// Per spoke, with kernel_expansion: ∫_0^π β_r I_s dψ for every basis function r, then for
  /// every knot t_j the three ∫_0^{t_j} β_{j+i} I_s dψ, i = 0, 1, 2 (the functions that straddle it).
  mutable std::vector<std::vector<float>> projections_;
  /// Per spoke, with kernel_expansion: for every knot t_j (j = 0 … intervals()) the index of the
  /// first piece that ends after it (pieces().size() when none): where a ray's partial last
  /// interval and its tail start reading pieces, without a binary search per ray.
  mutable std::vector<std::vector<std::uint32_t>> pieceAtKnot_;
  std::shared_ptr<const detail::KernelTable> kernel_;
  /// The kernel table at this pencil's τ (KernelTable::sliceAt), refreshed by reset(): rays
  /// read two rows of it per ray instead of four of the whole table. Empty beyond kTauMax.
  std::vector<float> sliceRows_;
  std::vector<int> sliceCuts_;
  /// cos and sin of the multiples of piece_deg / 8, where most samples of a spoke fall (the
  /// coarse cells' cuts, middles and quarter points down to piece_deg, the grid pieces' ends
  /// and middles): sampling saves a sincos per sample.
  std::vector<double> gridCos_, gridSin_;
  std::unique_ptr<std::atomic<int>[]> state_;
  /// Per spoke k: the planned leaf [leafA_[k], leafA_[k] + leafW_[k]] holding azimuths in
  /// [k, k + 1), or leafW_[k] = 0 (none: blend k and k + 1). Cleared by reset().
  std::vector<int> leafA_, leafW_;
  /// middleDiffers' test rays: per test angle, the expansion's coefficients (functions() floats,
  /// 0 from its cut on) and how many count.
  std::vector<float> testRows_;
  std::vector<int> testCut_;
};

}  // namespace fogbeam
