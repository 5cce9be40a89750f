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
//    over u = log1p(k/k0) / log1p(kmax/k0) and ζ = sgn q (1 − (1 + |q|)^{−1/2}), q = tan θ,
//    which clusters nodes at θ → ±π/2 like the accurate method's own tables and needs no
//    trigonometry per pixel; bilinear on a dense grid (8192 ζ nodes): two gathers per row
//    where cubic Hermite on a coarser one needs four, and gathers are what the kernel waits on.
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
#include <fogbeam/physics/medium.hpp>
#include <fogbeam/scene/scene.hpp>
#include <fogbeam/util/thread_pool.hpp>

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace fogbeam::kernels {

/// F(k, ζ) for one phase function. data: nK rows of nZ values.
struct IsoTable {
  int nK = 0, nZ = 0;
  float k0 = 0.0f;         ///< k scale of the log axis
  float uScale = 0.0f;     ///< (nK − 1) / log1p(kMax / k0)
  float kMax = 0.0f;
  std::vector<float> data;
  [[nodiscard]] std::size_t bytes() const noexcept { return data.size() * sizeof(float); }

  /// Builds (or returns the cached) table for `phase`: nK × nZ nodes, Gauss–Legendre
  /// integration of G between nodes. About 0.3 s; cached per phase (weakly held).
  [[nodiscard]] static std::shared_ptr<const IsoTable> get(const Phase& phase, int nK = 192, int nZ = 8192,
                                                           double kMax = 100.0);
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
};
inline constexpr double kMaxIsoOpticalDistance = 60.0;

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
  double build_seconds = 0.0;
  [[nodiscard]] std::size_t bytes() const noexcept { return data.size() * sizeof(float); }

  /// Tabulates `lamp` (built with the accurate method) as seen from `camera`, covering its
  /// frustum (centred or off-axis) with `stepDeg` spacing (in angle at the view axis) and `nX`
  /// distances.
  /// Runs on `pool`.
  [[nodiscard]] static ViewTable build(const AirlightEvaluator& lamp, const Camera& camera, double stepDeg, int nX,
                                       ThreadPool& pool);
  /// The same over a window of the tangent plane: nA × nB nodes from (a0, b0), spacing
  /// `step` in tangent units.
  [[nodiscard]] static ViewTable buildWindow(const AirlightEvaluator& lamp, const Camera& camera, double a0,
                                             double b0, int nA, int nB, double step, int nX, ThreadPool& pool);
  /// True where this table contributes (see innerR2/outerR2).
  [[nodiscard]] bool covers(double a, double b) const noexcept;
  /// Scalar lookup (double arithmetic): the reference for the SIMD kernel. Luminance for
  /// white light, cd/m²; 0 where the table does not cover (a, b).
  [[nodiscard]] double lookup(double a, double b, double d) const noexcept;
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
/// rgb[c][i] += weight_c · L(pixel i) from a view table (SIMD, best target).
void accumulateViewTable(const ViewTable& table, const PixelGeometry& g, const PixelBatch& px, float* r, float* gr,
                         float* b);

/// The same sums in scalar double arithmetic, for tests and as the definition.
void accumulateIsoLampsScalar(const IsoTable& table, const IsoLamp* lamps, std::size_t nLamps, const PixelGeometry& g,
                              const PixelBatch& px, float* r, float* gr, float* b);
void accumulateViewTableScalar(const ViewTable& table, const PixelGeometry& g, const PixelBatch& px, float* r,
                               float* gr, float* b);

/// Distance-edge mask of one image row (SIMD): out[i] = 1 where the second difference of the
/// inverse distance q across pixel i, along the row (c[i−1], c[i], c[i+1]) or, when `up` and
/// `dn` (the rows above and below) are given, across the rows, exceeds tol · the largest q
/// involved; 0 elsewhere. The row's first and last pixels get the cross-row test only.
void markDistanceEdges(const float* up, const float* c, const float* dn, std::size_t n, float tol, std::uint32_t* out);

/// Names of the SIMD targets compiled in and supported by this CPU (e.g. "AVX3", "AVX2"),
/// best first, and the one the kernels dispatch to.
[[nodiscard]] std::vector<std::string> availableTargets();
[[nodiscard]] std::string activeTarget();
/// For tests: restricts dispatch to one target (by name from availableTargets());
/// an empty name restores the default. Returns false for an unknown name.
bool forceTarget(const std::string& name);

}  // namespace fogbeam::kernels
