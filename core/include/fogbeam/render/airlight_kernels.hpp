// fogbeam — the per-pixel kernels behind AirlightImageEvaluator's fast path (accurate method).
//
// A frame evaluates millions of (pixel, lamp) pairs; the per-ray product integration of the
// accurate method costs 0.3–20 µs each, a frame budget allows a few nanoseconds. Two float
// tables move the integration out of the frame loop, and Highway kernels (runtime dispatch:
// AVX-512, AVX2, SSE4 …) evaluate them for many pixels at once:
//
//  * IsoTable — isotropic lamps. For I constant, eq. (3) of Lecocq et al. 2001 is
//        L_m = Ω K_t I e^{−K_t p} / h · [F(k, θd) − F(k, θ0)],   F(k, θ) = ∫_{−π/2}^{θ} G(k, θ') dθ',
//    the Sun et al. 2005 "F table": it depends on the phase function only. It is tabulated
//    over u = plog2(1 + k/k0) (pseudoLog2 below: a log axis read off a float's bits) and
//    ζ = sgn q (1 − (1 + |q|)^{−1/2}), q = tan θ, which clusters nodes at θ → ±π/2 like the
//    accurate method's own tables and needs no trigonometry per pixel; bilinear on a dense
//    grid (8192 ζ nodes): two gathers per row where cubic Hermite on a coarser one needs four,
//    and gathers are what the kernel waits on.
//  * IsoSky — the same lamp seen against the sky (d = ∞). Then p = D cos γ, h = D sin γ and
//    θ0 = γ − π/2 depend on the angle γ between the ray and the lamp alone (D = |S − O|), so
//    L_m · sin γ / (Ω K_t I) = e^{−K_t D cos γ} / D · [F(k, π/2) − F(k, γ − π/2)] is a smooth,
//    bounded function of γ, tabulated per lamp and frame (microseconds) over the half-chord
//    x = |ω ∓ e| / 2 (sin γ/2 in front of the lamp's direction, cos γ/2 behind it: both
//    computed without cancellation). A sky pixel then costs two gathers per lamp instead of
//    eight, and no logarithm or exponential.
//  * ViewTable — a lamp fixed to the camera (a vehicle's own headlamps seen from its driver's
//    eye). Then L_m depends only on the pixel's direction and its distance d, and is tabulated
//    once from the accurate method (AirlightEvaluator::evaluateCumulative): directions on a
//    grid of the camera's tangent plane (bilinear), distances at x = d / (d + D) (cubic
//    Hermite with dL/dx from the in-scattering integrand). It is rebuilt when the lamp's pose
//    relative to the camera, the fog or the field of view change.
//
// Units: metres, cd, cd/m². Pixels are given by their image coordinates (x right, y down,
// centre of pixel (i, j) at (i + 0.5, j + 0.5)), distances along the ray (+inf = sky).
//
// Thread-safety: tables are immutable after build; kernels may run on disjoint output ranges
// from any number of threads.
#pragma once

#include <fogbeam/physics/airlight.hpp>
#include <fogbeam/physics/airlight_pencil.hpp>
#include <fogbeam/physics/medium.hpp>
#include <fogbeam/scene/scene.hpp>
#include <fogbeam/util/thread_pool.hpp>

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace fogbeam::kernels {

/// The k axis of IsoTable: plog2(y) for y ≥ 1 is the piecewise-linear base-2 logarithm that a
/// float's bits give, e + (m − 1) for y = 2^e · m, m ∈ [1, 2): exact at powers of two, linear
/// between, monotone and continuous. It spaces the table's rows like a log axis (14 to 29 rows
/// per octave at the defaults) and costs one integer subtraction per pixel where log1p costs a
/// polynomial. pseudoExp2 is its inverse.
[[nodiscard]] double pseudoLog2(double y) noexcept;
[[nodiscard]] double pseudoExp2(double u) noexcept;

/// F(k, ζ) for one phase function. data: nK rows of nZ values. quads: the same values as the
/// SIMD kernel reads them, the four nodes of cell (iu, iz) side by side at 4·(iu·nZ + iz):
/// F(iu, iz), F(iu, iz + 1), F(iu + 1, iz), F(iu + 1, iz + 1) (one 128-bit load per pixel
/// where four gathers cost three times as much).
struct IsoTable {
  int nK = 0, nZ = 0;
  float k0 = 0.0f;         ///< k scale of the log axis
  float uScale = 0.0f;     ///< (nK − 1) / plog2(1 + kMax / k0): row coordinate = plog2(1 + k/k0) · uScale
  float kMax = 0.0f;
  std::vector<float> data;
  std::vector<float> quads;
  Phase phase;  ///< the phase function tabulated
  [[nodiscard]] std::size_t bytes() const noexcept { return (data.size() + quads.size()) * sizeof(float); }
  /// F(k, π/2) − F(k, θ) = ∫_θ^{π/2} G(k, θ') dθ' integrated directly (adaptive Gauss–Kronrod
  /// in t = k tan(π/4 + θ'/2), where G = e^{−t} p is smooth): the table's bilinear values lose
  /// their relative precision for θ within a few degrees of π/2 at small k (rays looking
  /// straight away from a lamp).
  [[nodiscard]] double tailIntegral(double k, double theta) const;

  /// Builds (or returns the cached) table for `phase`: nK × nZ nodes, Gauss–Legendre
  /// integration of G between nodes. About 0.2 s; cached per phase (shared while held, the 4
  /// most recent kept; util/shared_cache.hpp). The
  /// defaults keep the table within 1e-4 (p95) of the accurate method's integral: the k axis
  /// sets the error (192 rows: 4e-4, 384: 4e-5 for g = 0.85), ζ beyond 2048 nodes adds nothing.
  [[nodiscard]] static std::shared_ptr<const IsoTable> get(const Phase& phase, int nK = 384, int nZ = 2048,
                                                           double kMax = 100.0);
  /// A new table, not cached (get() caches what this builds).
  [[nodiscard]] static std::shared_ptr<const IsoTable> build(const Phase& phase, int nK, int nZ, double kMax);
  /// Scalar F(k, θ) from the table (double arithmetic): the reference for the SIMD kernel.
  [[nodiscard]] double lookup(double k, double q) const noexcept;
};

/// The image geometry every kernel shares: pixel (x, y) → camera-frame direction
/// (1, a, b) / |·| with a = (cx − x)·invF, b = (cy − y)·invF (x forward, y left, z up).
struct PixelGeometry {
  float cx = 0.0f, cy = 0.0f;  ///< principal point (Camera::principalPoint()), pixels
  float invF = 0.0f;           ///< 1 / focal length in pixels
};

/// One isotropic lamp in camera coordinates. The caller leaves out lamps with
/// K_t·|pos| > kMaxIsoOpticalDistance: their airlight is below e^{−60} of their intensity
/// (u + r ≥ |pos| along every ray) and e^{K_t |p|} must stay finite in float.
struct IsoLamp {
  float pos[3] = {0, 0, 0};     ///< lamp − eye in the camera frame, metres
  float weight[3] = {0, 0, 0};  ///< Ω K_t I × colour per channel
  float kt = 0.0f;              ///< extinction coefficient K_t, 1/m
  /// Sky rays: the lamp's IsoSky table (buildIsoSky, 2·kIsoSkyNodes values; dir must be set),
  /// or nullptr to evaluate them through the F table like any other ray.
  const float* sky = nullptr;
  float dir[3] = {1, 0, 0};     ///< pos / |pos|
};
inline constexpr double kMaxIsoOpticalDistance = 60.0;

/// Nodes per half of an IsoSky table: x = i / (n − 1) · √½ for i < n (in front, x = sin γ/2),
/// the same for i ≥ n behind (x = cos γ/2). 0.16° apart in γ at most; linear interpolation is
/// then within ~5e-5 of the table's own values (the phase function's forward peak, g ≤ 0.9,
/// spreads over ≥ 5°).
inline constexpr int kIsoSkyNodes = 512;
/// Fills out[0, 2·kIsoSkyNodes) with L_m · sin γ / (Ω K_t I) against the sky for a lamp at
/// distance |lamp.pos| in fog of extinction lamp.kt (see IsoSky above), from `table` in double
/// arithmetic (nodes within 3° of straight away from the lamp by IsoTable::tailIntegral), and
/// sets lamp.dir. About 0.1 ms.
void buildIsoSky(const IsoTable& table, IsoLamp& lamp, float* out);
/// Sets lamp.dir from lamp.pos (as buildIsoSky does), for a table kept from an earlier frame.
void setIsoDirection(IsoLamp& lamp) noexcept;

/// Cached airlight of one camera-fixed lamp over (direction, distance).
struct ViewTable {
  float a0 = 0.0f, b0 = 0.0f;  ///< tangent-plane coordinates of node (0, 0)
  float invStep = 0.0f;        ///< 1 / node spacing in tangent units
  int nA = 0, nB = 0, nX = 0;  ///< direction nodes along a and b; distance nodes
  float distanceScale = 0.0f;  ///< D of x = d / (d + D), metres
  float weight[3] = {1, 1, 1};  ///< lamp colour
  // Near the lamp's own image the airlight peaks like 1/h and no fixed grid interpolates it:
  // the table counts only where innerR2 < r² ≤ outerR2, r the tangent-plane distance from
  // (guardA, guardB). The frustum table leaves a hole of a few steps around the lamp, an inset
  // table 8× finer fills the ring around it, the per-ray evaluator the last pixels.
  float guardA = 0.0f, guardB = 0.0f;
  float innerR2 = -1.0f, outerR2 = 3.0e38f;
  std::vector<float> data;     ///< per direction (b-major), per x node: (L, dL/dx · Δx)
  /// The sky's values (x = 1) of the four direction nodes of cell (ia, ib) side by side at
  /// 4·(ib·nA + ia): (ia, ib), (ia + 1, ib), (ia, ib + 1), (ia + 1, ib + 1) (made by finish()).
  std::vector<float> skyQuads;
  double build_seconds = 0.0;
  [[nodiscard]] std::size_t bytes() const noexcept { return (data.size() + skyQuads.size()) * sizeof(float); }
  /// Makes skyQuads from data (after a build or add()).
  void finish();

  /// Tabulates `lamp` (built with the accurate method) as seen from `camera`, covering its
  /// frustum (centred or off-axis) with `stepDeg` spacing (in angle at the view axis) and `nX`
  /// distances; for frusta so wide that this spacing would need more than kMaxDirections
  /// directions, the spacing that gives that many (viewTableStep).
  /// Runs on `pool`.
  /// `distanceScale` (metres) fixes D of x = d / (d + D); 0 picks defaultDistanceScale(). Tables
  /// of several lamps built with the same camera, step, nX and D share one grid (sameGrid) and
  /// can be summed (add).
  /// `pencil`: when set (a PencilAirlight of `lamp` whose eye is the camera's position), the
  /// table's rays go through it instead of the lamp's per-ray evaluator: the same integral,
  /// the profile sampled once per plane through eye and lamp (docs/airlight.md, "View tables
  /// from the pencil").
  [[nodiscard]] static ViewTable build(const AirlightEvaluator& lamp, const Camera& camera, double stepDeg, int nX,
                                       ThreadPool& pool, double distanceScale = 0.0,
                                       const PencilAirlight* pencil = nullptr);
  /// Directions a frustum table holds at most (~230 MB a lamp at 48 distances): a view 120° wide at
  /// 16:9 (559 752 directions at 0.2°) keeps its step.
  static constexpr std::size_t kMaxDirections = 589824;
  /// The frustum table's node spacing in tangent units for `stepDeg` at the view axis over a
  /// window spanA × spanB of the tangent plane: tan(stepDeg), or coarser where that would
  /// exceed kMaxDirections nodes (views wider than ~120° at 16:9).
  [[nodiscard]] static double viewTableStep(double stepDeg, double spanA, double spanB) noexcept;
  /// The same over a window of the tangent plane: nA × nB nodes from (a0, b0), spacing
  /// `step` in tangent units.
  [[nodiscard]] static ViewTable buildWindow(const AirlightEvaluator& lamp, const Camera& camera, double a0,
                                             double b0, int nA, int nB, double step, int nX, ThreadPool& pool,
                                             double distanceScale = 0.0, const PencilAirlight* pencil = nullptr);
  /// D for a lamp at `lampDistance` metres from the eye in fog of extinction `kt`: about a
  /// third of the distance nodes within 0.3 mean free paths, and D at least twice the lamp's
  /// distance (the near-lamp peak), clamped to [.., 200 m].
  [[nodiscard]] static double defaultDistanceScale(double kt, double lampDistance) noexcept;
  /// True when both tables have the same nodes (window, spacing, distances).
  [[nodiscard]] bool sameGrid(const ViewTable& o) const noexcept;
  /// data += o.data (same grid): the airlight of two lamps of one colour in one table, read
  /// with one set of loads.
  void add(const ViewTable& o);
  /// True where this table contributes (see innerR2/outerR2).
  [[nodiscard]] bool covers(double a, double b) const noexcept;
  /// Scalar lookup (double arithmetic): the reference for the SIMD kernel. Luminance for
  /// white light, cd/m²; 0 where the table does not cover (a, b).
  [[nodiscard]] double lookup(double a, double b, double d) const noexcept;
  /// The same without the coverage test.
  [[nodiscard]] double lookupAnywhere(double a, double b, double d) const noexcept;
};

/// A batch of pixels, structure of arrays. Arrays hold `n` valid entries and must be
/// readable and writable up to paddedSize(n) (the kernels work in whole vectors).
struct PixelBatch {
  const float* x = nullptr;
  const float* y = nullptr;
  const float* d = nullptr;  ///< distance along the ray, metres, +inf = sky
  std::size_t n = 0;
};
/// Entries to allocate for a batch of n pixels: n rounded up to 64 (any vector length).
[[nodiscard]] constexpr std::size_t paddedSize(std::size_t n) noexcept { return (n + 63) / 64 * 64; }

/// rgb[c][i] += Σ_lamps weight_c · L_m(pixel i) for isotropic lamps (SIMD, best target).
void accumulateIsoLamps(const IsoTable& table, const IsoLamp* lamps, std::size_t nLamps, const PixelGeometry& g,
                        const PixelBatch& px, float* r, float* gr, float* b);
/// How a view table is applied: weights per channel and the annulus innerR2 < r² ≤ outerR2
/// around (guardA, guardB) where it counts. of() gives the table's own; a merged table's
/// correction inside one lamp's hole reads that lamp's frustum table with its weights negated
/// and the hole as the disc.
///
/// `rotated`: the table is read at the direction rot · (1, a, b) instead of (1, a, b) (camera
/// frame, row-major 3×3), i.e. at (a', b') = (y'/x', z'/x'): a table made for a lamp turned by
/// a rotation Q about its own position, read for the lamp as it is now, takes rot = Qᵀ (the
/// bending ladder, docs/airlight.md "Bending on the ladder"). The annulus is tested at the
/// pixel's own (a, b): the lamp's image does not move when it turns about its position. Rays
/// turned behind the eye (x' ≤ 0) read nothing. Inside the `nKeep` discs (centre keepA/keepB,
/// squared radius keepR2, tangent units: the lamps' images) the table is read unturned: there
/// the turn moves the reads into the peak around a lamp's image, where the eye's offset from
/// the turned lamp is not small against the ray's distance from it.
struct ViewTableUse {
  static constexpr int kMaxKeep = 4;
  float weight[3] = {1, 1, 1};
  float guardA = 0.0f, guardB = 0.0f;
  float innerR2 = -1.0f, outerR2 = 3.0e38f;
  bool rotated = false;
  float rot[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  int nKeep = 0;
  float keepA[kMaxKeep] = {}, keepB[kMaxKeep] = {}, keepR2[kMaxKeep] = {};
  [[nodiscard]] static ViewTableUse of(const ViewTable& t) noexcept;
};

/// rgb[c][i] += weight_c · L(pixel i) from a view table (SIMD, best target). Sky pixels
/// (d = +inf) read the last distance node only: one gather per corner instead of four.
void accumulateViewTable(const ViewTable& table, const PixelGeometry& g, const PixelBatch& px, float* r, float* gr,
                         float* b);
void accumulateViewTable(const ViewTable& table, const ViewTableUse& use, const PixelGeometry& g, const PixelBatch& px,
                         float* r, float* gr, float* b);

/// The same sums in scalar double arithmetic, for tests and as the definition.
void accumulateIsoLampsScalar(const IsoTable& table, const IsoLamp* lamps, std::size_t nLamps, const PixelGeometry& g,
                              const PixelBatch& px, float* r, float* gr, float* b);
void accumulateViewTableScalar(const ViewTable& table, const PixelGeometry& g, const PixelBatch& px, float* r,
                               float* gr, float* b);
void accumulateViewTableScalar(const ViewTable& table, const ViewTableUse& use, const PixelGeometry& g,
                               const PixelBatch& px, float* r, float* gr, float* b);

/// Distance-edge bits of one row of inverse distances: bit i of `bits` (64-bit words,
/// little-endian bit order) is set where the second difference across entry i, along the row or
/// across the rows, exceeds tol · the largest of the three values, and that largest value
/// exceeds `floor` (edges wholly beyond 1/floor metres are ignored). c[−1] and c[n … n + 15] (and
/// the same of up and dn) must be readable; entries 0 and n − 1 get the cross-row test only.
/// `bits` must hold (n + 63) / 64 + 1 words; they are overwritten.
void distanceEdgeBits(const float* up, const float* c, const float* dn, std::size_t n, float tol, float floor,
                      std::uint64_t* bits);
/// q[i] ≈ 1 / d[i] for i < n (0 for +inf), within 4e-4 relative (the hardware estimate where a
/// target has one): for the distance-edge and layer tests, not for arithmetic.
void inverseDistances(const float* d, std::size_t n, float* q);

/// A leaf of the adaptive subsampling in tile-plane coordinates: its corners (i0, j0),
/// (i0 + w, j0), (i0, j0 + h), (i0 + w, j0 + h) hold evaluated values; columns i0 … iEnd and
/// rows j0 … jEnd are filled.
struct FillBlock {
  std::int32_t i0, j0, w, h, iEnd, jEnd;
};
/// Fills every pixel of each block that `done` (one byte per pixel, 0 = not evaluated) does not
/// mark, in the planes r, g, b (row stride `stride` floats), by bilinear interpolation of the
/// block's corners. Rows must be readable and writable 16 floats past each block's iEnd.
void fillBlocks(const FillBlock* blocks, std::size_t n, float* r, float* g, float* b, const std::uint8_t* done,
                std::size_t stride);
/// out[3i + c] = plane c [i] for i < n: three planes to interleaved RGB, with non-temporal
/// stores. Call flushStreams() before another thread reads `out`.
void interleaveRgb(const float* r, const float* g, const float* b, std::size_t n, float* out);
/// out[3i + c] += plane c [i] for i < n (plain stores: `out` is read anyway).
void interleaveAddRgb(const float* r, const float* g, const float* b, std::size_t n, float* out);
/// Orders the non-temporal stores of this thread before its later stores (x86 sfence).
void flushStreams();

/// Names of the SIMD targets compiled in and supported by this CPU (e.g. "AVX3", "AVX2"),
/// best first, and the one the kernels dispatch to.
[[nodiscard]] std::vector<std::string> availableTargets();
[[nodiscard]] std::string activeTarget();
/// For tests: restricts dispatch to one target (by name from availableTargets());
/// an empty name restores the default. Returns false for an unknown name.
bool forceTarget(const std::string& name);

}  // namespace fogbeam::kernels
