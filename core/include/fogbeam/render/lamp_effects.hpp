// fogbeam — glow and glare layers of a frame (issue 7): what single scattering misses around the
// lamps in view. Formulas and their sources: fogbeam/physics/glow.hpp; design and measurements:
// docs/airlight.md, "Beyond single scattering".
//
//  * Glow: per lamp, the multiply-scattered radiance around it as a function of the angle θ from
//    it. Two models (GlowOptions::model):
//    - Table (default): glow(θ) = K_t² f(K_t R, θ, Ω) per cd of source, f fogbeam's
//      multiple-scattering table for the fog's phase function (orders ≥ 2, estimated by path
//      tracing; fogbeam/physics/multiple_scattering.hpp; glowCurveFromTable). Every lamp that is on
//      and not hidden behind a surface glows, in the frame or not (up to θ = π), from any K_t R.
//      A phase without a shipped table (shippedMultipleScatteringTable) takes the APSF.
//    - Apsf, per visible lamp from K_t R = 1.1 (glowCurve below):
//        glow(θ) = λ · max(0, A(T, cos θ) − S₁(θ)),
//    A the Narasimhan–Nayar APSF (all orders, albedo 1) for the lamp's optical distance
//    T = K_t R and the fog's mean cosine q, S₁ the exact single scattering of the same source
//    along the sky ray at θ (the F table, albedo 1), λ fixed by energy. No double counting:
//    the airlight layer holds the single scattering exactly, the glow holds only what the other
//    orders add, and λ makes the two together carry the scattered power an isotropic source
//    sends through the sphere of radius R: with albedo 1, R² Φ[S₁ + glow] = I (1 − e^{−T}),
//    Φ[L] = 2π ∫₀^π L cos θ sin θ dθ (the direct beam carries the rest, I e^{−T}); with albedo
//    Ω < 1 the multiple part is scaled by Ω² (its lowest order). Where A < S₁ (close to the
//    lamp's image, where the truncated series is smooth but single scattering peaks as 1/θ)
//    the glow is 0. λ is reported: it measures how far the APSF's own normalisation is from
//    energy conservation at that T (≈ 1 for T ≳ 4).
//    The source intensity is the lamp's mean intensity over a cone about the direction of the
//    eye of half-angle ψ, cos ψ = max(q^T, cos 60°) (the mean cosine of a photon's direction
//    after T scatterings: multiply-scattered light reaching the eye left the lamp within about
//    ψ of the eye's direction). For an isotropic lamp it is its intensity; for an oncoming
//    low beam it takes in the beam below the cut-off, as its glow in fog does.
//    The glow fades in linearly from T = 1.1 (the series' limit) to GlowOptions::fade_in; a
//    lamp hidden behind a surface has none, and pixels whose surface is nearer than the lamp
//    get less (the glow builds up along the last half of the way): weight
//    clamp((d − R/2) / (R/2), 0, 1).
//  * Glare: per lamp in front of the eye and not hidden, the veiling luminance of the eye's
//    stray light (CIE 146:2002) for each pixel taken as the line of sight:
//    L_v = Σ E_i · f(θ_i), E_i the illuminance at the eye from lamp i's direct (attenuated)
//    light I e^{−T} / R²; added to the displayed image as disability glare is seen. The report
//    gives its value at the image centre and each lamp's E.
//
// Lamps with mount = "vehicle" (the driver's own) have no glare (the bonnet and their housings
// keep their direct light from the eye) and glow only from the tables (GlowModel::Table): their
// multiply scattered light fills the fog ahead; never hidden, light forward of the lamp only,
// occlusion weight that of any lamp (docs/airlight.md, "Glow"); over a ground of ρ > 0
// (GlowOptions) the veil of the road they light is added to the glow layer (single scattering of
// the road's light, core/src/render/ground_veil.hpp; docs/airlight.md "The ground").
//
// How the layers are filled (docs/airlight.md, "Cost of glow and glare"). Both are Σ over lamps
// of colour × weight × F_i(θ_i), F_i a 512-node radial table over √sin(θ/2) (the glow curve ×
// its source; CIE 146's L_v/E × E), weight 1 (glare) or the glow's clamp((d − R/2)/(R/2), 0, 1).
// LampEffectsPath::Fast (default): F_i exactly at a grid of nodes every 16 px (kCell) and at each
// 16 × 16 tile's centre and edge midpoints; a tile interpolates lamp i bilinearly unless the lamp's
// image is within 2 tiles or the interpolation misses those samples by more than 0.25 % of
// max(their smallest, floor) (floor: 0 for the glare, 1e-4 of the lamp's peak for the glow),
// where lamp i goes per pixel; the weight is always per pixel (d jumps at silhouettes), and a
// row segment's lamps of weight 1 (surfaces at least as far) come from one grid of partial sums
// over the lamps, nearest first; those of weight 0 are skipped. SIMD
// (Highway, lamp_effects_simd.cpp) on the pool, tile rows in parallel. Within 0.25 % of the exact
// path (every pixel, as before) on the tests' scenes; their bound is 1 %.
// LampEffectsPath::Exact: every pixel, every lamp, scalar (the reference).
// A steady scene (lamps at the same distances, same fog and size) allocates nothing per frame:
// each lamp's glow curve is kept while its distance and the fog stay.
//
// Both layers are linear cd/m² per channel (lamp colour), 3 floats per pixel, row 0 at the top.
// Thread-safety: one evaluate() at a time per LampEffects; glowCurve is reentrant.
#pragma once

#include <fogbeam/render/airlight_kernels.hpp>
#include <fogbeam/render/surface.hpp>
#include <fogbeam/scene/scene.hpp>
#include <fogbeam/util/result.hpp>
#include <fogbeam/util/thread_pool.hpp>

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace fogbeam {

class MultipleScatteringTable;

/// How LampEffects fills its layers (header comment): Fast (default) interpolates a coarse
/// grid where the layers are smooth and evaluates per pixel near the lamps' images; Exact
/// evaluates every pixel (the reference the fast layers are tested against).
enum class LampEffectsPath { Fast, Exact };

struct LampEffectsReport {
  struct Lamp {
    std::string name;
    bool visible = false;            ///< in front of the eye and not hidden behind a surface
    double distance_m = 0.0;
    double optical_distance = 0.0;   ///< K_t R
    // Luminous figures: the profile's values × the mean of the lamp's colour (1 for white), so
    // that the point lamps of an aperture (colour × weight) add up to their lamp's.
    double intensity_cd = 0.0;       ///< towards the eye
    double eye_illuminance_lx = 0.0; ///< direct light at the eye, I e^{−K_t R} / R²
    double glow_source_cd = 0.0;     ///< the glow's source: mean intensity over the cone about the eye
    double glow_peak_cd_m2 = 0.0;    ///< largest glow radiance around its image
    double glow_scale = 0.0;         ///< λ (energy match), 0 without glow
    double glow_share = 0.0;         ///< multiple / (single + multiple) scattered flux at the eye
    int apsf_terms = 0;              ///< Legendre terms summed (0: no glow, or the tables)
    bool glow_from_table = false;    ///< the glow came from the multiple-scattering tables
    bool own = false;                ///< the driver's own lamp (mount = vehicle): glow only, from the tables
  };
  std::vector<Lamp> lamps;
  double eye_illuminance_lx = 0.0;        ///< Σ over visible lamps
  double veiling_luminance_cd_m2 = 0.0;   ///< glare at the image centre
  double glow_seconds = 0.0, glare_seconds = 0.0;
  /// The glow layer holds the veil of the road lit by the driver's own lamps (a ground of ρ > 0,
  /// the tables' glow, an own lamp on; docs/airlight.md "The ground").
  bool ground_veil = false;
  /// Of glow_seconds: making the veil anew this frame (0 when kept from an earlier frame).
  double ground_veil_build_seconds = 0.0;
  /// The fast path's (tile, lamp) pairs by how each was taken (docs/airlight.md, "Cost of glow
  /// and glare"): from the kCell grid, from the tile's half-cells, per pixel. 0 on the exact path.
  struct Tiles {
    std::size_t bilinear = 0, half = 0, exact = 0;
  };
  Tiles glow_tiles, glare_tiles;
};

/// The glow of an isotropic source of 1 cd at distance R in `fog` (header comment), on the
/// angles θ_i = 2 asin((i / (nodes − 1))²), i < nodes (dense near the lamp, up to π), radians.
/// Radiances in cd/m² per cd of source intensity, albedo included (glow) or 1 (single, apsf).
struct GlowCurve {
  std::vector<double> theta;   ///< rad
  std::vector<double> glow;    ///< λ · max(0, A − S₁) × Ω² (0 where A ≤ S₁)
  std::vector<double> single;  ///< S₁: exact single scattering, albedo 1 (+inf at θ = 0)
  std::vector<double> apsf;    ///< A: N&N series, albedo 1
  double scale = 0.0;          ///< λ
  double single_flux = 0.0;    ///< R² Φ[Ω S₁] (cd): single-scattered power share through the sphere
  double multiple_flux = 0.0;  ///< R² Φ[glow] (cd)
  int terms = 0;               ///< Legendre terms of A
};
/// Errors when K_t R < Apsf::minOpticalDistance() or the series does not converge.
[[nodiscard]] Result<GlowCurve> glowCurve(const kernels::IsoTable& table, const Medium& fog, double distance_m,
                                          int nodes = 512);
/// The same nodes from a multiple-scattering table (GlowModel::Table): glow = K_t² f(K_t R, θ, Ω)
/// (orders ≥ 2, albedo included; no clamp, no energy match: scale = 1, terms 0; `single` and
/// `apsf` empty, single_flux from S₁ on every 4th node, or 0 without `withSingleFlux`: it only
/// feeds a report figure, and costs more than the rest of the curve).
[[nodiscard]] Result<GlowCurve> glowCurveFromTable(const MultipleScatteringTable& ms, const kernels::IsoTable& table,
                                                   const Medium& fog, double distance_m, int nodes = 512,
                                                   bool withSingleFlux = true);
/// R² Φ[S₁] of an isotropic source of 1 cd, albedo 1, through the sphere of radius R about it
/// (cd): a function of the optical distance T = K_t R alone (S₁ R² depends on K_t and R only
/// through it), as GlowCurve::single_flux computes it.
[[nodiscard]] double singleScatteredFlux(const kernels::IsoTable& table, double opticalDistance, int nodes = 512);
/// Irradiance (lux per cd of source intensity) that the fog's scattered light of an isotropic
/// source at distance R brings to a surface element whose normal makes the angle i with the
/// direction to the source (cos i = `cosIncidence`, which may be ≤ 0: the element faces away):
/// E = ∫ L(θ) max(0, ω·n) dω over the sphere, L the radiance arriving from direction ω at the
/// angle θ from the source, order 1 exactly (the F table) and orders ≥ 2 from `ms`, both with
/// the albedo. Infinite fog: nothing blocks or reflects the light (a road absorbs part of the
/// diffuse light: `fogbeam validate --path-tracer` prints by how much). Reentrant.
struct ScatteredIrradiance {
  double single = 0.0;    ///< lux per cd, order 1
  double multiple = 0.0;  ///< lux per cd, orders ≥ 2
};
[[nodiscard]] Result<ScatteredIrradiance> scatteredIrradiance(const MultipleScatteringTable& ms,
                                                             const kernels::IsoTable& table, const Medium& fog,
                                                             double distance_m, double cosIncidence, int nodes = 512);
/// Mean intensity of `lamp` (cd) over each annulus η ∈ [edges[k], edges[k+1]] (radians) about the
/// direction from the lamp to `eye`, k < bins (the multiple-scattering tables' emission bins).
/// `frontOnly`: directions behind the lamp's photometric axis (lamp-frame x < 0) count as dark
/// (the driver's own lamps: housing and car body take what a file gives backwards).
/// `bandMeans` (null: not wanted): per annulus k the mean of each of its kGlowBands bands
/// uniform in cos η, at bandMeans[k · kGlowBands + b] (b = 0 nearest η = edges[k]). Annuli at
/// least 10° wide are summed over cells of ~1.5° of the profile's direction sphere (its mean
/// intensity per cell, computed once per profile and kept while a lamp holds it: ~18 000 cells
/// of 16 look-ups, ~25 ms), each cell in the annulus and band of its centre, so that a
/// beam of a few degrees counts with its solid angle wherever it lies; narrower ones (about the
/// direction to the eye or its opposite) are sampled as annulusMeans does, with azimuths at most
/// 1.5° apart. Thread-safe.
void glowAnnulusMeans(const Lamp& lamp, const Vec3& eye, const double* edges, std::size_t bins, double* out,
                      bool frontOnly = false, double* bandMeans = nullptr);
/// Bands per emission bin in glowAnnulusMeans (equal solid angles).
inline constexpr int kGlowBands = 4;
/// A profile's mean intensity on ~18 000 cells of ~1.5° of its direction sphere (lamp frame),
/// which glowAnnulusMeans sums for annuli at least 10° wide (~25 ms to make: 16 look-ups a cell).
struct ProfileSphereCells;
[[nodiscard]] std::shared_ptr<const ProfileSphereCells> profileSphereCells(const Profile& profile);
/// The same, shared: kept while anyone holds `profile` (the 16 last made kept regardless), so the
/// glow and the fog light's maps of one lamp file make its cells once. Thread-safe.
[[nodiscard]] std::shared_ptr<const ProfileSphereCells> sharedProfileSphereCells(
    const std::shared_ptr<const Profile>& profile);
/// glowAnnulusMeans about the lamp-frame unit direction `axis` of `profile`, from its `cells`
/// (null: the wide annuli stay 0), with (harmonic not null) each annulus' first azimuthal
/// harmonic as annulusMeans gives it (from the cells for the wide annuli: Σ I Ω ê / Σ Ω, ê from
/// each cell's centre), kGlowBands bands for the sampled narrow annuli. ~35–85 µs with cells of a headlamp (`fogbeam/render/fog_light.hpp`'s
/// AnnulusMeanMap calls it per node). Thread-safe.
void cellAnnulusMeans(const Profile& profile, const ProfileSphereCells* cells, const Vec3& axis, const double* edges,
                      std::size_t bins, double* out, bool frontOnly = false, double* bandMeans = nullptr,
                      Vec3* harmonic = nullptr);
/// The same about the lamp-frame unit direction `axis` of `profile`: 4 bands uniform in cos η ×
/// 24 azimuths per annulus, `narrowBands` bands for annuli narrower than 10°. `harmonic` (null:
/// not wanted): per annulus the first azimuthal harmonic Ī₁ (cd, a lamp-frame vector
/// perpendicular to `axis`) of I ≈ Ī + Ī₁ · ê, ê the unit vector of the azimuth about the axis:
/// which side of the axis the light leaves on (fogbeam/render/fog_light.hpp). `bandMeans`
/// (null: not wanted; only with narrowBands = 4): per annulus its 4 bands' means, as
/// glowAnnulusMeans. `azimuths`: samples per band (24 are 15° apart on an annulus at 90°: a beam
/// a few degrees wide there is over- or under-counted; glowAnnulusMeans sums cells instead).
void annulusMeans(const Profile& profile, const Vec3& axis, const double* edges, std::size_t bins, double* out,
                  bool frontOnly = false, int narrowBands = 4, Vec3* harmonic = nullptr, double* bandMeans = nullptr,
                  int azimuths = 24);
/// How the light that reaches one point from one emission bin is spread within the bin: the
/// multiple-scattering table gives each bin's share s_k of the light at a node (T, θ), not where
/// in the bin it left the lamp, and a bin 40° wide (60–100°) holds light that left at 60°, which
/// reaches the eye through smaller deflections, and at 100°, which needs larger ones. The share
/// per unit solid angle, s_k / (cos η_k − cos η_{k+1}), is taken as a sample at the bin's middle
/// (in cos η) of a function of η whose logarithm is linear between neighbouring bins' middles
/// (extrapolated from the nearest two in the first and last bins); each bin's kGlowBands bands
/// (uniform in cos η) get that function's value at their middle, scaled so that the bands' mean
/// is 1. A lamp uniform over a bin (an isotropic lamp: every bin) is weighted exactly as by the
/// bin's share alone; a narrow beam at one side of a bin (a high beam seen from the side, at
/// η ≈ 90° in the 60–100° bin) by the part of the bin it lights. Bins whose share or a
/// neighbour's is 0 keep weight 1 in every band. `shares`: the bins' shares at one node
/// (MultipleScatteringTable::emissionShares), `edges` the bins' bins + 1 edges (radians);
/// writes bins × kGlowBands weights. Reentrant.
void emissionBandWeights(const double* shares, const double* edges, std::size_t bins, double* weights);
/// The glow's source intensity of `lamp` seen from `eye` (header comment): the mean of I over
/// the cone of half-angle ψ about the direction from the lamp to the eye, cos ψ = max(q^T, ½).
[[nodiscard]] double glowSourceIntensity(const Lamp& lamp, const Vec3& eye, double opticalDistance, double q);

class LampEffects {
 public:
  /// `threads`: the pool the per-pixel passes run on (shared with the airlight evaluator).
  [[nodiscard]] static Result<LampEffects> build(const Scene& scene, const GlowOptions& glow, const GlareOptions& glare,
                                                 std::shared_ptr<ThreadPool> pool);
  /// Fills `glow` and `glare` (3 floats per pixel; cleared when the effect is off) for the
  /// scene's camera, lamps and fog, with the surface pass's distances. The scene may change
  /// from frame to frame (camera, fog, lamps moving, lamps added: they start switched on);
  /// setLampEnabled indices refer to the scene's lamp order.
  void evaluate(const Scene& scene, const SurfaceBuffers& surface, std::vector<float>& glow, std::vector<float>& glare,
                LampEffectsReport& report);
  /// Switches lamp `index` (scene order) on or off for the following frames.
  void setLampEnabled(std::size_t index, bool on);
  /// Fast (default) or Exact (every pixel per lamp, as before the coarse grid) for the
  /// following frames.
  void setPath(LampEffectsPath path) noexcept { path_ = path; }
  [[nodiscard]] LampEffectsPath path() const noexcept { return path_; }
  [[nodiscard]] bool glowEnabled() const noexcept { return glow_.enabled; }
  [[nodiscard]] bool glareEnabled() const noexcept { return glare_.enabled; }

  struct Tables;  // per-frame tables (private)

 private:
  LampEffects() = default;
  GlowOptions glow_;
  GlareOptions glare_;
  LampEffectsPath path_ = LampEffectsPath::Fast;
  std::shared_ptr<ThreadPool> pool_;
  std::vector<char> enabled_;
  std::shared_ptr<Tables> tables_;
};

/// The SIMD kernels of the fast path (lamp_effects_simd.cpp, Highway, dispatched at run time);
/// internal to LampEffects, declared here as the per-target half of this header.
namespace lamp_fx {
inline constexpr int kNodes = 512;  ///< radial table nodes over u = √sin(θ/2), u_i = i / (kNodes − 1)
inline constexpr int kCell = 16;    ///< coarse grid step, pixels (nodes at pixel centres 8c + ½, 8r + ½)

struct KernelLamp {
  float e[3] = {1, 0, 0};                 ///< lamp direction, camera frame (+x forward, +y left, +z up)
  float color[3] = {0, 0, 0};             ///< layer units per table unit, per channel
  /// The glow's weight per pixel, clamp((d − weight_from) × weight_scale, 0, 1), d the pixel's
  /// surface distance: 0 up to weight_from, 1 from weight_to = weight_from + 1/weight_scale (m).
  float weight_from = 0.0f, weight_to = 0.0f, weight_scale = 0.0f;
  const float* table = nullptr;           ///< kNodes values (+1 readable past the last: not read)
  const float* grid = nullptr;            ///< the table at the grid's nodes, gw × gh, row-major
  /// The table at each cell's top-edge midpoint, left-edge midpoint and centre (indexed by the
  /// cell's top-left node, gw × gh): with the grid, the 3 × 3 nodes of the cell's half-cells.
  const float* hmid = nullptr;
  const float* vmid = nullptr;
  const float* centre = nullptr;
};

/// Per (tile, lamp): how the fast path takes the lamp in that tile.
enum TileMode : std::uint8_t {
  kTileBilinear = 0,  ///< bilinear over the kCell grid (its share of the prefix sums)
  kTileExact = 1,     ///< the table per pixel
  kTileHalf = 2,      ///< bilinear over the tile's four half-cells (kCell / 2 px: the grid's 3 × 3 nodes of the tile)
};

/// One pixel row j of a layer: Σ over lamps of colour × (weight) × table(θ), from the grid's
/// bilinear interpolation, per pixel in the tiles whose flag for a lamp is set.
struct LayerRow {
  const KernelLamp* lamps = nullptr;
  int nLamps = 0;
  /// Partial sums of colour × grid over the first m lamps, 3 planes gw × gh each: with
  /// `prefix_all` for m = 1 … nLamps at prefix + (m − 1)·3·gw·gh (the lamps then sorted by
  /// distance, nearest first: a segment's lamps of weight 1 are a prefix of them), else only
  /// m = nLamps, at `prefix` (glare: weights 1). Sorted by weight_to.
  const float* prefix = nullptr;
  bool prefix_all = false;
  /// The lamps' weight_to and weight_from, contiguous, with kCell readable entries past the
  /// last lamp (a vector loaded from any lamp's index; glow: read only where `distance` is set),
  /// and whether weight_from ascends with them (then the lamps a segment skips for d ≤ from are
  /// a suffix).
  const float* weight_to = nullptr;
  const float* weight_from = nullptr;
  bool from_sorted = false;
  const std::uint8_t* exact = nullptr;   ///< (gw − 1) × (gh − 1) tiles × nLamps TileMode flags
  const std::int32_t* fine_first = nullptr;  ///< per tile: its first lamp whose flag is not kTileBilinear
  int gw = 0, gh = 0, width = 0, j = 0;
  float f = 1.0f, cx = 0.0f, cy = 0.0f;  ///< focal length and principal point, pixels
  const float* distance = nullptr;       ///< row j's surface distances (glow), nullptr: weights 1
  float* out = nullptr;                  ///< row j, 3 floats per pixel
  /// The veil of the road the driver's own lamps light (glow; nullptr: none): its nodes blended at
  /// row j's y, `veil_nx` of them evenly over the row, added per pixel as
  /// colour × val × min(1, min(1, hk d) / max(rampU, 10⁻³)), rampU = min(1, hkh |r| / max(−r_z, 10⁻¹²))
  /// with r = (f, cx − x, cy − y) in the camera frame and r_z = zf + zu (cy − y) + zl (cx − x)
  /// its world z (LampEffects' addVeil, the exact path's, in the same float arithmetic).
  const float* veil_line = nullptr;
  int veil_nx = 0;
  float veil_color[3] = {0, 0, 0};
  float veil_zf = 0.0f, veil_zl = 0.0f, veil_zu = 0.0f, veil_hk = 0.0f, veil_hkh = 0.0f;
};

/// Each of `nLamps` lamps' tables at the `count` points (x0 + k dx, y), pixel-centre coordinates:
/// lamp l's values at out + l · stride (the pixels' rays are computed once for all lamps).
void radialRow(const KernelLamp* lamps, int nLamps, std::size_t stride, float f, float cx, float cy, float x0,
               float dx, float y, int count, float* out);
/// The lamp's table at the `count` points (x[k], y[k]), pixel-centre coordinates.
void radialPoints(const KernelLamp& lamp, float f, float cx, float cy, const float* x, const float* y, int count,
                  float* out);
void fillRow(const LayerRow& row);
}  // namespace lamp_fx

}  // namespace fogbeam
