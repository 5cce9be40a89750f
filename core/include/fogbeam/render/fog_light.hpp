// fogbeam — the fog's scattered light on surfaces (issue 18): what the surface layer's direct
// light I(w) cos i e^{−K_t r}/r² leaves out. Every point of a surface is also lit by the fog
// around it, which glows with the light it scatters from the lamps (order 1) and scatters again
// (orders ≥ 2). In 50 m fog that is 0.6 × the direct light under a street lamp and 3–15 × it
// 20–40 m along the road (docs/airlight.md, "Scattered light on surfaces").
//
// The model (docs/physics.md, "Scattered light on surfaces"). For a lamp at distance r from a
// surface point X, seen in the direction a (unit, from X to the lamp), in fog of extinction K_t,
// albedo Ω and phase p, the radiance arriving at X from the direction ω at the angle θ from a is
// by dimensional analysis K_t² l(T, θ) per cd, T = K_t r. Split by the angle η at the lamp between
// the direction the light left it and the direction to X (the multiple-scattering tables'
// emission bins k, edges η_k), a measured lamp contributes Σ_k Ī_k(w) K_t² l_k(T, θ), Ī_k(w) the
// mean of its intensity over the annulus η ∈ [η_k, η_{k+1}] about w = −a (lamp frame): exact for
// the part of the light symmetric about the lamp–point axis. Per bin:
//   order 1:  l¹_k(T, θ) = Ω / (T sin θ) ∫_{η ∈ bin k, η < π − θ} p(cos(θ + η))
//                                           e^{−T (sin η + sin θ) / sin(θ + η)} dη
//   (law of sines in the triangle X, lamp, scattering point: the scattering angle is θ + η),
//   orders ≥ 2: f(T, θ, Ω) share_k(T, θ) from the multiple-scattering table.
// The irradiance of a Lambertian element with unit normal n is E = ∫ L(ω) max(0, ω·n) dω, for a
// radiance symmetric about a a function of μ = n·a alone. FogLightTable computes it exactly at 81
// values of μ (crowding to μ = 0, grazing incidence) and fits, per bin and T node,
//   E_k(μ) ≈ Σ_q c_kq b_q(μ),  b = (1, μ, r_0.01(μ), r_0.1(μ))          [lux per cd, K_t = 1 /m]
// (weighted least squares, nearly relative; r_σ(μ) = (μ + √(μ² + σ²))/2, smoothed ramps: the
// light from close to the lamp's direction has a kink at grazing incidence, μ⁺ for the lamp's
// direction itself, smoothed over the angle it arrives from; fogLightBasis).
//
// Which side of the lamp–point axis the light leaves on (a low beam lights the road below the
// axis to a point ahead and the fog above it hardly at all): the annulus's first azimuthal
// harmonic, I ≈ Ī_k + Ī₁_k · ê (ê the unit vector of the azimuth about the axis; Ī₁_k a vector
// perpendicular to it). A scatterer seen from X in the direction ω lies on the same side of the
// axis as ω, so order 1 gives the radiance l¹_k(T, θ) Ī₁_k · ω̂⊥, and the element's irradiance
// from it is (Ī₁_k · n) G_k(μ) with
//   G_k(μ) = ∫ l¹_k(θ) W₁(θ, μ) sin θ dθ / √(1 − μ²),  W₁ = ∫ cos φ max(0, ω·n) dφ,
// fitted as Σ_q g_kq d_q(μ), d = (1, and smoothed steps μ/√(μ² + σ²), σ = 0.3, 0.005, 0.04: G_k is a
// step at μ = 0 as wide as the sine of the angle its light arrives at). Orders ≥ 2 bring
// f(T, θ, Ω) h_k(T, θ) Ī₁_k · ω̂⊥, h_k the multiple-scattering table's first azimuthal harmonic
// of the emission (MultipleScatteringTable::emissionHarmonics: how much of the side the light that
// scattered more than once still remembers; 0, the ring means alone, with tables that lack it),
// so G_k integrates Ω l¹_k + f h_k. So a lamp's fog light at a point is s_q = K_t² Σ_k Ī_k c_kq and four vectors
// D_q = K_t² Σ_k Ī₁_k g_kq, all depending on the point's position only (fogLightLamp); the normal
// enters per pixel (fogLightIrradiance):
//   E = Σ_q b_q(μ) s_q + d_q(μ) D_q · n.
// The surface layer evaluates s on an adaptive grid and blends it between nodes (SurfaceShader,
// fogbeam/render/surface_shading.hpp).
//
// Assumes infinite homogeneous fog around each point (a road absorbs part of the diffuse light
// and there is no fog below it: `fogbeam validate --path-tracer` prints the model against the path
// tracer on a road of ρ = 0.1 and without it; docs/airlight.md),
// no shadows (as the direct light), and light that reaches the surface through the fog only
// (the direct light is the surface layer's).
//
// Thread-safety: the tables and maps are immutable after build and may be read from any thread.
#pragma once

#include <fogbeam/physics/medium.hpp>
#include <fogbeam/physics/profile.hpp>
#include <fogbeam/scene/scene.hpp>
#include <fogbeam/util/result.hpp>

#include <array>
#include <cmath>
#include <cstddef>
#include <functional>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

namespace fogbeam {

class MultipleScatteringTable;
class ThreadPool;

/// The coefficients c_k0 … c_k3 (T) and the dipole's g_k0 … g_k3 of the header comment
/// for one phase function and albedo, on T = 2^(−7) … 2^5 at 2^(1/4); per cd of each emission
/// bin's mean intensity (harmonic), K_t = 1 /m.
class FogLightTable {
 public:
  static constexpr std::size_t kSymmetric = 4;     ///< c0 … c3: the functions of μ (fogLightBasis)
  static constexpr std::size_t kCoefficients = 8;  ///< per bin: c0 … c3, then the dipole's g0 … g3
  /// weighted()'s output: s0 … s3, then D0 … D3 (3 floats each).
  static constexpr std::size_t kLampFloats = kSymmetric + 3 * kSymmetric;
  /// Order 1 by Gauss–Legendre quadrature over η (per bin, 8 points per piece, pieces ≤ 3°,
  /// finer near η = 0 for forward-peaked phase functions), orders ≥ 2 from `ms` (its emission
  /// bins; a table without bins counts as one bin 0–180°), E_k(μ) over the glow curve's 257
  /// angles. `pool`: the T nodes are spread over it (null: this thread). ~0.15 s on 2 cores.
  /// Errors: albedo outside (0, 1].
  [[nodiscard]] static Result<std::shared_ptr<const FogLightTable>> build(const MultipleScatteringTable& ms,
                                                                          const Phase& phase, double albedo,
                                                                          ThreadPool* pool = nullptr);
  /// Order 1 alone over the emission bins `edges` (radians, 0 … π, rising): for tests and
  /// `fogbeam validate`, which compare the model's order 1 with quadratures of it.
  [[nodiscard]] static Result<std::shared_ptr<const FogLightTable>> buildOrderOne(const std::vector<double>& edges,
                                                                                  const Phase& phase, double albedo,
                                                                                  ThreadPool* pool = nullptr);
  /// The cached table for (phase, albedo, ms): built on first use, the 4 most recent kept.
  [[nodiscard]] static Result<std::shared_ptr<const FogLightTable>> get(
      const std::shared_ptr<const MultipleScatteringTable>& ms, const Phase& phase, double albedo,
      ThreadPool* pool = nullptr);
  /// get() for the shipped multiple-scattering table of `phase` (shippedMultipleScatteringTable;
  /// an error where there is none), and with `cacheDir` (the view tables' table cache) kept on
  /// disk too ("fl-<hash>.bin": the phase function and albedo, the code version, which covers the
  /// shipped tables' files; a checksum): a later run loads it in a few ms instead of building it
  /// (~0.15–0.2 s on 2 cores). A store that fails leaves its message in `cacheError` (not null).
  [[nodiscard]] static Result<std::shared_ptr<const FogLightTable>> shipped(const Phase& phase, double albedo,
                                                                            ThreadPool* pool = nullptr,
                                                                            const std::string& cacheDir = {},
                                                                            std::string* cacheError = nullptr);
  /// shipped()'s table from `cacheDir` alone: null where no run of this code stored it there
  /// for this phase function and albedo, or the file is damaged (never a wrong table).
  [[nodiscard]] static std::shared_ptr<const FogLightTable> loadShipped(const Phase& phase, double albedo,
                                                                        const std::string& cacheDir);

  [[nodiscard]] std::size_t bins() const noexcept { return edges_.size() - 1; }
  /// Emission bin edges η_k, radians, 0 … π.
  [[nodiscard]] const std::vector<double>& edges() const noexcept { return edges_; }
  [[nodiscard]] double albedo() const noexcept { return albedo_; }
  /// c[k · kCoefficients + q] (c0 … c3, g0 … g3 of bin k) at optical distance T (per cd, K_t = 1 /m):
  /// between the fit's nodes log-linear in T for E_k(μ = 1) and linear for the coefficients over
  /// it, read from a dense resampling of that (linear between its rows); below the first node
  /// c ∝ 1/T (order 1's limit: the light gathered within a few mean free paths); above the last
  /// node (T = 32, where the light has fallen by e^{−32}) 0. `c` holds bins() · kCoefficients values.
  void coefficients(double opticalDistance, double* c) const noexcept;
  /// Σ_k binMeans[k] (c0 … c3)_k(T) × scale into out[0 … 3] and Σ_k binDipoles[3k … 3k+2]
  /// g_kq(T) × scale into out[4 + 3q … 6 + 3q] (in the dipoles' frame), in float, from the dense
  /// table; binMeans null: an isotropic lamp (every mean 1, no dipole); binDipoles null: none.
  /// out holds kLampFloats. The frames' look-up.
  void weighted(double opticalDistance, const float* binMeans, const float* binDipoles, float scale,
                float* out) const noexcept;
  /// E(μ) per cd of a lamp whose bins' mean intensities are `binMeans` and whose harmonics'
  /// components along the normal are `dipoleDotN` (null: 0) (K_t = 1 /m: multiply by K_t²),
  /// clamped at 0; μ = cos of the angle between the normal and the lamp's direction.
  [[nodiscard]] double irradiance(double opticalDistance, double mu, const double* binMeans,
                                  const double* dipoleDotN = nullptr) const noexcept;

  [[nodiscard]] const std::vector<double>& opticalDistances() const noexcept { return t_; }
  /// Seconds the table took to build, or to load from the table cache (shipped()).
  [[nodiscard]] double buildSeconds() const noexcept { return buildSeconds_; }

  /// The dense table the frames read, for the shaders (shaders/common_photometry.glsl mirrors
  /// weighted()): rows at T = 2^(−7 + i/16) for i ≤ kDenseLog, then 1 + (i − kDenseLog)/16 up
  /// to 32; row i holds bins() × kCoefficients floats (c0 … c3, g0 … g3 per bin),
  /// denseSums() row i the sums of the first 4 over the bins.
  static constexpr std::size_t kDenseLog = 7 * 16, kDenseNodes = kDenseLog + 31 * 16 + 1;
  [[nodiscard]] const std::vector<float>& dense() const noexcept { return dense_; }
  [[nodiscard]] const std::vector<float>& denseSums() const noexcept { return denseSum_; }

 private:
  FogLightTable() = default;
  [[nodiscard]] static Result<std::shared_ptr<const FogLightTable>> build(const MultipleScatteringTable* ms,
                                                                          const std::vector<double>& edges,
                                                                          const Phase& phase, double albedo,
                                                                          ThreadPool* pool);
  void smoothCoefficients(double opticalDistance, double* c) const noexcept;  // from the build nodes
  // Every array, for the table cache (shipped()); fromBytes: null unless the sizes are the
  // table's for `edges` and the stored edges and albedo are `edges` and `albedo`.
  [[nodiscard]] std::string toBytes() const;
  [[nodiscard]] static std::shared_ptr<const FogLightTable> fromBytes(std::string_view bytes,
                                                                      const std::vector<double>& edges, double albedo);
  /// The dense row below T, the weight of the next and the 1/T factor below the first node;
  /// false beyond the table (T ≤ 0 or T > 32: no light).
  bool denseRow(double opticalDistance, std::size_t& row, double& weight, double& below) const noexcept;
  std::vector<double> edges_, t_;
  std::vector<double> logEnv_, norm_;  // [iT][k] log E_k(μ = 1); [iT][k][kCoefficients] the coefficients over it
  std::vector<float> dense_;           // [dense T node][k][kCoefficients] (fog_light.cpp)
  std::vector<float> denseSum_;        // [dense T node][4]: Σ over bins
  double albedo_ = 1.0;
  double buildSeconds_ = 0.0;
};

/// Order 1 of the header comment for one bin: l¹ (albedo 1) at (T, θ) from the light that left
/// the lamp at η ∈ [eta0, eta1] (radians). Exposed for tests (the sum over bins is the isotropic
/// lamp's single scattering).
[[nodiscard]] double fogLightOrder1(const Phase& phase, double opticalDistance, double theta, double eta0,
                                    double eta1) noexcept;

/// The azimuthal integrals of the clamped cosine for radiance arriving at θ from the lamp's
/// direction a on an element whose normal n = μ a + √(1 − μ²) x̂: w0 = ∫ max(0, ω·n) dφ and
/// w1 = ∫ cos φ max(0, ω·n) dφ / √(1 − μ²) (φ from x̂; the dipole's, header comment). With
/// A = μ cos θ, B = √(1 − μ²) sin θ: where the element sees part of the ring about a, cos φ0 = −A/B,
/// w0 = 2 (A φ0 + B sin φ0), w1 = (A sin φ0 + B φ0) / √(1 − μ²); all of it (A ≥ B): 2π A and π sin θ;
/// none: 0. Exposed for tests (the model's integrals without its fits in μ).
struct FogLightAzimuthal {
  double w0 = 0.0, w1 = 0.0;
};
[[nodiscard]] FogLightAzimuthal fogLightAzimuthal(double theta, double mu) noexcept;

/// The irradiance of a horizontal element facing +z, E = ∫ L(ω) ω_z dω over the upper hemisphere,
/// by deterministic quadrature: u = sin² of the angle from +z (cos dω = ½ du dφ), 64-point
/// Gauss–Legendre in u (nodes crowding to the horizon, where a road sees the lamps along it) ×
/// `azimuths` midpoints in φ. The reference the fog light's model is checked against (tests,
/// `fogbeam validate --path-tracer`): `radiance(ω)` is e.g. the accurate method's airlight along the
/// sky ray ω from the point (cd/m² in, lux out). Rows of u run on `pool`'s threads, so `radiance` must
/// be callable concurrently; the sum is the same for any number of threads.
[[nodiscard]] double hemisphereIrradiance(const std::function<double(const Vec3&)>& radiance, ThreadPool& pool,
                                          std::size_t azimuths = 256);

/// Ī_k(w) and the harmonics Ī₁_k(w) of one profile over the lamp-frame directions: a grid of 0.5° / 3°
/// in the angle from the lamp's +x axis (0 … 180°) and 3° in the azimuth about it (atan2(z, y)),
/// bilinear between nodes. Each node's annuli as the glow's (cellAnnulusMeans, lamp_effects.hpp:
/// sphere cells for annuli ≥ 10° wide, fine azimuths for the others).
/// Built once per (profile, bins, frontOnly): ~0.9–1.0 s for a tabulated file on 2 cores, or
/// loaded from the table cache on disk (~10 ms) where an earlier run stored it.
class AnnulusMeanMap {
 public:
  /// `frontOnly`: directions behind the lamp's axis are dark (the driver's own lamps, as the glow).
  /// The profile's sphere cells are the glow's (sharedProfileSphereCells): made once per profile.
  /// `cacheDir` (empty: none): the table cache of the view tables (airlight_image.hpp,
  /// FastPathOptions::table_cache_dir): the map is loaded from there when a run of the same
  /// code stored it for the same profile data, edges and frontOnly, else built and stored
  /// ("am-<hash>.bin"); a store that fails leaves its message in `cacheError` (not null) and the
  /// built map is returned all the same.
  [[nodiscard]] static std::shared_ptr<const AnnulusMeanMap> build(const std::shared_ptr<const Profile>& profile,
                                                                   const std::vector<double>& edges, bool frontOnly,
                                                                   ThreadPool* pool = nullptr,
                                                                   const std::string& cacheDir = {},
                                                                   std::string* cacheError = nullptr);
  /// build()'s map, shared by the whole process: the one alive for the same profile (by
  /// identity), edges and frontOnly, else build()'s (the 16 most recent kept alive besides those
  /// held). One build at a time (SharedCache): a thread that asks for a map another thread is
  /// building waits for it instead of building it twice, so a map made ahead of the frames
  /// (FogLightPrewarm) is the one every SurfaceShader and GL pass of the process uses.
  /// Thread-safety: any thread; `pool` is used by the calling thread alone.
  [[nodiscard]] static std::shared_ptr<const AnnulusMeanMap> shared(const std::shared_ptr<const Profile>& profile,
                                                                    const std::vector<double>& edges, bool frontOnly,
                                                                    ThreadPool* pool = nullptr,
                                                                    const std::string& cacheDir = {},
                                                                    std::string* cacheError = nullptr);
  /// How many maps build() has computed in this process (loads from the table cache not
  /// counted): what tests read to tell a map made ahead from one made in a frame.
  [[nodiscard]] static std::size_t buildsSoFar() noexcept;
  /// Whether build() loaded it from the table cache.
  [[nodiscard]] bool fromCache() const noexcept { return fromCache_; }
  /// Ī_k for the lamp-frame unit direction `w`, k < bins, into means[k], and (dipoles not null)
  /// Ī₁_k, lamp frame, into dipoles[3k … 3k + 2] (made perpendicular to w).
  void lookup(const Vec3& w, double* means, double* dipoles = nullptr) const noexcept;
  void lookup(const Vec3& w, float* means, float* dipoles = nullptr) const noexcept;
  /// The dipoles' components along the unit vector `n` (lamp frame: a surface's normal),
  /// dotN[k] = Ī₁_k · n for k < bins: what FogLightTable::irradiance takes as `dipoleDotN`.
  static void dipolesAlong(const double* dipoles, std::size_t bins, const Vec3& n, double* dotN) noexcept {
    for (std::size_t k = 0; k < bins; ++k)
      dotN[k] = dipoles[3 * k] * n.x + dipoles[3 * k + 1] * n.y + dipoles[3 * k + 2] * n.z;
  }
  [[nodiscard]] std::size_t bins() const noexcept { return bins_; }

  /// The grid, for the shaders: rows of the angle α from the axis every kFineDeg up to
  /// kFineRows · kFineDeg, then every kStepDeg to 180°; columns of the azimuth atan2(z, y) every
  /// kStepDeg over 0 … 360° (the last repeats the first); values()[((row · columns() + column) ·
  /// bins() + k) · kFloats + i]: i = 0 the mean, 1 … 3 the harmonic (lamp frame).
  static constexpr std::size_t kFloats = 4;
  static constexpr double kFineDeg = 0.5, kStepDeg = 3.0;
  static constexpr int kFineRows = 48;
  [[nodiscard]] int rows() const noexcept { return nA_; }
  [[nodiscard]] int columns() const noexcept { return nB_; }
  [[nodiscard]] const std::vector<float>& values() const noexcept { return v_; }

 private:
  AnnulusMeanMap() = default;
  template <class T>
  void lookupInto(const Vec3& w, T* means, T* dipoles) const noexcept;
  std::size_t bins_ = 0;
  int nA_ = 0, nB_ = 0;
  std::vector<float> v_;  // [iα][iβ][k][kFloats]
  bool fromCache_ = false;
};

/// The fog light's table and its lamps' annulus maps made ahead of the frames that show the
/// lamps. A map is ~0.9–1.0 s of work on 2 cores the first time a lamp file is ever seen (later
/// runs load it from the table cache in a few ms), and SurfaceShader::prepareFogLight makes one
/// on first use, in the frame: a service that knows its lamps (the ego's, the world's, every
/// traffic class's) starts this at start-up so that the first oncoming car of a new lamp file
/// does not hold its frame for a second. Runs on a thread of its own with a pool of `threads`
/// (0: the machine's cores); the maps it makes are AnnulusMeanMap::shared's, held here while
/// this object lives. A frame that needs a map before the thread reaches it waits for the map
/// being built and then makes its own (never a map twice). Nothing in an image changes: the
/// maps are the same whoever makes them.
/// Thread-safety: ready(), wait() and summary() from any thread; the destructor stops the
/// thread after the map in progress (at most ~1 s) and joins it.
class FogLightPrewarm {
 public:
  struct Lamp {
    std::shared_ptr<const Profile> profile;  ///< isotropic profiles need no map and are skipped
    bool frontOnly = false;                  ///< the driver's own lamps (LampMount::Vehicle)
  };
  /// Starts the thread: the table for `phase` and `albedo` (nothing more when the phase
  /// function has no multiple-scattering table), then each distinct (profile, frontOnly) in the
  /// order given. `cacheDir`: the table cache (empty: none). `done` (may be empty) is called on
  /// the thread when it has finished, with the summary (a service logs it).
  struct Summary;
  FogLightPrewarm(std::vector<Lamp> lamps, const Phase& phase, double albedo, unsigned threads,
                  std::string cacheDir, std::function<void(const Summary&)> done = {});
  ~FogLightPrewarm();
  FogLightPrewarm(const FogLightPrewarm&) = delete;
  FogLightPrewarm& operator=(const FogLightPrewarm&) = delete;

  [[nodiscard]] bool ready() const;
  void wait() const;
  /// Waits for the thread, then: the maps made (or loaded), in the order asked; how many were
  /// loaded from the table cache; the thread's wall time, s; the last failure, to store a table
  /// or map in the cache or of the prewarm itself (memory; empty: none).
  struct Summary {
    std::vector<std::shared_ptr<const AnnulusMeanMap>> maps;
    std::size_t loaded = 0;
    double seconds = 0.0;
    std::string error;
  };
  [[nodiscard]] const Summary& summary() const;

 private:
  struct State;
  std::unique_ptr<State> state_;
};

/// One frame's lamps for the fog light, camera-relative (positions in metres from the eye).
struct FogLightFrame {
  struct Lamp {
    Vec3 pos{0.0};        ///< lamp − eye, m
    Mat3 lampFromWorld{1.0};
    double i0 = 0.0;      ///< isotropic intensity (map null), cd
    const AnnulusMeanMap* map = nullptr;
    std::shared_ptr<const AnnulusMeanMap> map_owner;  ///< keeps `map` alive (the GL upload holds it)
  };
  double extinction = 0.0;  ///< K_t, 1/m
  const FogLightTable* table = nullptr;
  std::shared_ptr<const FogLightTable> table_owner;  ///< keeps `table` alive
  std::vector<Lamp> lamps;
  /// Floats of all lamps' blocks in fogLightCoefficients' output (fogLightFloats summed).
  [[nodiscard]] std::size_t floats() const noexcept;
};

/// The fog light's functions of μ (cos of the angle between the normal and the lamp's direction).
/// Symmetric part: 1, μ and two smoothed ramps r_σ(μ) = (μ + √(μ² + σ²))/2 (σ = 0.01, 0.1): the
/// light arriving from close to the lamp's direction has a kink at grazing incidence (μ⁺ for light
/// from the lamp's direction itself), smoothed over the angle it arrives from. Dipole: 1 and three
/// smoothed steps μ/√(μ² + σ²) (σ = 0.3, 0.005, 0.04): G_k is a step about μ = 0 as wide as the
/// sine of that angle (docs/physics.md, "Scattered light on surfaces"). T: float or double.
inline constexpr double kFogRampWidth[2] = {0.01, 0.1};
inline constexpr double kFogStepWidth[3] = {0.3, 0.005, 0.04};
template <class T>
inline void fogLightBasis(T mu, T* sym, T* dip) noexcept {
  const T mu2 = mu * mu;
  if (sym != nullptr) {
    sym[0] = T(1);
    sym[1] = mu;
    for (int i = 0; i < 2; ++i) {
      const T w = static_cast<T>(kFogRampWidth[i]);
      sym[2 + i] = T(0.5) * (mu + std::sqrt(mu2 + w * w));
    }
  }
  if (dip != nullptr) {
    dip[0] = T(1);
    for (int i = 0; i < 3; ++i) {
      const T w = static_cast<T>(kFogStepWidth[i]);
      dip[1 + i] = mu / std::sqrt(mu2 + w * w);
    }
  }
}

/// Floats of a measured lamp's block (fogLightLamp): s0 … s3, then D0 … D3 (camera-relative world
/// vectors, 3 floats each).
inline constexpr std::size_t kFogLightFloats = FogLightTable::kLampFloats;
/// Floats of lamp `l`'s block: kFogLightFloats with an annulus map, 4 for an isotropic lamp (no
/// dipole: its light is the same on every side).
[[nodiscard]] inline std::size_t fogLightFloats(const FogLightFrame::Lamp& l) noexcept {
  return l.map != nullptr ? kFogLightFloats : FogLightTable::kSymmetric;
}

/// Each lamp's s = K_t² Σ_k Ī_k c_k(K_t r) and D_q = K_t² Σ_k Ī₁_k g_kq(K_t r) at the camera-relative
/// point `x` (m), into consecutive blocks of fogLightFloats(lamp) floats, lamp after lamp (0
/// where K_t r > 32 or r = 0; an isotropic lamp's block holds s alone): its
/// fog light on an element of unit normal n there is E = Σ_q b_q(μ) s_q + d_q(μ) D_q · n lux (clamp
/// at 0), b, d the functions of fogLightBasis, μ = n · (lamp − x)/r. Returns the distance to the
/// nearest lamp that counts (m; +inf: none). Reentrant.
double fogLightCoefficients(const FogLightFrame& frame, const Vec3& x, float* out) noexcept;

/// The same for lamp `lamp` alone, into out[0 … fogLightFloats(lamp)); returns its distance (m).
double fogLightLamp(const FogLightFrame& frame, std::size_t lamp, const Vec3& x, float* out) noexcept;

/// E of one lamp from its block (fogLightCoefficients; `dipole`: it holds D, fogLightFloats = 16)
/// on an element of unit normal (nx, ny, nz), camera-relative world frame, clamped at 0.
[[nodiscard]] inline float fogLightIrradiance(const float* s, bool dipole, float mu, float nx, float ny,
                                              float nz) noexcept {
  float b[4], bd[4];
  fogLightBasis(mu, b, bd);
  float e = 0.0f;
  for (int q = 0; q < 4; ++q) {
    e += b[q] * s[q];
    if (dipole) {
      const float* d = s + 4 + 3 * q;
      e += bd[q] * (d[0] * nx + d[1] * ny + d[2] * nz);
    }
  }
  return e > 0.0f ? e : 0.0f;
}

}  // namespace fogbeam
