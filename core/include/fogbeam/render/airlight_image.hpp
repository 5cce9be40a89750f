// fogbeam — the airlight layer of a frame: the in-scattered luminance of every lamp along every
// pixel's ray, up to the visible surface given by the surface pass's distance buffer.
//
// Adaptive subsampling (the paper's "coherence" idea): the image is covered by blocks of
// `coarse_step` pixels whose corners are evaluated; a block is filled by bilinear
// interpolation when its evaluated centre matches the corners' bilinear prediction within the
// tolerances, its distance buffer has no edge, and no lamp projects into it; otherwise it is
// split in four, down to single pixels. A block of 4 px or less whose only fault is a distance
// edge (a silhouette) is filled layer by layer: each pixel from the corners whose distance is
// within 10 % of its own (along nearby rays the airlight is the same function of direction
// whatever surface stops them), the centre checked against that prediction, pixels without such
// a corner evaluated. The coarse grid's corners are evaluated first, as one
// batch over all threads; then the image is cut into tiles of 128 pixels (a multiple of the
// coarse step), each refined, interpolated and written by one thread with its memory in cache:
// the distance-edge mask of the tile, level by level the new sample points as one SIMD batch
// and the block tests, the fill of the leaves, and the tile's rows streamed to the image. A
// tile owns its pixels; points on the border it shares with the next tile are evaluated by
// both (a few per cent more evaluations, no shared writes).
// `full` forces per-pixel evaluation, tile by tile. Buffers are sized once per image and tile
// size, so frames of the same size do not allocate.
//
// Fast path (accurate method, airlight_kernels.hpp): isotropic lamps are evaluated from the
// phase function's F table (sky pixels from a per-lamp table over the angle to the lamp) and
// vehicle-mounted lamps from view tables (built once: the lamp is fixed to the eye; lamps of
// one colour summed into one table), by Highway kernels. Measured and spot lamps fixed in the
// world or on other vehicles go per pixel through the pencil integrator (airlight_pencil.hpp)
// or per ray (MovingLampPath). With the pencil, the spokes a frame's rays read are planned and
// sampled on all threads before the pixels (adaptively: PencilOptions::spoke_tolerance); the
// coarse grid evaluates them at a lattice twice as coarse and interpolates them where their own
// light is smooth there (SubsamplingOptions::moving_lattice); and in a block split for another
// reason a moving lamp whose own light is smooth there is interpolated instead of evaluated,
// across a distance edge in the centre's layer only (moving_layers). Each such test grants the
// moving lamps together a quarter of the block tolerance, lamps whose light deviates least from
// the interpolation first; AirlightImage::moving_evaluated counts the pairs evaluated.
//
// Thread-safety: one evaluate() at a time per AirlightImageEvaluator.
#pragma once

#include <fogbeam/physics/airlight.hpp>
#include <fogbeam/physics/airlight_bound.hpp>
#include <fogbeam/physics/airlight_pencil.hpp>
#include <fogbeam/render/lamp_map.hpp>
#include <fogbeam/render/airlight_kernels.hpp>
#include <fogbeam/render/surface.hpp>
#include <fogbeam/scene/scene.hpp>
#include <fogbeam/util/result.hpp>
#include <fogbeam/util/thread_pool.hpp>

#include <cstddef>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace fogbeam {

struct SubsamplingOptions {
  bool full = false;          ///< evaluate every pixel
  /// Initial block size in pixels (≥ 2), or 0: chosen from the camera, 16 px where 16 px span
  /// at most 0.8° (1280 px and more across a 60° view), else 8. Interpolation error follows
  /// the blocks' angular size, which the airlight's structure (beam edges, glow) sets.
  int coarse_step = 0;
  double rel_tolerance = 0.005; ///< centre vs bilinear prediction: |Δ| ≤ rel · L + abs (luminance sum)
  double abs_tolerance_cd_m2 = 1e-3;
  double depth_edge_rel = 0.02;  ///< edge: the second difference of 1/d across a pixel exceeds this fraction of the largest 1/d
  /// Edges beyond the distance where the fog's transmittance e^{−K_t d} falls below this are
  /// ignored (what lies behind them is dimmed below it); 0 keeps every edge.
  double edge_transmittance = 0.005;
  int lamp_guard_px = 2;      ///< blocks within this many pixels of a lamp's image are split
  /// Moving lamps (pencil path) on a lattice twice as coarse as the coarse grid: evaluated at
  /// the corners and centres of super-cells of 2 × 2 coarse blocks, and interpolated over a
  /// super-cell where its centre matches its corners (the block test, with what the lamp is granted of
  /// the tolerance), no lamp is imaged in it and its coarse nodes and block centres lie in one
  /// distance layer. false: every coarse node and block centre evaluates every moving lamp.
  bool moving_lattice = true;
  /// With moving_lattice, a second level first: cells of 4 × 4 coarse blocks evaluated at their
  /// corners and centres only, and the first level's nodes inside a cell interpolated from its
  /// corners where the same test passes at its centre (no lamp imaged within lamp_guard_px + 4
  /// coarse steps of it, its 25 nodes and 16 block centres in one distance layer). 1: the first
  /// level alone (every super-cell's corners and centre evaluated).
  int moving_lattice_levels = 2;
  /// Moving lamps in a block split across a distance edge (a silhouette): interpolated in the
  /// centre's layer where the lamp's value there matches the prediction from the corners in that
  /// layer (the block test, with what the lamp is granted of the tolerance); pixels of other layers are
  /// evaluated. false: every pixel such a split adds evaluates every moving lamp.
  bool moving_layers = true;
};

/// How measured and spot lamps that move relative to the eye (fixed in the world or on other
/// vehicles) are evaluated by the fast path (docs/airlight.md, "Moving lamps"):
///  * PerRay — the accurate method per pixel (the definition; 15–25 µs per pixel and lamp for
///    a measured profile);
///  * Pencil — per pixel through PencilAirlight, whose profile samples are shared by every
///    ray in a plane through eye and lamp, and a kernel expansion per ray: 0.2–0.8 µs per
///    pixel and lamp besides the spokes (~12 µs each, shared), within 1e-3 (p95) of PerRay;
///  * Map — per frame, each lamp's own adaptive table of pencil columns over the image
///    (render/lamp_map.hpp), read per pixel at the pixel's own distance; the pencil per ray
///    only at the lamp's image and where the table cannot follow the lamp's pattern.
/// (Uniform view tables rebuilt every frame were tried and dropped: bilinear over directions
/// in distance, they blur the sharp pattern around an oncoming lamp's image, 16 % p95 at 0.5°.)
enum class MovingLampPath { PerRay, Pencil, Map };
/// Where the service and `fogbeam render` keep view tables by default (`table_cache = "auto"`):
/// $XDG_CACHE_HOME/fogbeam, else $HOME/.cache/fogbeam; empty when neither is set (no cache).
[[nodiscard]] std::string defaultTableCacheDir();
/// The directory a `table_cache` setting names: "off" → empty (no cache), "auto" →
/// defaultTableCacheDir(), anything else → itself.
[[nodiscard]] std::string tableCacheDirFor(std::string_view setting);

/// "per-ray", "pencil", "map" (the names of config keys and command-line options).
[[nodiscard]] std::optional<MovingLampPath> parseMovingLampPath(std::string_view name) noexcept;
[[nodiscard]] std::string_view toString(MovingLampPath path) noexcept;

/// The accurate method's table-and-SIMD path (airlight_kernels.hpp).
struct FastPathOptions {
  bool enabled = true;              ///< false: every lamp through the per-ray evaluator
  double view_table_step_deg = 0.2; ///< view-table direction spacing at the image centre, degrees
  int view_table_distances = 48;    ///< view-table distance nodes per direction
  /// View tables' rays through a PencilAirlight of the lamp from the eye (every spoke sampled
  /// once per build) instead of the per-ray accurate method: the same integral, several times
  /// faster to build (docs/airlight.md, "View tables from the pencil"). false: per ray.
  bool pencil_view_tables = true;
  /// Measured or spot lamps fixed in the world or on other vehicles (street lamps, traffic):
  /// their pose relative to the eye changes whenever either moves, so nothing can be
  /// tabulated once for them.
  MovingLampPath moving_lamps = MovingLampPath::Pencil;
  PencilOptions pencil_options{};
  LampMapOptions lamp_map_options{};  ///< MovingLampPath::Map
  /// Moving lamps are left out where they cannot matter: the most, in cd/m² per channel, that the
  /// lamps left out add to any pixel together. Each of the frame's N moving lamps that is on gets
  /// cutoff / N; outside the cone about its image where AirlightBound's bound
  /// (physics/airlight_bound.hpp) of its light falls below that share, its pixels skip it
  /// (Pencil; Map reads its map there as elsewhere), and a lamp whose cone misses the view is
  /// left out of the frame (Pencil and Map: no spokes or map, no pixels).
  /// Distant traffic in dense fog costs nothing then (docs/airlight.md, "Moving lamps that
  /// cannot matter"). 0: every moving lamp at every pixel.
  double moving_lamp_cutoff_cd_m2 = 1e-3;
  /// A budget for frames with much traffic: at most this many moving lamps (after the cutoff
  /// above) are evaluated in a frame; the rest, those whose bound K_s I_max e^{−K_t D}/D
  /// (AirlightBound::factor × their largest colour weight) is smallest, are left out of it and
  /// counted (AirlightImage::moving_dropped). Unlike the cutoff this loses light without a bound:
  /// it trades accuracy for a frame time that does not grow without limit. 0: no budget.
  int max_moving_lamps = 0;
  /// Directory where vehicle lamps' view tables are kept between runs, keyed by everything they
  /// depend on (the profile's data, the lamp's pose in the camera frame, the frustum, the fog,
  /// these options and the code's version): a second start with the same rig, view and fog loads
  /// them instead of building them (seconds). Empty (default): no cache.
  std::string table_cache_dir;
};

/// Airlight per pixel and channel (cd/m²), and how many pixels were evaluated.
struct AirlightImage {
  int width = 0, height = 0;
  std::vector<float> rgb;        ///< 3 per pixel, row 0 at the top
  std::size_t evaluated = 0;     ///< rays evaluated (the rest interpolated; tile borders count twice)
  double seconds = 0.0;          ///< wall time of the last evaluate(), table builds included
  double table_seconds = 0.0;    ///< part of `seconds` spent (re)building view and sky tables
  std::size_t view_tables_loaded = 0;  ///< vehicle lamps whose view tables came from the table cache this frame
  /// Rungs of the fog ladder the vehicle lamps' view tables were read from this frame
  /// (AirlightImageEvaluator::setFogLadder): 0 = the evaluator's own tables (or none), 1 = a rung
  /// at the frame's K_t, 2 = two rungs around it, blended.
  int fog_rungs = 0;
  /// Rungs read per fog through a rotation this frame (setFogLadder's maxBendingDeg): 0 = rungs
  /// made for the lamps' poses (or none), 2 = the two rungs around the lamps' bending, blended.
  int bending_rungs = 0;
  std::string table_cache_error;       ///< the last failure to write the table cache (empty: none)
  double map_seconds = 0.0;      ///< part of `seconds` spent building the moving lamps' maps (every frame)
  std::size_t map_nodes = 0;     ///< directions evaluated for those maps
  std::size_t spokes = 0;        ///< moving lamps' spokes sampled before the pixels this frame (pencil path)
  double spoke_seconds = 0.0;    ///< part of `seconds` spent planning and sampling those spokes (wall time)
  std::size_t spokes_kept = 0;   ///< spokes the frame's rays read that were kept from an earlier frame (PencilAirlight::reset)
  /// (pixel, moving lamp) pairs evaluated; the others of the evaluated pixels were interpolated
  /// lamp by lamp where that lamp's light is smooth (pencil path, subsampled)
  std::size_t moving_evaluated = 0;
  /// Moving lamps on but left out of this frame: their light is below their share of
  /// FastPathOptions::moving_lamp_cutoff_cd_m2 at every pixel of the view.
  std::size_t moving_culled = 0;
  /// Moving lamps on, within the cutoff's reach, but left out of this frame by the budget
  /// FastPathOptions::max_moving_lamps (the least bright by their bound).
  std::size_t moving_dropped = 0;
  // The stages run interleaved on all threads: thread time per stage divided by the threads
  // (equal to wall time when the threads are kept busy).
  double eval_seconds = 0.0;     ///< evaluating pixels (kernels and per-ray lamps)
  double judge_seconds = 0.0;    ///< distance edges and block tests (subsampling)
  double fill_seconds = 0.0;     ///< interpolating and writing the image (subsampling)
};

/// The view tables of a scene's vehicle lamps built for one fog: a rung of the fog ladder
/// (AirlightImageEvaluator::buildFogTables, setFogLadder; docs/airlight.md, "The fog ladder").
/// Immutable once built: shared between evaluators and threads.
struct FogTables;
/// The extinction coefficient (1/m) a rung was built for.
[[nodiscard]] double fogTablesExtinction(const FogTables& rung) noexcept;
/// Bytes its tables hold.
[[nodiscard]] std::size_t fogTablesBytes(const FogTables& rung) noexcept;
/// Why its tables could not be written to the table cache (empty: written, or no cache).
[[nodiscard]] std::string_view fogTablesCacheError(const FogTables& rung) noexcept;

class AirlightImageEvaluator {
 public:
  /// Builds one AirlightEvaluator per lamp (tables shared through the evaluators' caches).
  /// `threads` = 0: all hardware threads.
  [[nodiscard]] static Result<AirlightImageEvaluator> build(const Scene& scene, AirlightMethod method,
                                                            const AirlightOptions& options = {},
                                                            unsigned threads = 0, const FastPathOptions& fast = {});
  /// The same on an existing thread pool (evaluators built per frame must not start threads).
  [[nodiscard]] static Result<AirlightImageEvaluator> build(const Scene& scene, AirlightMethod method,
                                                            const AirlightOptions& options,
                                                            std::shared_ptr<ThreadPool> pool,
                                                            const FastPathOptions& fast = {});
  [[nodiscard]] const std::shared_ptr<ThreadPool>& pool() const noexcept { return pool_; }

  /// How evaluate() writes `out.rgb`.
  enum class Write {
    Replace,  ///< the image is this evaluator's lamps' airlight
    /// this evaluator's lamps' airlight is added to the image already there (another
    /// evaluator's lamps, same camera): one image for two sets of lamps, without a second
    /// image and a pass to sum them. An `out` of another size is replaced as with Replace.
    Add,
  };
  /// Fills `out` for the scene's camera using `surface.distance` (+inf = sky). Its figures
  /// (evaluated, seconds, spokes, …) describe this call alone, also with Write::Add.
  void evaluate(const Scene& scene, const SurfaceBuffers& surface, const SubsamplingOptions& opt, AirlightImage& out,
                Write write = Write::Replace);

  /// Takes the lamps' poses from `scene` (same lamps, same order as at build): vehicles move
  /// between frames. Tables are kept; view tables stay valid while a lamp's pose relative to
  /// the camera does not change. Errors when the lamp count differs.
  [[nodiscard]] Status setLampPoses(const Scene& scene);
  /// Switches lamp `index` (scene order) on or off for the following frames (lamp switching).
  void setLampEnabled(std::size_t index, bool on);
  /// Another fog with the same phase function, for the next evaluate(): each lamp's evaluator
  /// takes it (AirlightEvaluator::setMedium), and the tables that depend on the extinction or
  /// albedo follow at the next frame (isotropic lamps' sky tables, vehicle lamps' view tables,
  /// the pencils' per-fog state). A pencil keeps the spokes it has sampled: they depend on the
  /// lamp's profile and its pose relative to the eye, not on the fog, so a fog that changes
  /// every frame costs what a steady fog does for lamps fixed to the eye that go per pixel.
  /// Errors: an invalid medium or another phase function (build a new evaluator); the
  /// evaluator is then unchanged. Not thread-safe with evaluate().
  [[nodiscard]] Status setFog(const Medium& fog);

  /// The view tables of `scene`'s vehicle lamps (mount Vehicle, profile not isotropic; scene
  /// order) for its fog, lamp poses and camera, built on `pool` as evaluate() builds them (or
  /// loaded from fast.table_cache_dir, and stored there): one rung of a fog ladder. About a
  /// second at 1280×720 (docs/airlight.md). `enabled` (one flag per scene lamp, empty: all on):
  /// the lamps that will be on. Only those are tabulated (a frame with another lamp on does not
  /// read the rung), and the rung is merged for them (frames with fewer lamps on merge once,
  /// tens of milliseconds). Thread-safe: touches no evaluator. Errors as
  /// build()'s, or `enabled` of another size than the scene's lamps.
  [[nodiscard]] static Result<std::shared_ptr<const FogTables>> buildFogTables(const Scene& scene,
                                                                               const FastPathOptions& fast,
                                                                               std::shared_ptr<ThreadPool> pool,
                                                                               const std::vector<char>& enabled = {});
  /// The fog ladder (docs/airlight.md, "The fog ladder"): rungs that evaluate() reads instead of
  /// building when the vehicle lamps' own tables were made for another fog. A frame whose K_t
  /// lies between two rungs made for the same lamps (profiles, colours, scene order; tables for
  /// every lamp on), poses
  /// relative to the camera, frustum and albedo, at most `maxRatio` apart in K_t, reads both,
  /// weighted linearly in ln K_t (p95 2e-3 against tables at its K_t for rungs 1.2 apart); a
  /// rung at its K_t exactly is read alone. Frames that the own tables serve, or that no two
  /// rungs bracket, go on as before (the latter build). Replaces the previous set (empty: off);
  /// the rungs are kept alive by the evaluator. Not thread-safe with evaluate().
  ///
  /// `maxBendingDeg` > 0 also puts bending on the ladder (docs/airlight.md, "Bending on the
  /// ladder"): rungs made for the lamps at the frame's positions but turned, all by one rotation
  /// Q about one axis (a headlamp's bending about the vehicle's vertical), serve the frame when
  /// per fog one rung is turned each way, at most `maxBendingDeg` apart: each is read through
  /// its rotation (the table at Qᵀ·d for the ray d) and the two are blended with the weights
  /// that cancel their rotations (p95 1.5e-3 against tables at the frame's angle for rungs 1°
  /// apart, the ego's low beams). With a fog between two rungs, four rungs are read.
  void setFogLadder(std::vector<std::shared_ptr<const FogTables>> rungs, double maxRatio,
                    double maxBendingDeg = 0.0);
  /// True when evaluate() of `camera`'s view, with the lamps' current poses and fog (setFog,
  /// setLampPoses), reads every vehicle lamp's view tables without building (its own tables or
  /// the ladder's); true without vehicle lamps. What the service checks before a table frame.
  [[nodiscard]] bool viewTablesReady(const Camera& camera) const;

  /// Sum over lamps of colour × L_m for one ray (cd/m² per channel), every lamp through the
  /// per-ray evaluator of the method (no tables): the definition the fast path is tested against.
  void evaluateRay(const Ray& ray, float rgb[3]) const noexcept;

  /// Which lamps take which path, and the SIMD target in use, in words (for logs and bench).
  [[nodiscard]] std::string describe() const;
  /// Bytes held by this evaluator's fast-path tables (view tables and the F table).
  [[nodiscard]] std::size_t fastTableBytes() const noexcept;

  /// The fast path's tables and the latest frame's isotropic-lamp parameters, for running the
  /// kernels on their own (`fogbeam bench` times them per SIMD target): those of the latest
  /// evaluate(), valid until the next. `isoTable` is null without isotropic lamps; `viewTables`
  /// holds per vehicle lamp its frustum table and insets (empty tables where none was built).
  struct FastPathView {
    const kernels::IsoTable* isoTable = nullptr;
    const std::vector<kernels::IsoLamp>* isoLamps = nullptr;
    const std::vector<kernels::ViewTable>* viewTables = nullptr;
  };
  [[nodiscard]] FastPathView fastPathView() const;

  struct State;  // per-frame buffers and tables (private)

 private:
  AirlightImageEvaluator() = default;
  std::vector<AirlightEvaluator> lamps_;
  std::shared_ptr<ThreadPool> pool_;
  std::shared_ptr<State> state_;
};

}  // namespace fogbeam
