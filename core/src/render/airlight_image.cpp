#include <fogbeam/render/airlight_image.hpp>

#include "render/view_table_cache.hpp"

#include <fogbeam/physics/airlight_pencil.hpp>
#include <fogbeam/render/airlight_kernels.hpp>

#include <algorithm>
#include <atomic>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <limits>
#include <optional>
#include <sstream>

namespace fogbeam {

namespace {

// The coarse grid's corners are evaluated in chunks of this many pixels (a multiple of 64, so
// every chunk is whole SIMD vectors of any width: kernels::paddedSize).
constexpr std::size_t kChunk = 2048;
// The image is cut into tiles of about this many pixels square (a multiple of the coarse step),
// each refined, interpolated and written by one thread with its memory in cache (about 300 KB).
// Measured on the bench scene at 1920×1080: 32 px 10.8 ms, 64 px 8.3 ms, 128 px 7.8 ms, 256 px
// 8.5 ms (per-tile set-up against cache misses).
constexpr int kTile = 128;
// View tables per vehicle lamp: the frustum table and two insets around the lamp's image.
constexpr std::size_t kTablesPerLamp = 3;

struct Block {
  int i0, j0, i1, j1;  // inclusive corner pixels (image coordinates), all four already evaluated
};

// One thread's working memory, sized once per image and tile size (no allocation per frame).
struct Scratch {
  // A batch of pixels (padded structure of arrays) and, per entry, its place in the tile.
  std::vector<float> x, y, d, r, g, b;
  std::vector<std::uint32_t> slot;
  std::size_t n = 0;
  // The pixels of a batch inside one disc (view-table rings, per-ray guards), compacted.
  std::vector<float> sx, sy, sd, sr, sg, sb;
  std::vector<std::uint32_t> sidx;
  // The tile's closed region (its pixels and the next tile's first column and row), `stride`
  // floats per row: airlight planes, evaluated flags; rows of 1/d with a one-pixel halo (qStride
  // per row, entry 1 = the halo column left of the region) and their distance-edge bits.
  std::size_t stride = 0, qStride = 0, edgeWords = 0;
  std::vector<float> pr, pg, pb;
  std::vector<std::uint8_t> done;
  std::vector<float> q;
  std::vector<std::uint64_t> edges;
  std::vector<Block> cur, next, leaves, layered;
  std::vector<std::pair<double, double>> tileLamps;  // lampPixels whose guard reaches the tile
  std::vector<kernels::FillBlock> fill;
  // Moving lamps interpolated lamp by lamp (FrameCtx::nq > 0): per batch entry, nq values of
  // white L_m (cd/m²), NaN where the lamp is to be evaluated (filled in by evaluateBatch) when
  // `mlActive`; per tile pixel, nq values as for the planes above (NaN: not known yet).
  std::vector<float> ml, pml;
  bool mlActive = false;
  // evaluateBatch adds only the moving lamps (pencil path) of `ml`: the coarse lattice's second
  // pass (evaluateCoarseGrid), whose pixels have every other lamp already.
  bool movingOnly = false;
  // grantBudget's per-lamp working memory (FrameCtx::nq entries).
  std::vector<float> dev;
  std::vector<std::uint32_t> order;
  std::vector<std::uint8_t> grant;
  // Figures of this frame (thread time).
  std::size_t evaluated = 0, movingEvaluated = 0;
  double evalSeconds = 0.0, judgeSeconds = 0.0, fillSeconds = 0.0;
};

// Everything a view table depends on besides the lamp's profile: rebuilt when any changes.
struct ViewKey {
  Vec3 lampInCamera{0.0};
  Mat3 lampAxesInCamera{1.0};
  double fovX = 0.0, aspect = 0.0;
  // Principal point as fractions of width and height (0.5, 0.5 when centred): with fovX and
  // aspect it fixes the frustum in tangent space, hence the table's window.
  double principalX = 0.5, principalY = 0.5;
  double kt = 0.0, albedo = 0.0;
  // Equal up to rounding: a moving vehicle recomputes the lamp's camera-frame pose from world
  // poses every frame (R^T R ≠ I in the last bits), which must not rebuild the tables.
  [[nodiscard]] bool sameAs(const ViewKey& o) const noexcept {
    constexpr double kTol = 1e-7;  // metres and unit-vector components
    for (int i = 0; i < 3; ++i) {
      if (std::abs(lampInCamera[i] - o.lampInCamera[i]) > kTol) return false;
      for (int j = 0; j < 3; ++j)
        if (std::abs(lampAxesInCamera[i][j] - o.lampAxesInCamera[i][j]) > kTol) return false;
    }
    return fovX == o.fovX && aspect == o.aspect && principalX == o.principalX && principalY == o.principalY &&
           kt == o.kt && albedo == o.albedo;
  }
};

}  // namespace

std::string defaultTableCacheDir() {
  if (const char* x = std::getenv("XDG_CACHE_HOME"); x && *x) return (std::filesystem::path(x) / "fogbeam").string();
  if (const char* h = std::getenv("HOME"); h && *h) return (std::filesystem::path(h) / ".cache" / "fogbeam").string();
  return {};
}

std::string tableCacheDirFor(std::string_view setting) {
  if (setting == "off") return {};
  if (setting == "auto") return defaultTableCacheDir();
  return std::string(setting);
}

std::optional<MovingLampPath> parseMovingLampPath(std::string_view name) noexcept {
  if (name == "per-ray") return MovingLampPath::PerRay;
  if (name == "pencil") return MovingLampPath::Pencil;
  if (name == "map") return MovingLampPath::Map;
  return std::nullopt;
}

std::string_view toString(MovingLampPath path) noexcept {
  switch (path) {
    case MovingLampPath::PerRay: return "per-ray";
    case MovingLampPath::Pencil: return "pencil";
    case MovingLampPath::Map: return "map";
  }
  return "?";
}

struct AirlightImageEvaluator::State {
  AirlightMethod method = AirlightMethod::Accurate;
  FastPathOptions fast;
  // Lamp routing (indices into lamps_).
  std::vector<std::size_t> isoLamps, viewLamps, rayLamps, pencilLamps;
  // Per pencilLamps entry: the integrator for this frame's eye and lamp pose, and that pose.
  std::vector<std::optional<PencilAirlight>> pencils;
  struct PencilKey {
    const AirlightEvaluator* lamp = nullptr;
    Vec3 eye{0.0}, position{0.0};
    Mat3 axes{1.0};
    double kt = 0.0, albedo = 0.0;  // the fog (setFog): a pencil's per-fog state follows it
  };
  std::vector<PencilKey> pencilKeys;
  std::vector<float> pencilLum;  // per pencilLamps entry: r + g + b of its colour (block tests)
  // Moving lamps that cannot matter (FastPathOptions::moving_lamp_cutoff_cd_m2): the phase
  // function's bound, and per pencilLamps entry its peak intensity × largest colour weight
  // (cd), then per frame the eye→lamp direction (world), the cosine of its cone (pixels whose
  // ray has dot(ray, dir) ≤ cullCos skip the lamp; −2: none) and whether the whole lamp is out.
  std::optional<AirlightBound> bound;
  std::vector<double> pencilPeak;
  std::vector<Vec3> cullDir;
  std::vector<double> cullCos;
  std::vector<char> culled;
  std::size_t culledCount = 0, droppedCount = 0;
  std::vector<std::pair<double, std::size_t>> ranked;  // the budget's ranking (per frame, kept)
  // Stage "sample spokes": per frame, which spokes of each pencil its rays read, and the
  // (pencil, spoke) pairs handed to the threads (memory kept between frames).
  std::vector<int> gridSpokes;
  std::vector<char> spokeMask;
  std::vector<int> spokeCover;     // difference array of the azimuths read (sampleSpokes)
  std::vector<char> spokeDiffers;  // per spokeIntervals entry: its middle is not the blend of its ends
  std::vector<std::pair<std::size_t, int>> spokeJobs;
  // The adaptive plan's open intervals [a, a + w] of pencil q (PencilAirlight::coarseStep()).
  struct SpokeInterval {
    std::size_t q;
    int a, w;
  };
  std::vector<SpokeInterval> spokeIntervals, nextIntervals;
  // MovingLampPath::Map: per pencilLamps entry, the lamp's map of this frame, and the frame's
  // distance edges they share.
  std::vector<LampMap> maps;
  DepthEdges depthEdges;
  // Table cache (FastPathOptions::table_cache_dir): lamps loaded this frame, the last write error.
  std::size_t tablesLoaded = 0;
  std::string tableCacheError;
  double mapSeconds = 0.0;
  std::size_t mapNodes = 0;
  std::shared_ptr<const kernels::IsoTable> isoTable;
  // Per vehicle lamp v: viewTables[kTablesPerLamp·v] covers the frustum except a hole around
  // the lamp's image, the next ones (empty when the lamp is not in front) finer rings inside
  // it, and rayGuards[v] the last few pixels, evaluated per ray.
  std::vector<kernels::ViewTable> viewTables;
  struct RayGuard {
    double a = 0.0, b = 0.0, r2 = -1.0;  // tangent-plane centre and squared radius
  };
  std::vector<RayGuard> rayGuards;
  std::vector<ViewKey> viewKeys;
  std::vector<bool> viewValid;
  // Frustum tables of enabled vehicle lamps of one colour summed into one (read with one set
  // of gathers instead of one per lamp), rebuilt when a member's table or the enabled set
  // changes; mergedFrom[m] lists the vehicle lamps (viewLamps entries) summed into merged[m].
  std::vector<kernels::ViewTable> merged;
  std::vector<std::vector<std::size_t>> mergedFrom;
  std::vector<char> mergedEnabled;  // viewEnabled when the merged tables were made
  bool mergedValid = false;
  // Every view-table lookup of this frame: a table, how it is applied, and whether it covers the
  // whole image (else only the disc (a, b, r²) of the tangent plane, where pixels are compacted).
  struct TableUse {
    const kernels::ViewTable* table = nullptr;
    kernels::ViewTableUse use;
    bool whole = true;
    double a = 0.0, b = 0.0, r2 = 0.0;
  };
  std::vector<TableUse> tableUses;
  // The per-ray guard discs this frame reads: rayGuards, or a rung's (setFogLadder).
  std::vector<RayGuard> frameGuards;
  // The fog ladder (setFogLadder), sorted by K_t, and the merged tables of the rungs read lately
  // (per rung and set of enabled lamps; a fog ramp reads each rung for several frames).
  std::vector<std::shared_ptr<const FogTables>> ladder;
  double ladderMaxRatio = 1.0;
  struct RungMerge {
    const FogTables* rung = nullptr;
    std::vector<char> enabled;
    std::vector<kernels::ViewTable> merged;
    std::vector<TableUse> uses;
    std::uint64_t lastUse = 0;
  };
  double ladderMaxBendingRad = 0.0;
  std::array<RungMerge, 5> rungMerges;
  std::uint64_t frameCount = 0;
  int fogRungs = 0;      // AirlightImage::fog_rungs of this frame
  int bendingRungs = 0;  // AirlightImage::bending_rungs of this frame
  std::vector<kernels::IsoLamp> isoParams;  // this frame, capacity kept
  // Per isoLamps entry: its IsoSky table (2·kIsoSkyNodes floats) and what it was built for
  // (distance and extinction; rebuilt when either changes, i.e. whenever eye or lamp moves).
  std::vector<float> isoSky;
  std::vector<std::array<float, 2>> isoSkyKey;
  std::vector<std::size_t> isoSlot;  // per isoParams entry: its isoLamps entry (sky table slot)
  std::vector<char> isoSkyStale;     // per isoParams entry: its sky table is rebuilt this frame
  std::vector<char> enabled;                 // per lamp (scene order)
  std::vector<char> viewEnabled;             // per viewLamps entry, this frame

  std::vector<std::pair<double, double>> lampPixels;  // image positions of lamps in front, this frame
  // Per-thread working memory and the coarse grid's airlight (3 per corner), sized once.
  std::vector<Scratch> scratch;
  std::vector<float> coarse;
  std::vector<float> coarseMl;  // the coarse grid's moving-lamp values (FrameCtx::nq per corner)
  // Per super-cell of the moving lamps' lattice (FrameCtx::superX × superY, row-major) and moving
  // lamp: 1 where that lamp is interpolated over the super-cell (evaluateCoarseGrid).
  std::vector<std::uint8_t> superPass;
  // The same per cell of the lattice's second level (FrameCtx::hyperX × hyperY, 4 × 4 blocks).
  std::vector<std::uint8_t> hyperPass;
  std::size_t scratchBatch = 0, scratchTile = 0, scratchNq = 0;
  // The tiles' thread time in the last frame (s) and the order this frame takes them in: the
  // costliest first, so that no thread is left with a costly tile when the others are done
  // (runTiles). Sized when the tile count changes.
  std::vector<double> tileSeconds;
  std::vector<std::uint32_t> tileOrder;
};

struct FogTables {
  double kt = 0.0, albedo = 0.0;
  // Per vehicle lamp (scene order): what a frame's lamp must be to read the rung (profiles kept
  // alive, compared by address), its key (the fog's K_t aside), kTablesPerLamp tables, its guard.
  std::vector<std::shared_ptr<const Profile>> profiles;
  std::vector<glm::dvec3> colours;
  std::vector<ViewKey> keys;
  std::vector<kernels::ViewTable> tables;
  std::vector<AirlightImageEvaluator::State::RayGuard> guards;
  std::vector<char> built;  // per lamp: tabulated (the lamps on at the build), else no tables
  std::string table_cache_error;  // the table cache's write failure, if any
  // The tables merged for one set of enabled lamps (buildFogTables' `enabled`), made with the
  // rung: a frame with that set reads them without merging (a merge copies and sums whole
  // tables, tens of milliseconds at 1280×720).
  std::vector<char> mergedFor;
  std::vector<kernels::ViewTable> merged;
  std::vector<AirlightImageEvaluator::State::TableUse> uses;
};

double fogTablesExtinction(const FogTables& rung) noexcept { return rung.kt; }

std::size_t fogTablesBytes(const FogTables& rung) noexcept {
  std::size_t n = 0;
  for (const kernels::ViewTable& t : rung.tables) n += t.bytes();
  return n;
}

Result<AirlightImageEvaluator> AirlightImageEvaluator::build(const Scene& scene, AirlightMethod method,
                                                             const AirlightOptions& options, unsigned threads,
                                                             const FastPathOptions& fast) {
  return build(scene, method, options, std::make_shared<ThreadPool>(threads), fast);
}

Result<AirlightImageEvaluator> AirlightImageEvaluator::build(const Scene& scene, AirlightMethod method,
                                                             const AirlightOptions& options,
                                                             std::shared_ptr<ThreadPool> pool,
                                                             const FastPathOptions& fast) {
  AirlightImageEvaluator e;
  e.state_ = std::make_shared<State>();
  State& st = *e.state_;
  st.method = method;
  st.fast = fast;
  for (std::size_t i = 0; i < scene.lamps.size(); ++i) {
    const SceneLamp& sl = scene.lamps[i];
    auto ev = AirlightEvaluator::build(sl.lamp, scene.fog, method, options);
    if (!ev) return Error{sl.name + ": " + ev.error().message};
    e.lamps_.push_back(std::move(ev).value());
    const bool useFast = fast.enabled && method == AirlightMethod::Accurate;
    if (useFast && std::holds_alternative<IsotropicProfile>(sl.lamp.profile->model()))
      st.isoLamps.push_back(i);
    else if (useFast && sl.mount == LampMount::Vehicle)
      st.viewLamps.push_back(i);
    else if (useFast && fast.moving_lamps != MovingLampPath::PerRay) {
      st.pencilLamps.push_back(i);
      st.pencilLum.push_back(static_cast<float>(sl.lamp.color[0] + sl.lamp.color[1] + sl.lamp.color[2]));
      st.pencilPeak.push_back(sl.lamp.profile->peak().intensity_cd *
                              std::max({sl.lamp.color[0], sl.lamp.color[1], sl.lamp.color[2], 0.0}));
    } else {
      st.rayLamps.push_back(i);
    }
  }
  if (!st.isoLamps.empty()) st.isoTable = kernels::IsoTable::get(scene.fog.phase);
  if (fast.max_moving_lamps < 0)
    return Error{"fast path: max_moving_lamps = " + std::to_string(fast.max_moving_lamps) + " must be >= 0 (0: no budget)"};
  if (!(fast.moving_lamp_cutoff_cd_m2 >= 0.0 && std::isfinite(fast.moving_lamp_cutoff_cd_m2)))
    return Error{"fast path: moving_lamp_cutoff_cd_m2 = " + std::to_string(fast.moving_lamp_cutoff_cd_m2) +
                 " must be finite and >= 0"};
  if (!st.pencilLamps.empty()) {
    st.bound.emplace(scene.fog.phase);
    // The pencil's options are checked here, once: an integrator built per frame must not fail.
    if (Status v = PencilAirlight::validate(fast.pencil_options); !v) return Error{"fast path: " + v.error().message};
    if (fast.moving_lamps == MovingLampPath::Map)
      if (Status v = LampMap::validate(fast.lamp_map_options); !v) return Error{"fast path: " + v.error().message};
  }
  st.viewTables.resize(kTablesPerLamp * st.viewLamps.size());
  st.rayGuards.resize(st.viewLamps.size());
  st.viewKeys.resize(st.viewLamps.size());
  st.viewValid.assign(st.viewLamps.size(), false);
  st.enabled.assign(scene.lamps.size(), 1);
  st.viewEnabled.assign(st.viewLamps.size(), 1);
  e.pool_ = std::move(pool);
  return e;
}

Status AirlightImageEvaluator::setLampPoses(const Scene& scene) {
  if (scene.lamps.size() != lamps_.size())
    return Error{"setLampPoses: the scene has " + std::to_string(scene.lamps.size()) + " lamps, the evaluator " +
                 std::to_string(lamps_.size())};
  for (std::size_t i = 0; i < lamps_.size(); ++i)
    lamps_[i].setPose(scene.lamps[i].lamp.position_m, scene.lamps[i].lamp.worldFromLamp);
  return Ok{};
}

Status AirlightImageEvaluator::setFog(const Medium& fog) {
  if (Status s = fog.validate(); !s) return s.error();
  for (const AirlightEvaluator& ev : lamps_)
    if (!(phaseIdentity(ev.medium().phase) == phaseIdentity(fog.phase)))
      return Error{"setFog: another phase function needs other tables (build a new evaluator)"};
  for (AirlightEvaluator& ev : lamps_)
    if (Status s = ev.setMedium(fog); !s) return s;  // cannot fail after the checks above
  return Ok{};
}

void AirlightImageEvaluator::setLampEnabled(std::size_t index, bool on) {
  if (index < state_->enabled.size()) state_->enabled[index] = on ? 1 : 0;
}

void AirlightImageEvaluator::evaluateRay(const Ray& ray, float rgb[3]) const noexcept {
  double acc[3] = {0.0, 0.0, 0.0};
  for (const AirlightEvaluator& ev : lamps_) {
    const double l = ev.evaluate(ray);
    for (int c = 0; c < 3; ++c) acc[c] += l * ev.lamp().color[c];
  }
  for (int c = 0; c < 3; ++c) rgb[c] = static_cast<float>(acc[c]);
}

std::string AirlightImageEvaluator::describe() const {
  const State& st = *state_;
  std::ostringstream o;
  o << "method " << toString(st.method) << "; ";
  if (st.isoLamps.empty() && st.viewLamps.empty()) {
    o << "per-ray evaluation for all " << lamps_.size() << " lamps";
  } else {
    o << st.isoLamps.size() << " isotropic lamp(s) by F table, " << st.viewLamps.size()
      << " vehicle lamp(s) by view table, " << st.pencilLamps.size() << " moving lamp(s) by "
      << (st.fast.moving_lamps == MovingLampPath::Map ? "lamp map, " : "pencil, ")
      << st.rayLamps.size() << " per ray; SIMD target "
      << kernels::activeTarget();
  }
  return o.str();
}

AirlightImageEvaluator::FastPathView AirlightImageEvaluator::fastPathView() const {
  const State& st = *state_;
  FastPathView v;
  v.isoTable = st.isoTable.get();
  v.isoLamps = &st.isoParams;
  v.viewTables = &st.viewTables;
  return v;
}

std::size_t AirlightImageEvaluator::fastTableBytes() const noexcept {
  std::size_t n = state_->isoTable ? state_->isoTable->bytes() : 0;  // shared per phase
  for (const auto& vt : state_->viewTables) n += vt.bytes();
  for (const auto& vt : state_->merged) n += vt.bytes();
  return n;
}

namespace {

// Whether pencil lamp q (an index into pencilLamps) is evaluated this frame: switched on, its
// integrator built, and not left out by the cutoff or the lamp budget (cullMovingLamps).
bool pencilOn(const AirlightImageEvaluator::State& st, std::size_t q) {
  return st.enabled[st.pencilLamps[q]] && st.pencils[q] && !st.culled[q];
}

double since(std::chrono::steady_clock::time_point t) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
}

// One frame's evaluation context: the evaluator's state plus this frame's inputs and tiling.
struct FrameCtx {
  const AirlightImageEvaluator::State* st;
  const std::vector<AirlightEvaluator>* lamps;
  const Camera* cam;
  const SurfaceBuffers* surf;
  AirlightImage* out;
  bool add = false;  // Write::Add: the pixels go onto out's values instead of replacing them
  kernels::PixelGeometry geo;
  const SubsamplingOptions* opt;
  PixelRays rays;         // cam's pixel rays (rayDirection without its tangents per call)
  int step = 8;           // coarse step, pixels
  int tile = kTile;       // tile size, pixels (a multiple of step)
  int tilesX = 1, tilesY = 1;
  int coarseX = 1, coarseY = 1;  // coarse grid corners along x and y
  std::size_t chunk = kChunk;     // coarse-grid corners per task (coarseChunk)
  float edgeFloor = 0.0f;  // 1/d beyond which distance edges are ignored
  // Moving lamps (pencil path) judged and interpolated each on its own in the tiles: their
  // count (0: off, every evaluated pixel evaluates every lamp), and per lamp the factor from
  // its white L_m to the block test's luminance (r + g + b of its colour).
  std::size_t nq = 0;
  const float* mlLum = nullptr;  // State::pencilLum
  // The moving lamps' lattice (SubsamplingOptions::moving_lattice): super-cells of 2 × 2 coarse
  // blocks, superX × superY of them whole (0 when off).
  int superX = 0, superY = 0;
  // Its second level (SubsamplingOptions::moving_lattice_levels = 2): cells of 4 × 4 coarse
  // blocks, hyperX × hyperY of them whole (0 when off).
  int hyperX = 0, hyperY = 0;
  std::size_t idx(int i, int j) const {
    return static_cast<std::size_t>(j) * static_cast<std::size_t>(cam->width) + static_cast<std::size_t>(i);
  }
  // Index of a coarse-grid column (a multiple of step, or the last pixel column) and row.
  int coarseCol(int i) const { return i == cam->width - 1 ? coarseX - 1 : i / step; }
  int coarseRow(int j) const { return j == cam->height - 1 ? coarseY - 1 : j / step; }
  // Pixel column (row) of coarse-grid column ci (row cj).
  int nodeX(int ci) const { return std::min(ci * step, cam->width - 1); }
  int nodeY(int cj) const { return std::min(cj * step, cam->height - 1); }
  // Whether the coarse stage evaluates the moving lamps at node (ci, cj): always without the
  // lattice and outside whole super-cells; else at super-cell corners (both even) and centres
  // (both odd) only.
  bool movingAnchor(int ci, int cj) const {
    if (superX == 0 || ci > 2 * superX || cj > 2 * superY) return true;
    return (ci % 2) == (cj % 2);
  }
  // Whether node (ci, cj) is inside the second level's whole cells.
  bool inHyper(int ci, int cj) const { return hyperX > 0 && ci <= 4 * hyperX && cj <= 4 * hyperY; }
  // Whether the coarse stage's first pass evaluates the moving lamps at node (ci, cj): inside
  // the second level's cells at their corners and centres only, elsewhere movingAnchor.
  bool firstPassAnchor(int ci, int cj) const {
    if (!inHyper(ci, cj)) return movingAnchor(ci, cj);
    return ((ci % 4) == 0 && (cj % 4) == 0) || ((ci % 4) == 2 && (cj % 4) == 2);
  }
};

// SubsamplingOptions::coarse_step = 0: 16 px where 16 px span at most 0.8° at the image centre,
// else 8 (measured on the bench scene at 1920×1080, 0.5° blocks: p95 3.5e-3 against every pixel
// evaluated; 8 px blocks at 256×144, 1.9°: 5.5e-3).
int autoCoarseStep(const Camera& cam) {
  const double degPerPixel = 180.0 / kPi / cam.focalLengthPixels();
  return 16.0 * degPerPixel <= 0.8 ? 16 : 8;
}

// Tiles along an image side of n pixels: tile t owns [t·T, (t + 1)·T), the last one up to n.
int tilesAlong(int n, int tile) { return n <= 1 ? 1 : (n - 1 + tile - 1) / tile; }

// Evaluates the batch held in `sc` (x, y, d of sc.n pixels) into sc.r, sc.g, sc.b: every lamp,
// through the SIMD kernels where it can, per pixel otherwise.
void evaluateBatch(const FrameCtx& f, Scratch& sc) {
  const AirlightImageEvaluator::State& st = *f.st;
  const std::size_t n = sc.n;
  if (n == 0) return;
  const auto t0 = std::chrono::steady_clock::now();
  const std::size_t padded = kernels::paddedSize(n);
  // Padding lanes: a harmless pixel (the kernels work in whole vectors).
  for (std::size_t k = n; k < padded; ++k) {
    sc.x[k] = sc.x[0];
    sc.y[k] = sc.y[0];
    sc.d[k] = sc.d[0];
  }
  std::fill_n(sc.r.data(), padded, 0.0f);
  std::fill_n(sc.g.data(), padded, 0.0f);
  std::fill_n(sc.b.data(), padded, 0.0f);
  const kernels::PixelBatch px{sc.x.data(), sc.y.data(), sc.d.data(), n};
  float* r = sc.r.data();
  float* g = sc.g.data();
  float* b = sc.b.data();
  const bool others = !sc.movingOnly;
  if (others && !st.isoParams.empty())
    kernels::accumulateIsoLamps(*st.isoTable, st.isoParams.data(), st.isoParams.size(), f.geo, px, r, g, b);
  // The batch's extent on the tangent plane: inset tables and per-ray guards cover a small
  // disc, and most batches do not reach it.
  float xMin = px.x[0], xMax = px.x[0], yMin = px.y[0], yMax = px.y[0];
  for (std::size_t k = 1; k < n; ++k) {
    xMin = std::min(xMin, px.x[k]);
    xMax = std::max(xMax, px.x[k]);
    yMin = std::min(yMin, px.y[k]);
    yMax = std::max(yMax, px.y[k]);
  }
  const double aLo = (static_cast<double>(f.geo.cx) - static_cast<double>(xMax)) * static_cast<double>(f.geo.invF);
  const double aHi = (static_cast<double>(f.geo.cx) - static_cast<double>(xMin)) * static_cast<double>(f.geo.invF);
  const double bLo = (static_cast<double>(f.geo.cy) - static_cast<double>(yMax)) * static_cast<double>(f.geo.invF);
  const double bHi = (static_cast<double>(f.geo.cy) - static_cast<double>(yMin)) * static_cast<double>(f.geo.invF);
  auto reaches = [&](double ca, double cb, double r2) {
    const double da = std::max({aLo - ca, 0.0, ca - aHi}), db = std::max({bLo - cb, 0.0, cb - bHi});
    return da * da + db * db <= r2;
  };
  // Tables and guards that cover a small disc run on the batch's pixels inside it only.
  auto compact = [&](double ca, double cb, double r2) {
    std::size_t m = 0;
    for (std::size_t k = 0; k < n; ++k) {
      const double a = (static_cast<double>(f.geo.cx) - static_cast<double>(px.x[k])) * static_cast<double>(f.geo.invF);
      const double bb = (static_cast<double>(f.geo.cy) - static_cast<double>(px.y[k])) * static_cast<double>(f.geo.invF);
      if ((a - ca) * (a - ca) + (bb - cb) * (bb - cb) > r2) continue;
      sc.sx[m] = px.x[k];
      sc.sy[m] = px.y[k];
      sc.sd[m] = px.d[k];
      sc.sidx[m] = static_cast<std::uint32_t>(k);
      ++m;
    }
    for (std::size_t k = m; k < kernels::paddedSize(m); ++k) {
      sc.sx[k] = sc.sx[0];
      sc.sy[k] = sc.sy[0];
      sc.sd[k] = sc.sd[0];
    }
    return m;
  };
  for (const AirlightImageEvaluator::State::TableUse& tu : st.tableUses) {
    if (!others) break;
    if (tu.whole) {
      kernels::accumulateViewTable(*tu.table, tu.use, f.geo, px, r, g, b);
      continue;
    }
    if (!reaches(tu.a, tu.b, tu.r2)) continue;
    const std::size_t m = compact(tu.a, tu.b, tu.r2);
    if (m == 0) continue;
    std::fill_n(sc.sr.data(), kernels::paddedSize(m), 0.0f);
    std::fill_n(sc.sg.data(), kernels::paddedSize(m), 0.0f);
    std::fill_n(sc.sb.data(), kernels::paddedSize(m), 0.0f);
    kernels::accumulateViewTable(*tu.table, tu.use, f.geo, {sc.sx.data(), sc.sy.data(), sc.sd.data(), m},
                                 sc.sr.data(), sc.sg.data(), sc.sb.data());
    for (std::size_t k = 0; k < m; ++k) {
      const std::size_t t = sc.sidx[k];
      r[t] += sc.sr[k];
      g[t] += sc.sg[k];
      b[t] += sc.sb[k];
    }
  }
  // Pixels at the image of a vehicle lamp: per ray (see State::rayGuards).
  for (std::size_t v = 0; v < st.frameGuards.size(); ++v) {
    const auto& gd = st.frameGuards[v];
    if (!others || gd.r2 < 0.0 || !st.viewEnabled[v] || !reaches(gd.a, gd.b, gd.r2)) continue;
    const std::size_t m = compact(gd.a, gd.b, gd.r2);
    const AirlightEvaluator& ev = (*f.lamps)[st.viewLamps[v]];
    for (std::size_t c = 0; c < m; ++c) {
      const std::size_t k = sc.sidx[c];
      const Ray ray{f.cam->position_m, f.rays.direction(static_cast<double>(px.x[k]), static_cast<double>(px.y[k])),
                    static_cast<double>(px.d[k])};
      const double l = ev.evaluate(ray);
      r[k] += static_cast<float>(l * ev.lamp().color[0]);
      g[k] += static_cast<float>(l * ev.lamp().color[1]);
      b[k] += static_cast<float>(l * ev.lamp().color[2]);
    }
  }
  if (!st.rayLamps.empty() || !st.pencilLamps.empty()) {
    const bool useMaps = st.fast.moving_lamps == MovingLampPath::Map;
    // The ray itself only for the lamps evaluated per ray or by the pencil; maps read pixels.
    const bool needRay = (others && !st.rayLamps.empty()) || !useMaps;
    // In chunks of kLampChunk pixels, lamp by lamp within a chunk: a pencil's working set (its
    // kernel slice, 120 KB, and the spokes its rays read) stays in cache over the chunk's rays
    // instead of four lamps' taking turns ray by ray. Each pixel still adds its lamps in the
    // same order, in double: the image is bit for bit what one pixel at a time gives.
    constexpr std::size_t kLampChunk = 128;
    Vec3 dirs[kLampChunk];
    double acc[kLampChunk][3];
    for (std::size_t k0 = 0; k0 < n; k0 += kLampChunk) {
      const std::size_t k1 = std::min(n, k0 + kLampChunk);
      for (std::size_t k = k0; k < k1; ++k) {
        // The ray only where a lamp is evaluated: in the lattice's second pass and the tiles'
        // interpolated blocks most pixels know every moving lamp's value already.
        const float* known = sc.mlActive ? sc.ml.data() + k * f.nq : nullptr;
        bool anyUnknown = others && !st.rayLamps.empty();
        for (std::size_t q = 0; q < st.pencilLamps.size() && !anyUnknown; ++q)
          anyUnknown = !known || std::isnan(known[q]);
        dirs[k - k0] = needRay && anyUnknown
                           ? f.rays.direction(static_cast<double>(px.x[k]), static_cast<double>(px.y[k]))
                           : Vec3(1, 0, 0);
        double* a = acc[k - k0];
        a[0] = a[1] = a[2] = 0.0;
        if (!others) continue;
        const Ray ray{f.cam->position_m, dirs[k - k0], static_cast<double>(px.d[k])};
        for (std::size_t li : st.rayLamps) {
          if (!st.enabled[li]) continue;
          const AirlightEvaluator& ev = (*f.lamps)[li];
          const double l = ev.evaluate(ray);
          for (int c = 0; c < 3; ++c) a[c] += l * ev.lamp().color[c];
        }
      }
      for (std::size_t q = 0; q < st.pencilLamps.size(); ++q) {
        const bool on = pencilOn(st, q);
        const Vec3 cullDir = st.cullDir[q];
        const double cullCos = st.cullCos[q];
        for (std::size_t k = k0; k < k1; ++k) {
          float* known = sc.mlActive ? sc.ml.data() + k * f.nq : nullptr;
          if (!on) {
            if (known) known[q] = 0.0f;
            continue;
          }
          const PencilAirlight& pa = *st.pencils[q];
          double l = 0.0;
          if (known && !std::isnan(known[q])) {
            l = static_cast<double>(known[q]);  // interpolated in its block (subsampleTile)
          } else if (!useMaps && glm::dot(dirs[k - k0], cullDir) <= cullCos) {
            if (known) known[q] = 0.0f;  // outside its cone: below its share of the cutoff
          } else {
            l = useMaps ? st.maps[q].lookup(static_cast<int>(px.x[k]), static_cast<int>(px.y[k]))
                        : pa.evaluate(dirs[k - k0], static_cast<double>(px.d[k]));
            if (known) known[q] = static_cast<float>(l);
            ++sc.movingEvaluated;
          }
          for (int c = 0; c < 3; ++c) acc[k - k0][c] += l * pa.lamp().lamp().color[c];
        }
      }
      for (std::size_t k = k0; k < k1; ++k) {
        r[k] += static_cast<float>(acc[k - k0][0]);
        g[k] += static_cast<float>(acc[k - k0][1]);
        b[k] += static_cast<float>(acc[k - k0][2]);
      }
    }
  }
  if (!sc.movingOnly) sc.evaluated += n;  // the lattice's second pass: pixels counted in the first
  sc.evalSeconds += since(t0);
}

// The tile-local view of one tile's closed region [x0, xc] × [y0, yc] (image coordinates).
struct TileView {
  int x0, y0, xc, yc;  // closed region, inclusive
  int x1, y1;          // owned pixels: [x0, x1) × [y0, y1)
  std::size_t stride;  // plane row stride
  int cw() const { return xc - x0 + 1; }
  int ch() const { return yc - y0 + 1; }
  std::size_t at(int i, int j) const {
    return static_cast<std::size_t>(j - y0) * stride + static_cast<std::size_t>(i - x0);
  }
};

TileView tileView(const FrameCtx& f, std::size_t t, std::size_t stride) {
  const int W = f.cam->width, H = f.cam->height;
  const int tx = static_cast<int>(t % static_cast<std::size_t>(f.tilesX));
  const int ty = static_cast<int>(t / static_cast<std::size_t>(f.tilesX));
  TileView v{};
  v.x0 = tx * f.tile;
  v.y0 = ty * f.tile;
  v.xc = std::min(v.x0 + f.tile, W - 1);
  v.yc = std::min(v.y0 + f.tile, H - 1);
  v.x1 = tx == f.tilesX - 1 ? W : v.x0 + f.tile;
  v.y1 = ty == f.tilesY - 1 ? H : v.y0 + f.tile;
  v.stride = stride;
  return v;
}

// Adds pixel (i, j) of the tile to the batch unless it was evaluated already.
void request(const FrameCtx& f, Scratch& sc, const TileView& tv, int i, int j) {
  const std::size_t k = tv.at(i, j);
  if (sc.done[k]) return;
  sc.done[k] = 1;
  sc.x[sc.n] = static_cast<float>(i) + 0.5f;
  sc.y[sc.n] = static_cast<float>(j) + 0.5f;
  sc.d[sc.n] = f.surf->distance[f.idx(i, j)];
  sc.slot[sc.n] = static_cast<std::uint32_t>(k);
  ++sc.n;
}

// Evaluates the batch and stores it into the tile.
// Puts the batch's sky pixels (d = +inf) before the others (x, y, d and slot together): the
// kernels' sky paths then run on whole vectors, and mixed vectors, which pay for both paths,
// are at most one per batch.
void groupSky(Scratch& sc) {
  std::size_t lo = 0, hi = sc.n;
  while (true) {
    while (lo < hi && std::isinf(sc.d[lo])) ++lo;
    while (lo < hi && !std::isinf(sc.d[hi - 1])) --hi;
    if (lo + 1 >= hi) return;
    --hi;
    std::swap(sc.x[lo], sc.x[hi]);
    std::swap(sc.y[lo], sc.y[hi]);
    std::swap(sc.d[lo], sc.d[hi]);
    std::swap(sc.slot[lo], sc.slot[hi]);
    ++lo;
  }
}

void runTileBatch(const FrameCtx& f, Scratch& sc) {
  groupSky(sc);
  const std::size_t nq = f.nq;
  sc.mlActive = nq > 0;
  for (std::size_t k = 0; k < sc.n && nq > 0; ++k)
    std::copy_n(sc.pml.data() + static_cast<std::size_t>(sc.slot[k]) * nq, nq, sc.ml.data() + k * nq);
  evaluateBatch(f, sc);
  sc.mlActive = false;
  for (std::size_t k = 0; k < sc.n; ++k) {
    const std::size_t at = sc.slot[k];
    sc.pr[at] = sc.r[k];
    sc.pg[at] = sc.g[k];
    sc.pb[at] = sc.b[k];
    if (nq > 0) std::copy_n(sc.ml.data() + k * nq, nq, sc.pml.data() + at * nq);
  }
  sc.n = 0;
}

// The distance-edge bits of the tile's closed region, one row of words per pixel row. A pixel
// is an edge when the second difference of 1/d across it (in x or in y) exceeds depth_edge_rel
// of the largest 1/d involved: over a plane 1/d is affine in the pixel coordinates up to the
// slowly varying 1/|ray| factor (second differences ~1e-7 relative), a silhouette or the sky
// line gives differences of order 1, a crease between two surfaces flags the pixels along it.
// The image's first and last columns (rows) get no x (y) test.
void buildTileEdges(const FrameCtx& f, Scratch& sc, const TileView& tv) {
  const int W = f.cam->width, H = f.cam->height;
  const int cw = tv.cw(), ch = tv.ch();
  const float* dist = f.surf->distance.data();
  // q rows −1 … ch (halo rows outside the image are not read): entry 1 is the column left of
  // the region, 2 … cw + 1 the region, cw + 2 the column right of it.
  for (int r = -1; r <= ch; ++r) {
    const int j = tv.y0 + r;
    if (j < 0 || j >= H) continue;
    float* q = sc.q.data() + static_cast<std::size_t>(r + 1) * sc.qStride + 1;
    const float* drow = dist + f.idx(0, j);
    const int lo = std::max(tv.x0 - 1, 0), hi = std::min(tv.xc + 1, W - 1);
    kernels::inverseDistances(drow + lo, static_cast<std::size_t>(hi - lo + 1), q + (lo - (tv.x0 - 1)));
    // At the image's border a linear extrapolation: second difference 0, no x test there.
    if (tv.x0 == 0) q[0] = cw > 1 ? 2.0f * q[1] - q[2] : q[1];
    if (tv.xc == W - 1) q[cw + 1] = cw > 1 ? 2.0f * q[cw] - q[cw - 1] : q[cw];
  }
  const float tol = static_cast<float>(f.opt->depth_edge_rel);
  const std::size_t n = static_cast<std::size_t>(cw) + 2;
  for (int r = 0; r < ch; ++r) {
    const int j = tv.y0 + r;
    const float* c = sc.q.data() + static_cast<std::size_t>(r + 1) * sc.qStride + 1;
    const bool yTest = j > 0 && j + 1 < H;
    kernels::distanceEdgeBits(yTest ? c - sc.qStride : nullptr, c, yTest ? c + sc.qStride : nullptr, n, tol, f.edgeFloor,
                              sc.edges.data() + static_cast<std::size_t>(r) * sc.edgeWords);
  }
}

// True when a bit in [from, to] of one row of edge words is set.
bool anyBits(const std::uint64_t* w, int from, int to) {
  for (int k = from / 64; k <= to / 64; ++k) {
    std::uint64_t m = ~std::uint64_t{0};
    if (k == from / 64) m &= ~std::uint64_t{0} << (from % 64);
    if (k == to / 64 && to % 64 != 63) m &= (std::uint64_t{1} << (to % 64 + 1)) - 1;
    if (w[k] & m) return true;
  }
  return false;
}

float lumAt(const Scratch& sc, std::size_t at) { return sc.pr[at] + sc.pg[at] + sc.pb[at]; }

// 1/d of pixel (i, j) of the tile (sc.q: rows with a one-pixel halo, entry 1 = column x0 − 1).
float qAt(const Scratch& sc, const TileView& tv, int i, int j) {
  return sc.q[static_cast<std::size_t>(j - tv.y0 + 1) * sc.qStride + static_cast<std::size_t>(i - tv.x0 + 2)];
}

// Two pixels see their surfaces at about the same distance (1/d within kLayerTolerance of each
// other), or both beyond the fog's edge cut-off (FrameCtx::edgeFloor): along nearby rays the
// airlight is then nearly the same function of direction, whatever surface stops the ray.
constexpr float kLayerTolerance = 0.1f;
bool sameLayer(float qa, float qb, float floor) {
  return (qa <= floor && qb <= floor) || std::abs(qa - qb) <= kLayerTolerance * std::max(qa, qb);
}

// Blocks up to this size whose only fault is a distance edge are filled layer by layer.
constexpr int kLayeredMax = 4;

enum class BlockTest { Smooth, Layered, Split };

// The block test of the header comment: centre against the corners' bilinear prediction,
// distance-buffer edges, lamp images. A small block across a distance edge (a silhouette) is
// accepted as Layered when the centre matches the prediction of the corners in its own layer
// (sameLayer), bilinear weights renormalised over them: each pixel is then interpolated from
// the corners of its layer, and pixels with none are evaluated.
// `edge` tells whether the block holds a distance edge, when no lamp is imaged in it (`lamp`).
BlockTest testBlock(const FrameCtx& f, const Scratch& sc, const TileView& tv, const Block& bl, bool& edge, bool& lamp) {
  const SubsamplingOptions& o = *f.opt;
  edge = false;
  lamp = true;
  const int w = bl.i1 - bl.i0, h = bl.j1 - bl.j0;
  const int im = bl.i0 + w / 2, jm = bl.j0 + h / 2;
  // A lamp imaged inside the block makes a peak that the corners cannot see (the lamps whose
  // guard reaches the tile: sc.tileLamps).
  for (const auto& [x, y] : sc.tileLamps)
    if (x >= bl.i0 - o.lamp_guard_px && x <= bl.i1 + 1 + o.lamp_guard_px && y >= bl.j0 - o.lamp_guard_px &&
        y <= bl.j1 + 1 + o.lamp_guard_px)
      return BlockTest::Split;
  lamp = false;
  // Distance edges inside the block (a car's silhouette, the horizon) change θd abruptly: any
  // pixel of the edge mask in the closed block (bit 1 of a row is column x0). The block's rows
  // are OR-ed word by word, then its columns tested once.
  std::uint64_t rowsOr[8] = {0, 0, 0, 0, 0, 0, 0, 0};  // a block spans at most 257 columns: 6 words
  const int w0 = (bl.i0 - tv.x0 + 1) / 64, w1 = (bl.i1 - tv.x0 + 1) / 64;
  for (int j = bl.j0; j <= bl.j1; ++j) {
    const std::uint64_t* row = sc.edges.data() + static_cast<std::size_t>(j - tv.y0) * sc.edgeWords;
    for (int k = w0; k <= w1; ++k) rowsOr[k - w0] |= row[k];
  }
  edge = anyBits(rowsOr, (bl.i0 - tv.x0 + 1) - 64 * w0, (bl.i1 - tv.x0 + 1) - 64 * w0);
  if (edge && (w > kLayeredMax || h > kLayeredMax)) return BlockTest::Split;
  const float um = w > 0 ? static_cast<float>(im - bl.i0) / static_cast<float>(w) : 0.0f;
  const float vm = h > 0 ? static_cast<float>(jm - bl.j0) / static_cast<float>(h) : 0.0f;
  const float wc[4] = {(1 - um) * (1 - vm), um * (1 - vm), (1 - um) * vm, um * vm};
  const int ci[4] = {bl.i0, bl.i1, bl.i0, bl.i1}, cj[4] = {bl.j0, bl.j0, bl.j1, bl.j1};
  float predicted = 0.0f, weight = 0.0f;
  const float qm = qAt(sc, tv, im, jm);
  for (int c = 0; c < 4; ++c) {
    if (edge && !sameLayer(qAt(sc, tv, ci[c], cj[c]), qm, f.edgeFloor)) continue;
    predicted += wc[c] * lumAt(sc, tv.at(ci[c], cj[c]));
    weight += wc[c];
  }
  if (!(weight > 0.0f)) return BlockTest::Split;
  predicted /= weight;
  const float actual = lumAt(sc, tv.at(im, jm));
  if (std::abs(actual - predicted) >
      static_cast<float>(o.rel_tolerance) * actual + static_cast<float>(o.abs_tolerance_cd_m2))
    return BlockTest::Split;
  return edge ? BlockTest::Layered : BlockTest::Smooth;
}

// The owned pixels of a layered leaf (columns [i0, i1), rows [j0, j1), plus the image's last
// column and row) that have no corner in their layer (a post thinner than the block): they join
// the batch.
void requestLoneLayerPixels(const FrameCtx& f, Scratch& sc, const TileView& tv, const Block& bl) {
  const int iEnd = bl.i1 == f.cam->width - 1 ? bl.i1 : bl.i1 - 1;
  const int jEnd = bl.j1 == f.cam->height - 1 ? bl.j1 : bl.j1 - 1;
  const float q00 = qAt(sc, tv, bl.i0, bl.j0), q10 = qAt(sc, tv, bl.i1, bl.j0), q01 = qAt(sc, tv, bl.i0, bl.j1),
              q11 = qAt(sc, tv, bl.i1, bl.j1);
  for (int j = bl.j0; j <= std::max(jEnd, bl.j0); ++j)
    for (int i = bl.i0; i <= std::max(iEnd, bl.i0); ++i) {
      if (sc.done[tv.at(i, j)]) continue;
      const float q = qAt(sc, tv, i, j);
      if (sameLayer(q00, q, f.edgeFloor) || sameLayer(q10, q, f.edgeFloor) || sameLayer(q01, q, f.edgeFloor) ||
          sameLayer(q11, q, f.edgeFloor))
        continue;
      request(f, sc, tv, i, j);
    }
}

// Fills the owned pixels of a layered leaf that were not evaluated: bilinear weights of the
// corners in the pixel's layer, renormalised (every such pixel has one: requestLoneLayerPixels).
void fillLayeredLeaf(const FrameCtx& f, Scratch& sc, const TileView& tv, const Block& bl) {
  const int w = bl.i1 - bl.i0, h = bl.j1 - bl.j0;
  const int iEnd = bl.i1 == f.cam->width - 1 ? bl.i1 : bl.i1 - 1;
  const int jEnd = bl.j1 == f.cam->height - 1 ? bl.j1 : bl.j1 - 1;
  const int ci[4] = {bl.i0, bl.i1, bl.i0, bl.i1}, cj[4] = {bl.j0, bl.j0, bl.j1, bl.j1};
  float qc[4];
  std::size_t at[4];
  for (int c = 0; c < 4; ++c) {
    qc[c] = qAt(sc, tv, ci[c], cj[c]);
    at[c] = tv.at(ci[c], cj[c]);
  }
  const float invW = w > 0 ? 1.0f / static_cast<float>(w) : 0.0f, invH = h > 0 ? 1.0f / static_cast<float>(h) : 0.0f;
  for (int j = bl.j0; j <= std::max(jEnd, bl.j0); ++j)
    for (int i = bl.i0; i <= std::max(iEnd, bl.i0); ++i) {
      const std::size_t k = tv.at(i, j);
      if (sc.done[k]) continue;
      const float u = static_cast<float>(i - bl.i0) * invW, v = static_cast<float>(j - bl.j0) * invH;
      const float wc[4] = {(1 - u) * (1 - v), u * (1 - v), (1 - u) * v, u * v};
      const float q = qAt(sc, tv, i, j);
      float r = 0.0f, g = 0.0f, b = 0.0f, wsum = 0.0f;
      for (int c = 0; c < 4; ++c) {
        if (!sameLayer(qc[c], q, f.edgeFloor)) continue;
        r += wc[c] * sc.pr[at[c]];
        g += wc[c] * sc.pg[at[c]];
        b += wc[c] * sc.pb[at[c]];
        wsum += wc[c];
      }
      // A pixel whose only same-layer corners have weight 0 (it lies on the opposite edge):
      // the nearest of them.
      if (!(wsum > 0.0f)) {
        float best = 3.0e38f;
        for (int c = 0; c < 4; ++c) {
          if (!sameLayer(qc[c], q, f.edgeFloor)) continue;
          const float dd = static_cast<float>((ci[c] - i) * (ci[c] - i) + (cj[c] - j) * (cj[c] - j));
          if (dd < best) {
            best = dd;
            r = sc.pr[at[c]];
            g = sc.pg[at[c]];
            b = sc.pb[at[c]];
          }
        }
        wsum = 1.0f;
      }
      sc.pr[k] = r / wsum;
      sc.pg[k] = g / wsum;
      sc.pb[k] = b / wsum;
    }
}

// Every pixel of one tile evaluated (SubsamplingOptions::full), written to the image.
void fullTile(const FrameCtx& f, Scratch& sc, std::size_t t) {
  const TileView tv = tileView(f, t, sc.stride);
  sc.n = 0;
  for (int j = tv.y0; j < tv.y1; ++j) {
    const float* drow = f.surf->distance.data() + f.idx(0, j);
    for (int i = tv.x0; i < tv.x1; ++i) {
      sc.x[sc.n] = static_cast<float>(i) + 0.5f;
      sc.y[sc.n] = static_cast<float>(j) + 0.5f;
      sc.d[sc.n] = drow[i];
      ++sc.n;
    }
  }
  evaluateBatch(f, sc);
  std::size_t k = 0;
  for (int j = tv.y0; j < tv.y1; ++j) {
    float* dst = f.out->rgb.data() + 3 * f.idx(tv.x0, j);
    for (int i = tv.x0; i < tv.x1; ++i, ++k) {
      if (f.add) {
        dst[0] += sc.r[k];
        dst[1] += sc.g[k];
        dst[2] += sc.b[k];
      } else {
        dst[0] = sc.r[k];
        dst[1] = sc.g[k];
        dst[2] = sc.b[k];
      }
      dst += 3;
    }
  }
  sc.n = 0;
}

// 1/d of pixel (i, j) (0 for the sky), as the tiles' distance-edge test reads it.
float inverseDistanceAt(const FrameCtx& f, int i, int j) {
  const float d = f.surf->distance[f.idx(i, j)];
  return std::isfinite(d) && d > 0.0f ? 1.0f / d : 0.0f;
}

// The moving lamps' values over super-cell (a, b) at pixel (i, j): bilinear between its corner
// nodes (pixel positions, so that the image's last, narrower column and row interpolate
// right), lamp q.
float superBilinear(const FrameCtx& f, const AirlightImageEvaluator::State& st, int a, int b, std::size_t q, int i, int j) {
  const int c0 = 2 * a, r0 = 2 * b;
  const int x0 = f.nodeX(c0), x2 = f.nodeX(c0 + 2), y0 = f.nodeY(r0), y2 = f.nodeY(r0 + 2);
  const float u = static_cast<float>(i - x0) / static_cast<float>(x2 - x0);
  const float v = static_cast<float>(j - y0) / static_cast<float>(y2 - y0);
  auto at = [&](int ci, int cj) {
    return st.coarseMl[f.nq * (static_cast<std::size_t>(cj) * static_cast<std::size_t>(f.coarseX) +
                               static_cast<std::size_t>(ci)) + q];
  };
  return (1 - v) * ((1 - u) * at(c0, r0) + u * at(c0 + 2, r0)) + v * ((1 - u) * at(c0, r0 + 2) + u * at(c0 + 2, r0 + 2));
}

// The same over a cell (a, b) of the lattice's second level (4 × 4 coarse blocks).
float hyperBilinear(const FrameCtx& f, const AirlightImageEvaluator::State& st, int a, int b, std::size_t q, int i, int j) {
  const int c0 = 4 * a, r0 = 4 * b;
  const int x0 = f.nodeX(c0), x4 = f.nodeX(c0 + 4), y0 = f.nodeY(r0), y4 = f.nodeY(r0 + 4);
  const float u = static_cast<float>(i - x0) / static_cast<float>(x4 - x0);
  const float v = static_cast<float>(j - y0) / static_cast<float>(y4 - y0);
  auto at = [&](int ci, int cj) {
    return st.coarseMl[f.nq * (static_cast<std::size_t>(cj) * static_cast<std::size_t>(f.coarseX) +
                               static_cast<std::size_t>(ci)) + q];
  };
  return (1 - v) * ((1 - u) * at(c0, r0) + u * at(c0 + 4, r0)) + v * ((1 - u) * at(c0, r0 + 4) + u * at(c0 + 4, r0 + 4));
}

// The share of a block's tolerance (of its centre's whole luminance) that the moving lamps
// interpolated over it may miss together, on top of the block test's own: a quarter.
constexpr float kMovingShare = 0.25f;

// Which moving lamps may be interpolated over a block: dev[q] is what interpolating lamp q would
// miss at the block's centre (its value there against the prediction from the corners, in
// luminance; NaN or +inf: it may not be), `total` the error the block grants the moving lamps
// together (kMovingShare of its tolerance). Lamps are granted in order of their deviation,
// smallest first, while the deviations granted sum to at most `total`: a lamp whose light is
// flat there (a far car, a lamp behind a silhouette) leaves what it does not need to the others.
// Measured on the traffic bench (four moving low beams, 1280×720): equal shares of half the
// tolerance (0.125 each) 142 k (pixel, lamp) evaluations; granted from a quarter, 133 k, the
// error against per ray p95 4.0e-3 → 4.3e-3; granted from a half, 114 k, but the 128×72 test
// image against the reference went from p95 9.5e-3 to 1.06e-2. grant[q] = 1 for those granted.
void grantBudget(Scratch& sc, std::size_t nq, float total) {
  std::size_t n = 0;
  for (std::size_t q = 0; q < nq; ++q) {
    sc.grant[q] = 0;
    if (sc.dev[q] <= total) sc.order[n++] = static_cast<std::uint32_t>(q);  // false for NaN
  }
  std::sort(sc.order.begin(), sc.order.begin() + static_cast<std::ptrdiff_t>(n),
            [&](std::uint32_t a, std::uint32_t b) { return sc.dev[a] < sc.dev[b]; });
  float used = 0.0f;
  for (std::size_t k = 0; k < n; ++k) {
    used += sc.dev[sc.order[k]];
    if (used > total) break;
    sc.grant[sc.order[k]] = 1;
  }
}

// A block split for the whole image's sake (no lamp image in it) may still be smooth in one
// moving lamp's light: where the lamp's own value at the centre is the bilinear prediction from
// the corners within what grantBudget grants it of a quarter of the block tolerance (of the whole
// pixel's luminance, which is what the tolerance bounds), the lamp is interpolated over the block's
// pixels not yet known instead of evaluated at each (the same test, and the same fill, the whole
// image gets; a moving lamp's light is smooth away from its image and cut-off, and a pixel costs
// it ~0.25 µs against ~0.03 µs for a lamp read from view tables).
// A block with a distance edge (`edge`, a silhouette) is judged in its centre's layer only, as a
// layered leaf is (testBlock): the prediction from the corners in that layer, bilinear weights
// renormalised over them, and the fill only to pixels of that layer, each from the corners in
// its own layer; pixels of the other layers are evaluated. Along silhouettes the subsampling
// splits blocks down to 4 px whatever the lamps do: there this took the moving lamps' evaluations
// from 79 k to 55 k on the traffic bench (AirlightImage.MovingLampsAcrossSilhouettes: 33 k →
// 15 k).
// Measured on the traffic bench (four moving low beams, 1280×720), in blocks without edges and
// with equal shares of the budget (before grantBudget): 316 k → 226 k (pixel, lamp)
// evaluations; on the 128×72 test image against the reference (two moving lamps, a quarter of
// the tolerance each), p95 8.0e-3 → 9.5e-3 (half each: 1.06e-2).
void interpolateSmoothLamps(const FrameCtx& f, Scratch& sc, const TileView& tv, const Block& bl, bool edge) {
  const SubsamplingOptions& o = *f.opt;
  const std::size_t nq = f.nq;
  const int w = bl.i1 - bl.i0, h = bl.j1 - bl.j0;
  if (w < 2 && h < 2) return;
  const int im = bl.i0 + w / 2, jm = bl.j0 + h / 2;
  const float um = w > 0 ? static_cast<float>(im - bl.i0) / static_cast<float>(w) : 0.0f;
  const float vm = h > 0 ? static_cast<float>(jm - bl.j0) / static_cast<float>(h) : 0.0f;
  const std::size_t at[4] = {tv.at(bl.i0, bl.j0), tv.at(bl.i1, bl.j0), tv.at(bl.i0, bl.j1), tv.at(bl.i1, bl.j1)};
  const int ci[4] = {bl.i0, bl.i1, bl.i0, bl.i1}, cj[4] = {bl.j0, bl.j0, bl.j1, bl.j1};
  const std::size_t mid = tv.at(im, jm);
  // The corners' layers (all one layer without an edge).
  const float qm = qAt(sc, tv, im, jm);
  float qc[4];
  bool inMid[4];
  for (int c = 0; c < 4; ++c) {
    qc[c] = qAt(sc, tv, ci[c], cj[c]);
    inMid[c] = !edge || sameLayer(qc[c], qm, f.edgeFloor);
  }
  // Bilinear over the corners whose flag is set, weights renormalised (NaN: none with weight).
  auto predict = [&](const float* c, const bool* use, float u, float v) {
    const float wc[4] = {(1 - u) * (1 - v), u * (1 - v), (1 - u) * v, u * v};
    float sum = 0.0f, wsum = 0.0f;
    for (int k = 0; k < 4; ++k)
      if (use[k]) {
        sum += wc[k] * c[k];
        wsum += wc[k];
      }
    return wsum > 0.0f ? sum / wsum : std::numeric_limits<float>::quiet_NaN();
  };
  // A quarter of the block tolerance, granted to the moving lamps by grantBudget.
  const float budget = kMovingShare * (static_cast<float>(o.rel_tolerance) * lumAt(sc, mid) + static_cast<float>(o.abs_tolerance_cd_m2));
  const float invW = w > 0 ? 1.0f / static_cast<float>(w) : 0.0f, invH = h > 0 ? 1.0f / static_cast<float>(h) : 0.0f;
  const float inf = std::numeric_limits<float>::infinity();
  for (std::size_t q = 0; q < nq; ++q) {
    float c[4];
    bool known = true;
    for (int k = 0; k < 4; ++k) {
      c[k] = sc.pml[at[k] * nq + q];
      known = known && (!inMid[k] || !std::isnan(c[k]));
    }
    const float cm = sc.pml[mid * nq + q];
    sc.dev[q] = known && !std::isnan(cm) ? std::abs(cm - predict(c, inMid, um, vm)) * f.mlLum[q] : inf;
  }
  grantBudget(sc, nq, budget);
  for (std::size_t q = 0; q < nq; ++q) {
    if (!sc.grant[q]) continue;
    float c[4];
    for (int k = 0; k < 4; ++k) c[k] = sc.pml[at[k] * nq + q];
    for (int j = bl.j0; j <= bl.j1; ++j) {
      const float v = static_cast<float>(j - bl.j0) * invH;
      for (int i = bl.i0; i <= bl.i1; ++i) {
        float& dst = sc.pml[tv.at(i, j) * nq + q];
        if (!std::isnan(dst)) continue;
        const float u = static_cast<float>(i - bl.i0) * invW;
        if (!edge) {
          dst = predict(c, inMid, u, v);
          continue;
        }
        // Only the centre's layer, from the corners of the pixel's own layer (all known: they
        // are in the centre's layer too).
        const float qp = qAt(sc, tv, i, j);
        if (!sameLayer(qp, qm, f.edgeFloor)) continue;
        bool use[4];
        for (int k = 0; k < 4; ++k) use[k] = inMid[k] && sameLayer(qc[k], qp, f.edgeFloor);
        dst = predict(c, use, u, v);  // NaN (evaluated) when no such corner has weight
      }
    }
  }
}

// One tile of the adaptive subsampling: corners from the coarse grid, then level by level the
// block centres, the block test and the split blocks' new corners, each level's new pixels as
// one batch; then the leaves interpolated and the tile's pixels written to the image.
void subsampleTile(const FrameCtx& f, Scratch& sc, const std::vector<float>& coarse, std::size_t t) {
  const TileView tv = tileView(f, t, sc.stride);
  const int s = f.step;
  auto tj = std::chrono::steady_clock::now();
  for (int r = 0; r < tv.ch(); ++r)
    std::fill_n(sc.done.data() + static_cast<std::size_t>(r) * sc.stride, static_cast<std::size_t>(tv.cw()), 0);
  if (f.nq > 0)
    for (int r = 0; r < tv.ch(); ++r)
      std::fill_n(sc.pml.data() + static_cast<std::size_t>(r) * sc.stride * f.nq, static_cast<std::size_t>(tv.cw()) * f.nq,
                  std::numeric_limits<float>::quiet_NaN());
  buildTileEdges(f, sc, tv);
  // Level 0: the coarse blocks, their corners copied from the coarse grid.
  sc.cur.clear();
  sc.leaves.clear();
  sc.layered.clear();
  sc.tileLamps.clear();
  const double guard = static_cast<double>(f.opt->lamp_guard_px) + 1.0;
  for (const auto& [x, y] : f.st->lampPixels)
    if (x >= tv.x0 - guard && x <= tv.xc + 1 + guard && y >= tv.y0 - guard && y <= tv.yc + 1 + guard)
      sc.tileLamps.emplace_back(x, y);
  auto corner = [&](int i, int j) {
    const std::size_t k = tv.at(i, j);
    if (sc.done[k]) return;
    sc.done[k] = 1;
    const float* c = coarse.data() + 3 * (static_cast<std::size_t>(f.coarseRow(j)) * static_cast<std::size_t>(f.coarseX) +
                                          static_cast<std::size_t>(f.coarseCol(i)));
    sc.pr[k] = c[0];
    sc.pg[k] = c[1];
    sc.pb[k] = c[2];
    if (f.nq > 0)
      std::copy_n(f.st->coarseMl.data() + f.nq * (static_cast<std::size_t>(f.coarseRow(j)) * static_cast<std::size_t>(f.coarseX) +
                                                  static_cast<std::size_t>(f.coarseCol(i))),
                  f.nq, sc.pml.data() + k * f.nq);
  };
  for (int j0 = tv.y0; j0 < tv.yc || j0 == tv.y0; j0 += s) {
    const int j1 = std::min(j0 + s, tv.yc);
    for (int i0 = tv.x0; i0 < tv.xc || i0 == tv.x0; i0 += s) {
      const int i1 = std::min(i0 + s, tv.xc);
      corner(i0, j0);
      corner(i1, j0);
      corner(i0, j1);
      corner(i1, j1);
      sc.cur.push_back(Block{i0, j0, i1, j1});
      if (i1 == tv.xc) break;
    }
    if (j1 == tv.yc) break;
  }
  // Blocks that have pixels besides their corners are tested against their centre; the others
  // are done. Each level's new pixels (the centres of its blocks, which were requested with the
  // corners of the split that made them) are one batch.
  auto push = [&](const Block& b) {
    const int w = b.i1 - b.i0, h = b.j1 - b.j0;
    if (w <= 1 && h <= 1) return;  // every pixel is a corner
    request(f, sc, tv, b.i0 + w / 2, b.j0 + h / 2);
    sc.next.push_back(b);
  };
  sc.next.clear();
  for (const Block& bl : sc.cur) {
    // The moving lamps' lattice: a block centre inside a super-cell that passed for a lamp
    // takes the lamp's interpolation over the super-cell (movingLattice) instead of evaluating it.
    if (f.superX > 0 && bl.i1 - bl.i0 > 1 && bl.j1 - bl.j0 > 1) {
      const int a = f.coarseCol(bl.i0) / 2, b = f.coarseRow(bl.j0) / 2;
      if (a < f.superX && b < f.superY) {
        const int im = bl.i0 + (bl.i1 - bl.i0) / 2, jm = bl.j0 + (bl.j1 - bl.j0) / 2;
        const std::uint8_t* pass = f.st->superPass.data() +
                                   (static_cast<std::size_t>(b) * static_cast<std::size_t>(f.superX) + static_cast<std::size_t>(a)) * f.nq;
        float* dst = sc.pml.data() + tv.at(im, jm) * f.nq;
        for (std::size_t q = 0; q < f.nq; ++q)
          if (pass[q]) dst[q] = superBilinear(f, *f.st, a, b, q, im, jm);
      }
    }
    push(bl);
  }
  std::swap(sc.cur, sc.next);
  sc.judgeSeconds += since(tj);
  while (!sc.cur.empty()) {
    runTileBatch(f, sc);
    tj = std::chrono::steady_clock::now();
    sc.next.clear();
    for (const Block& bl : sc.cur) {
      bool edge = false, lamp = false;
      const BlockTest test = testBlock(f, sc, tv, bl, edge, lamp);
      if (test == BlockTest::Smooth) {
        sc.leaves.push_back(bl);
        continue;
      }
      if (test == BlockTest::Layered) {
        requestLoneLayerPixels(f, sc, tv, bl);
        sc.layered.push_back(bl);
        continue;
      }
      // Split: the new corners and the quadrants' centres join the next batch, the quadrants
      // the next level.
      if (f.nq > 0 && !lamp && (!edge || f.opt->moving_layers)) interpolateSmoothLamps(f, sc, tv, bl, edge);
      const int w = bl.i1 - bl.i0, h = bl.j1 - bl.j0;
      const int im = bl.i0 + w / 2, jm = bl.j0 + h / 2;
      for (int j : {bl.j0, jm, bl.j1})
        for (int i : {bl.i0, im, bl.i1}) request(f, sc, tv, i, j);
      if (w <= 1) {
        push(Block{bl.i0, bl.j0, bl.i1, jm});
        push(Block{bl.i0, jm, bl.i1, bl.j1});
      } else if (h <= 1) {
        push(Block{bl.i0, bl.j0, im, bl.j1});
        push(Block{im, bl.j0, bl.i1, bl.j1});
      } else {
        push(Block{bl.i0, bl.j0, im, jm});
        push(Block{im, bl.j0, bl.i1, jm});
        push(Block{bl.i0, jm, im, bl.j1});
        push(Block{im, jm, bl.i1, bl.j1});
      }
    }
    sc.judgeSeconds += since(tj);
    std::swap(sc.cur, sc.next);
  }
  runTileBatch(f, sc);  // pixels of layered leaves without a corner in their layer
  // Interpolate what was not evaluated: each leaf fills its own pixels (columns [i0, i1), rows
  // [j0, j1), plus the image's last column and row), then the tile's pixels go to the image.
  const auto tf = std::chrono::steady_clock::now();
  sc.fill.clear();
  for (const Block& bl : sc.leaves) {
    const int iEnd = bl.i1 == f.cam->width - 1 ? bl.i1 : bl.i1 - 1;
    const int jEnd = bl.j1 == f.cam->height - 1 ? bl.j1 : bl.j1 - 1;
    sc.fill.push_back(kernels::FillBlock{bl.i0 - tv.x0, bl.j0 - tv.y0, bl.i1 - bl.i0, bl.j1 - bl.j0,
                                         std::max(iEnd, bl.i0) - tv.x0, std::max(jEnd, bl.j0) - tv.y0});
  }
  kernels::fillBlocks(sc.fill.data(), sc.fill.size(), sc.pr.data(), sc.pg.data(), sc.pb.data(), sc.done.data(),
                      sc.stride);
  for (const Block& bl : sc.layered) fillLayeredLeaf(f, sc, tv, bl);
  for (int j = tv.y0; j < tv.y1; ++j) {
    const std::size_t at = tv.at(tv.x0, j);
    float* dst = f.out->rgb.data() + 3 * f.idx(tv.x0, j);
    const auto m = static_cast<std::size_t>(tv.x1 - tv.x0);
    if (f.add) kernels::interleaveAddRgb(sc.pr.data() + at, sc.pg.data() + at, sc.pb.data() + at, m, dst);
    else kernels::interleaveRgb(sc.pr.data() + at, sc.pg.data() + at, sc.pb.data() + at, m, dst);
  }
  kernels::flushStreams();  // the image is read by other threads once the frame is done
  sc.fillSeconds += since(tf);
}

// ---------------------------------------------------------------------------------------------
// The stages of evaluate(), in the order it runs them. The first five bring the lamps and tables
// to this frame's camera (what the kernels read); the last ones cover the image.

using State = AirlightImageEvaluator::State;
using Lamps = std::vector<AirlightEvaluator>;

// This frame's camera as the stages use it: the rotation into camera coordinates (x forward,
// y left, z up), the focal length and the principal point in pixels.
struct CameraFrame {
  explicit CameraFrame(const Camera& c)
      : cam(c), camFromWorld(glm::transpose(c.worldFromCamera)), focal(c.focalLengthPixels()),
        principal(c.principalPoint()) {}
  // A world point relative to the eye, in camera coordinates (metres).
  [[nodiscard]] Vec3 toCamera(const Vec3& world_m) const { return camFromWorld * (world_m - cam.position_m); }

  const Camera& cam;
  Mat3 camFromWorld;
  double focal;   // pixels
  Vec2 principal; // pixels, (W/2, H/2) for a centred camera
};

// Stage "prepare lamps": the isotropic lamps' kernel parameters in camera coordinates
// (st.isoParams; kernels::IsoLamp: position, K_t, the weight ϖ K_t I₀ · colour of the F-table
// formula, airlight_kernels.hpp). Lamps switched off, and lamps more than
// kMaxIsoOpticalDistance optical depths away (their airlight is below the kernels' float
// resolution), are left out of this frame. Sky-table slots are kept per isoLamps entry, so a
// lamp keeps its table while it leaves and re-enters.
void prepareIsoLamps(State& st, const Lamps& lamps, const CameraFrame& cf) {
  st.isoParams.clear();
  st.isoSlot.clear();
  st.isoSky.resize(2 * kernels::kIsoSkyNodes * st.isoLamps.size());
  st.isoSkyKey.resize(st.isoLamps.size(), {-1.0f, -1.0f});
  st.isoSkyStale.resize(st.isoLamps.size());
  for (std::size_t q = 0; q < st.isoLamps.size(); ++q) {
    const std::size_t li = st.isoLamps[q];
    if (!st.enabled[li]) continue;
    const AirlightEvaluator& ev = lamps[li];
    const Vec3 p = cf.toCamera(ev.lamp().position_m);
    const double kt = ev.medium().extinction_per_m;
    if (kt * glm::length(p) > kernels::kMaxIsoOpticalDistance) continue;
    const double i0 = std::get<IsotropicProfile>(ev.lamp().profile->model()).intensity_cd;
    kernels::IsoLamp l;
    for (int c = 0; c < 3; ++c) {
      l.pos[c] = static_cast<float>(p[c]);
      l.weight[c] = static_cast<float>(ev.medium().albedo * kt * i0 * ev.lamp().color[c]);
    }
    l.kt = static_cast<float>(kt);
    kernels::setIsoDirection(l);
    l.sky = st.isoSky.data() + 2 * kernels::kIsoSkyNodes * q;
    st.isoParams.push_back(l);
    st.isoSlot.push_back(q);
  }
}

// Stage "refresh sky tables": the per-lamp tables over the angle to the lamp that sky pixels
// of isotropic lamps read, rebuilt for the lamps whose distance or fog changed (every moving
// lamp, every frame the eye moves): ~0.1 ms each, one lamp per thread. Returns the seconds spent
// (0 when every table was current).
double refreshSkyTables(State& st, ThreadPool& pool) {
  const auto ts = std::chrono::steady_clock::now();
  bool any = false;
  for (std::size_t k = 0; k < st.isoParams.size(); ++k) {
    const kernels::IsoLamp& l = st.isoParams[k];
    const float D = std::sqrt(l.pos[0] * l.pos[0] + l.pos[1] * l.pos[1] + l.pos[2] * l.pos[2]);
    const std::array<float, 2> key{D, l.kt};
    st.isoSkyStale[k] = key != st.isoSkyKey[st.isoSlot[k]];
    if (st.isoSkyStale[k]) st.isoSkyKey[st.isoSlot[k]] = key;
    any = any || st.isoSkyStale[k];
  }
  if (!any) return 0.0;
  State* sp = &st;
  pool.parallelFor(st.isoParams.size(), [sp](std::size_t k) {
    if (!sp->isoSkyStale[k]) return;
    kernels::buildIsoSky(*sp->isoTable, sp->isoParams[k], sp->isoSky.data() + 2 * kernels::kIsoSkyNodes * sp->isoSlot[k]);
  });
  return since(ts);
}

// The kTablesPerLamp view tables of one vehicle lamp (`tables`) and its per-ray guard disc, for
// the pose in `key`: the frustum table, and when the lamp is in front of the eye the insets
// around its image. `viewD` is the distance scale shared by every vehicle lamp's tables.
void buildLampViewTables(const AirlightEvaluator& ev, const Camera& cam, const ViewKey& key, const FastPathOptions& fast,
                         double viewD, ThreadPool& pool, kernels::ViewTable* tables, State::RayGuard& guard) {
  std::optional<PencilAirlight> pencil;
  if (fast.pencil_view_tables) {
    PencilOptions po = fast.pencil_options;
    po.spoke_tolerance = 0.0;  // no plan: a table's rays read every azimuth about the lamp
    if (auto pa = PencilAirlight::build(ev, cam.position_m, po)) {
      pencil.emplace(std::move(pa).value());
      // Every spoke up front on all threads: left to the table's rows, neighbouring rows want
      // the same spoke at once and one thread waits while the other samples it.
      const PencilAirlight* pp = &*pencil;
      pool.parallelFor(static_cast<std::size_t>(pp->spokeCount()),
                       [pp](std::size_t s) { pp->prepareSpoke(static_cast<int>(s)); });
    }
  }
  const PencilAirlight* pp = pencil ? &*pencil : nullptr;
  tables[0] = kernels::ViewTable::build(ev, cam, fast.view_table_step_deg, fast.view_table_distances, pool, viewD, pp);
  for (std::size_t t = 1; t < kTablesPerLamp; ++t) tables[t] = kernels::ViewTable{};
  guard = {};
  if (key.lampInCamera.x <= 0.0) return;
  // Near its own image a lamp's airlight changes fast with direction: a 1/α peak, which
  // bilinear interpolation over a step δ follows within (δ/α)²/8 (1 % from α = 5δ), and
  // the beam's cut-off crossing the ray close to the lamp. Measured on the bench scene
  // (docs/airlight.md), the frustum table is within 1 % from 15 of its steps out. Insets,
  // each 4× finer than the last, cover the disc inside down to 5 of their own steps; the
  // pixels left (about 2 px across at 1080p) are evaluated per ray.
  constexpr double kMainGuardSteps = 15.0, kInsetRefine = 4.0, kInsetGuardSteps = 5.0;
  const double la = key.lampInCamera.y / key.lampInCamera.x, lb = key.lampInCamera.z / key.lampInCamera.x;
  double step = 1.0 / static_cast<double>(tables[0].invStep);
  double outer = kMainGuardSteps * step;
  tables[0].guardA = static_cast<float>(la);
  tables[0].guardB = static_cast<float>(lb);
  tables[0].innerR2 = static_cast<float>(outer * outer);
  for (std::size_t t = 1; t < kTablesPerLamp; ++t) {
    step /= kInsetRefine;
    const double inner = kInsetGuardSteps * step;
    const int nodes = static_cast<int>(std::ceil(2.0 * (outer + 2.0 * step) / step)) + 1;
    kernels::ViewTable& in = tables[t];
    in = kernels::ViewTable::buildWindow(ev, cam, la - outer - 2.0 * step, lb - outer - 2.0 * step, nodes, nodes, step,
                                         fast.view_table_distances, pool, viewD, pp);
    in.guardA = static_cast<float>(la);
    in.guardB = static_cast<float>(lb);
    in.outerR2 = static_cast<float>(outer * outer);
    in.innerR2 = static_cast<float>(inner * inner);
    outer = inner;
  }
  guard = {la, lb, outer * outer};
}

// Sums the frustum tables of enabled vehicle lamps of one colour (same grid) into one, and lists
// this frame's table lookups (State::tableUses): merged tables over the whole image; inside a
// merged lamp's hole, its own frustum table subtracted again (the hole is where its insets and
// per-ray guard take over); frustum tables that were not merged; insets over their rings.
// `viewTables` holds kTablesPerLamp tables per vehicle lamp, `enabled` one flag per lamp; the
// merged tables go to `merged` (mergedFrom: their members), the lookups to `uses` (they point
// into `viewTables` and `merged`).
void mergeTables(const kernels::ViewTable* viewTables, const std::vector<char>& enabled,
                 std::vector<kernels::ViewTable>& merged, std::vector<std::vector<std::size_t>>& mergedFrom,
                 std::vector<State::TableUse>& uses) {
  using TableUse = State::TableUse;
  merged.clear();
  mergedFrom.clear();
  const std::size_t nv = enabled.size();
  std::vector<char> inMerged(nv, 0);
  for (std::size_t v = 0; v < nv; ++v) {
    const kernels::ViewTable& fv = viewTables[kTablesPerLamp * v];
    if (!enabled[v] || fv.data.empty() || inMerged[v]) continue;
    std::vector<std::size_t> group{v};
    for (std::size_t u = v + 1; u < nv; ++u) {
      const kernels::ViewTable& fu = viewTables[kTablesPerLamp * u];
      if (enabled[u] && !fu.data.empty() && fu.sameGrid(fv) && fu.weight[0] == fv.weight[0] &&
          fu.weight[1] == fv.weight[1] && fu.weight[2] == fv.weight[2])
        group.push_back(u);
    }
    if (group.size() < 2) continue;
    kernels::ViewTable m = fv;  // grid, weights; the guard is cleared: it covers everything
    m.guardA = m.guardB = 0.0f;
    m.innerR2 = -1.0f;
    m.outerR2 = 3.0e38f;
    for (std::size_t k = 1; k < group.size(); ++k) m.add(viewTables[kTablesPerLamp * group[k]]);
    for (std::size_t u : group) inMerged[u] = 1;
    merged.push_back(std::move(m));
    mergedFrom.push_back(std::move(group));
  }
  uses.clear();
  for (const kernels::ViewTable& m : merged) uses.push_back(TableUse{&m, kernels::ViewTableUse::of(m)});
  for (std::size_t v = 0; v < nv; ++v) {
    if (!enabled[v]) continue;
    const kernels::ViewTable* tables = viewTables + kTablesPerLamp * v;
    if (tables[0].data.empty()) continue;
    if (!inMerged[v]) {
      uses.push_back(TableUse{&tables[0], kernels::ViewTableUse::of(tables[0])});
    } else if (tables[0].innerR2 >= 0.0f) {
      kernels::ViewTableUse minus = kernels::ViewTableUse::of(tables[0]);
      for (float& w : minus.weight) w = -w;
      minus.outerR2 = tables[0].innerR2;
      minus.innerR2 = -1.0f;
      uses.push_back(TableUse{&tables[0], minus, false, static_cast<double>(tables[0].guardA),
                                      static_cast<double>(tables[0].guardB), static_cast<double>(minus.outerR2)});
    }
    for (std::size_t t = 1; t < kTablesPerLamp; ++t) {
      const kernels::ViewTable& in = tables[t];
      if (in.data.empty()) continue;
      uses.push_back(TableUse{&in, kernels::ViewTableUse::of(in), false, static_cast<double>(in.guardA),
                                      static_cast<double>(in.guardB), static_cast<double>(in.outerR2)});
    }
  }
}

void mergeViewTables(State& st) {
  mergeTables(st.viewTables.data(), st.viewEnabled, st.merged, st.mergedFrom, st.tableUses);
  st.mergedEnabled = st.viewEnabled;
  st.mergedValid = true;
}

// Everything one vehicle lamp's view tables depend on, for the table cache.
detail::TableKey viewTableKey(const AirlightEvaluator& ev, const Camera& cam, const ViewKey& key,
                              const FastPathOptions& fast, double viewD) {
  detail::TableKey k;
  k.add("fogbeam view tables").add(static_cast<std::int64_t>(kTablesPerLamp));
  k.addProfile(*ev.lamp().profile);
  for (int c = 0; c < 3; ++c) k.add(ev.lamp().color[c]);
  // The pose within ViewKey's own tolerance (a moving vehicle's last bits vary along the road).
  for (int i = 0; i < 3; ++i) k.addNear(key.lampInCamera[i]);
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) k.addNear(key.lampAxesInCamera[i][j]);
  k.add(key.fovX).add(key.aspect).add(key.principalX).add(key.principalY).add(key.kt).add(key.albedo);
  k.add(static_cast<std::int64_t>(cam.width)).add(static_cast<std::int64_t>(cam.height));
  k.addPhase(ev.medium().phase);
  k.add(fast.view_table_step_deg).add(static_cast<std::int64_t>(fast.view_table_distances)).add(viewD);
  const AirlightOptions& o = ev.options();
  k.add(static_cast<std::int64_t>(o.g_table_theta)).add(static_cast<std::int64_t>(o.g_table_k)).add(o.g_table_k_max);
  k.add(static_cast<std::int64_t>(o.accurate_segments)).add(static_cast<std::int64_t>(o.accurate_spot_segments));
  // Rays through the pencil (every spoke: its spoke tolerance is not used) or per ray.
  k.add(static_cast<std::int64_t>(fast.pencil_view_tables ? 1 : 0));
  if (fast.pencil_view_tables) {
    const PencilOptions& po = fast.pencil_options;
    k.add(static_cast<std::int64_t>(po.spokes)).add(po.piece_deg).add(po.merge_tolerance);
    k.add(static_cast<std::int64_t>(po.kernel_expansion ? 1 : 0));
  }
  return k;
}

// The key of a vehicle lamp's view tables for this camera and the lamp's pose and fog.
ViewKey viewKeyOf(const AirlightEvaluator& ev, const CameraFrame& cf) {
  const Camera& cam = cf.cam;
  return ViewKey{cf.toCamera(ev.lamp().position_m),
                 cf.camFromWorld * ev.lamp().worldFromLamp,
                 cam.fov_x,
                 static_cast<double>(cam.height) / cam.width,
                 cf.principal.x / cam.width,
                 cf.principal.y / cam.height,
                 ev.medium().extinction_per_m,
                 ev.medium().albedo};
}

// True when every vehicle lamp's own tables were made for this frame's key.
bool ownTablesServe(const State& st, const Lamps& lamps, const CameraFrame& cf) {
  for (std::size_t v = 0; v < st.viewLamps.size(); ++v)
    if (!st.viewValid[v] || !st.viewKeys[v].sameAs(viewKeyOf(lamps[st.viewLamps[v]], cf))) return false;
  return true;
}

// Rotations equal up to rounding (the tolerance of ViewKey::sameAs, on unit-vector components).
bool sameRotation(const Mat3& a, const Mat3& b) noexcept {
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      if (std::abs(a[i][j] - b[i][j]) > 1e-7) return false;
  return true;
}
bool isIdentity(const Mat3& a) noexcept { return sameRotation(a, Mat3(1.0)); }

// The rungs of the ladder a frame reads (at most two fogs × two bending angles), each with its
// weight and, for a rung made for the lamps turned by a rotation Q about their positions, the
// rotation Qᵀ its tables are read through (ViewTableUse::rotated).
struct LadderPick {
  struct Read {
    const FogTables* rung = nullptr;
    double w = 0.0;
    bool rotated = false;
    Mat3 qT{1.0};        // camera frame: the direction a pixel's ray is read at in the rung
    double angle = 0.0;  // the rung's turn from the frame's poses, radians
  };
  std::array<Read, 4> reads;
  int n = 0;
  int fogRungs = 0;      // AirlightImage::fog_rungs
  int bendingRungs = 0;  // AirlightImage::bending_rungs
};

// The rungs that serve this frame (setFogLadder's rule), if any: made for the same lamps (profile,
// colour, order; tables for every lamp on), positions relative to the camera, frustum and
// albedo, and K_t at most ladderMaxRatio apart around the frame's. Their orientations are the
// frame's, or (bending, ladderMaxBendingRad > 0) the frame's turned by one rotation Q common
// to every lamp, about one axis for all rungs: then per fog the nearest rung turned one way and
// the nearest turned the other, at most ladderMaxBendingRad apart, are blended with the weights
// that cancel their rotations (docs/airlight.md, "Bending on the ladder").
std::optional<LadderPick> pickRungs(const State& st, const Lamps& lamps, const CameraFrame& cf) {
  const std::size_t nv = st.viewLamps.size();
  if (st.ladder.empty() || nv == 0) return std::nullopt;
  // Per thread, kept: a ladder frame asks twice (the service's viewTablesReady, then the frame),
  // and neither should allocate.
  thread_local std::vector<ViewKey> keys;
  struct Fit {
    const FogTables* rung;
    double s;  // signed angle of the rung's rotation about the common axis (0: the frame's poses)
    Mat3 qT;
  };
  thread_local std::vector<Fit> fitting;
  keys.clear();
  fitting.clear();
  for (std::size_t v = 0; v < nv; ++v) keys.push_back(viewKeyOf(lamps[st.viewLamps[v]], cf));
  const double kt = keys[0].kt;  // setFog gives every lamp the same fog
  const bool bending = st.ladderMaxBendingRad > 0.0;
  Vec3 axis(0.0);  // the common rotation axis, from the first turned rung
  // Whether rung r serves the frame's lamps, and through which rotation: Q = M_frame · M_rungᵀ
  // per lamp (camera frame), the same for every lamp on.
  auto fits = [&](const FogTables& r, Fit& out) {
    if (r.keys.size() != nv) return false;
    bool first = true;
    Mat3 q(1.0);
    for (std::size_t v = 0; v < nv; ++v) {
      const Lamp& lamp = lamps[st.viewLamps[v]].lamp();
      if (r.profiles[v].get() != lamp.profile.get() || r.colours[v] != lamp.color) return false;
      if (!st.enabled[st.viewLamps[v]]) continue;  // off this frame: its tables are not read
      if (!r.built[v]) return false;
      ViewKey k = keys[v];
      k.kt = r.kt;
      if (r.keys[v].sameAs(k)) {
        if (!first && !isIdentity(q)) return false;
        first = false;
        continue;
      }
      if (!bending) return false;
      k.lampAxesInCamera = r.keys[v].lampAxesInCamera;
      if (!r.keys[v].sameAs(k)) return false;  // position, frustum, albedo
      const Mat3 qv = keys[v].lampAxesInCamera * glm::transpose(r.keys[v].lampAxesInCamera);
      if (first) {
        q = qv;
        first = false;
      } else if (!sameRotation(q, qv)) {
        return false;
      }
    }
    out.rung = &r;
    out.qT = glm::transpose(q);
    out.s = 0.0;
    if (isIdentity(q)) return true;
    // sin φ · u from the antisymmetric part; the rung is the frame turned by −φ about u.
    const Vec3 w(q[1][2] - q[2][1], q[2][0] - q[0][2], q[0][1] - q[1][0]);
    const double sinPhi = 0.5 * glm::length(w);
    const Vec3 u = w / (2.0 * sinPhi);
    if (glm::length(axis) == 0.0) axis = u;
    const double c = glm::dot(u, axis);
    if (glm::length(glm::cross(u, axis)) > 1e-3) return false;  // another axis: not this ladder
    const double phi = std::atan2(sinPhi, 0.5 * (q[0][0] + q[1][1] + q[2][2] - 1.0));
    out.s = c > 0.0 ? phi : -phi;
    return true;
  };
  for (const auto& r : st.ladder) {
    Fit f{};
    if (fits(*r, f)) fitting.push_back(f);
  }
  // Per fog level: the rung at the frame's poses alone, else the nearest on either side of them.
  struct Level {
    LadderPick::Read a, b;
    int n = 0;
  };
  auto levelAt = [&](double levelKt, Level& out) {
    const Fit* exact = nullptr;
    const Fit* pos = nullptr;
    const Fit* neg = nullptr;
    for (const Fit& f : fitting) {
      if (f.rung->kt != levelKt) continue;
      if (f.s == 0.0) exact = &f;
      else if (f.s > 0.0 && (!pos || f.s < pos->s)) pos = &f;
      else if (f.s < 0.0 && (!neg || f.s > neg->s)) neg = &f;
    }
    if (exact) {
      out.a = {exact->rung, 1.0, false, Mat3(1.0), 0.0};
      out.n = 1;
      return true;
    }
    if (!pos || !neg || pos->s - neg->s > st.ladderMaxBendingRad * (1.0 + 1e-9)) return false;
    // Turned reads keep off at most kMaxKeep lamps' images (readLadder).
    int images = 0;
    for (std::size_t v = 0; v < pos->rung->built.size(); ++v)
      images += pos->rung->built[v] && pos->rung->tables[kTablesPerLamp * v].innerR2 > 0.0f ? 1 : 0;
    if (images > kernels::ViewTableUse::kMaxKeep) return false;
    // w₊ s₊ + w₋ s₋ = 0: the rotations' first-order errors (the eye seen from the turned lamp
    // moves by Q's turn of O − S) cancel.
    const double wPos = -neg->s / (pos->s - neg->s);
    out.a = {pos->rung, wPos, true, pos->qT, pos->s};
    out.b = {neg->rung, 1.0 - wPos, true, neg->qT, neg->s};
    out.n = 2;
    return true;
  };
  // The fog levels: the frame's K_t itself, else the nearest below and above that serve.
  double lo = -1.0, hi = -1.0;
  Level levelLo, levelHi;
  for (const Fit& f : fitting) {
    const double k = f.rung->kt;
    Level l;
    if (k <= kt && (lo < 0.0 || k > lo) && levelAt(k, l)) {
      lo = k;
      levelLo = l;
    }
    if (k >= kt && (hi < 0.0 || k < hi) && levelAt(k, l)) {
      hi = k;
      levelHi = l;
    }
  }
  LadderPick pick;
  auto take = [&](const Level& l, double w) {
    for (int i = 0; i < l.n; ++i) {
      LadderPick::Read r = i == 0 ? l.a : l.b;
      r.w *= w;
      pick.reads[static_cast<std::size_t>(pick.n++)] = r;
    }
    pick.bendingRungs = l.n == 2 ? 2 : 0;
  };
  if (lo == kt || hi == kt) {
    take(lo == kt ? levelLo : levelHi, 1.0);
    pick.fogRungs = 1;
    return pick;
  }
  if (lo < 0.0 || hi < 0.0 || hi > lo * st.ladderMaxRatio * (1.0 + 1e-12)) return std::nullopt;
  const double w = std::log(kt / lo) / std::log(hi / lo);
  take(levelLo, 1.0 - w);
  take(levelHi, w);
  pick.fogRungs = 2;
  return pick;
}

// A rung's tables merged for this frame's enabled lamps (as mergeViewTables merges the own
// ones), kept in State::rungMerges: a ramp reads each rung over several frames, and a merge
// copies and sums whole tables (tens of milliseconds at 1280×720). The rung's own merge when it
// was made for this set of lamps; else the least recently used slot is taken.
const std::vector<State::TableUse>& rungMerge(State& st, const FogTables& rung, double& seconds) {
  if (rung.mergedFor == st.viewEnabled) return rung.uses;
  for (State::RungMerge& m : st.rungMerges)
    if (m.rung == &rung && m.enabled == st.viewEnabled) {
      m.lastUse = st.frameCount;
      return m.uses;
    }
  State::RungMerge* slot = &st.rungMerges[0];
  for (State::RungMerge& m : st.rungMerges)
    if (m.lastUse < slot->lastUse) slot = &m;
  const auto t = std::chrono::steady_clock::now();
  std::vector<std::vector<std::size_t>> members;
  mergeTables(rung.tables.data(), st.viewEnabled, slot->merged, members, slot->uses);
  slot->rung = &rung;
  slot->enabled = st.viewEnabled;
  slot->lastUse = st.frameCount;
  seconds += since(t);
  return slot->uses;
}

// This frame's table lookups from the ladder: each rung's lookups with its weight (1 − w and w,
// linear in ln K_t; a rung at the frame's K_t alone), and the rung's per-ray guards (they
// depend on the pose only). The own tables are left as they are, their lookups listed again
// when they next serve. Returns the seconds spent merging.
double readLadder(State& st, const LadderPick& pick) {
  double seconds = 0.0;
  st.tableUses.clear();
  // Turned reads keep off the lamps' images: within the frustum table's hole around each image,
  // widened by the farthest a read moves there (a turn by φ moves a direction near (a, b) by at
  // most φ (1 + a² + b²) in tangent units), every table is read unturned (ViewTableUse::keepA).
  // Their frustum tables' holes are those of the first rung read (they depend on the lamps'
  // positions and the frustum alone).
  kernels::ViewTableUse keep;
  if (pick.bendingRungs > 0) {
    double phi = 0.0;
    for (int i = 0; i < pick.n; ++i)
      if (pick.reads[static_cast<std::size_t>(i)].rotated)
        phi = std::max(phi, std::abs(pick.reads[static_cast<std::size_t>(i)].angle));
    const FogTables& first = *pick.reads[0].rung;
    for (std::size_t v = 0; v < first.built.size(); ++v) {
      const kernels::ViewTable& frustum = first.tables[kTablesPerLamp * v];
      if (!first.built[v] || frustum.data.empty() || !(frustum.innerR2 > 0.0f)) continue;
      if (keep.nKeep == kernels::ViewTableUse::kMaxKeep) break;  // pickRungs allows no more
      const double ga = frustum.guardA, gb = frustum.guardB;
      const double r = std::sqrt(static_cast<double>(frustum.innerR2)) + 1.25 * phi * (1.0 + ga * ga + gb * gb);
      const int k = keep.nKeep++;
      keep.keepA[k] = frustum.guardA;
      keep.keepB[k] = frustum.guardB;
      keep.keepR2[k] = static_cast<float>(r * r);
    }
  }
  for (int i = 0; i < pick.n; ++i) {
    const LadderPick::Read& r = pick.reads[static_cast<std::size_t>(i)];
    if (r.w <= 0.0) continue;
    for (State::TableUse tu : rungMerge(st, *r.rung, seconds)) {
      for (float& x : tu.use.weight) x = static_cast<float>(static_cast<double>(x) * r.w);
      if (r.rotated) {
        tu.use.rotated = true;
        for (int row = 0; row < 3; ++row)
          for (int col = 0; col < 3; ++col) tu.use.rot[3 * row + col] = static_cast<float>(r.qT[col][row]);
        tu.use.nKeep = keep.nKeep;
        for (int k = 0; k < keep.nKeep; ++k) {
          tu.use.keepA[k] = keep.keepA[k];
          tu.use.keepB[k] = keep.keepB[k];
          tu.use.keepR2[k] = keep.keepR2[k];
        }
      }
      st.tableUses.push_back(tu);
    }
  }
  st.frameGuards = pick.reads[0].rung->guards;  // they depend on the lamps' positions alone
  st.mergedValid = false;
  st.fogRungs = pick.fogRungs;
  st.bendingRungs = pick.bendingRungs;
  return seconds;
}

// Stage "refresh view tables": the vehicle lamps' view tables, rebuilt only for lamps whose pose
// relative to the camera, the frustum or the fog changed (ViewKey; a table costs seconds, a
// fixed rig builds once), then merged again when a table or the set of enabled lamps changed.
// When the own tables do not serve the frame and two rungs of the fog ladder do, those are read
// instead (readLadder). `rung` = true (buildFogTables): only the lamps that are on, no merge.
// Returns the seconds spent building and merging.
double refreshViewTables(State& st, const Lamps& lamps, ThreadPool& pool, const CameraFrame& cf, bool rung = false) {
  const Camera& cam = cf.cam;
  double seconds = 0.0;
  ++st.frameCount;
  st.fogRungs = 0;
  st.bendingRungs = 0;
  for (std::size_t v = 0; v < st.viewLamps.size(); ++v) st.viewEnabled[v] = st.enabled[st.viewLamps[v]];
  if (!st.ladder.empty() && !ownTablesServe(st, lamps, cf))
    if (const std::optional<LadderPick> pick = pickRungs(st, lamps, cf)) return readLadder(st, *pick);
  // One distance scale for every vehicle lamp's tables, so that their frustum tables share a
  // grid and can be merged.
  double viewD = 0.0;
  for (std::size_t v = 0; v < st.viewLamps.size(); ++v) {
    const AirlightEvaluator& ev = lamps[st.viewLamps[v]];
    viewD = std::max(viewD, kernels::ViewTable::defaultDistanceScale(
                                ev.medium().extinction_per_m, glm::length(ev.lamp().position_m - cam.position_m)));
  }
  bool viewChanged = false;
  for (std::size_t v = 0; v < st.viewLamps.size(); ++v) {
    const AirlightEvaluator& ev = lamps[st.viewLamps[v]];
    const ViewKey key = viewKeyOf(ev, cf);
    if (rung && !st.viewEnabled[v]) continue;
    if (st.viewValid[v] && st.viewKeys[v].sameAs(key)) continue;
    viewChanged = true;
    kernels::ViewTable* tables = st.viewTables.data() + kTablesPerLamp * v;
    if (!st.fast.table_cache_dir.empty()) {
      const detail::TableKey tk = viewTableKey(ev, cam, key, st.fast, viewD);
      detail::LampTables lt{tables, kTablesPerLamp};
      const auto tl = std::chrono::steady_clock::now();
      if (detail::loadLampTables(st.fast.table_cache_dir, tk, lt)) {
        st.rayGuards[v] = {lt.guard[0], lt.guard[1], lt.guard[2]};
        st.viewKeys[v] = key;
        st.viewValid[v] = true;
        ++st.tablesLoaded;
        seconds += since(tl);
        continue;
      }
      buildLampViewTables(ev, cam, key, st.fast, viewD, pool, tables, st.rayGuards[v]);
      const State::RayGuard& g = st.rayGuards[v];
      lt.guard[0] = g.a;
      lt.guard[1] = g.b;
      lt.guard[2] = g.r2;
      if (Status stored = detail::storeLampTables(st.fast.table_cache_dir, tk, lt); !stored)
        st.tableCacheError = stored.error().message;
    } else {
      buildLampViewTables(ev, cam, key, st.fast, viewD, pool, tables, st.rayGuards[v]);
    }
    st.viewKeys[v] = key;
    st.viewValid[v] = true;
    for (std::size_t t = 0; t < kTablesPerLamp; ++t) seconds += tables[t].build_seconds;
  }
  if (viewChanged || st.mergedEnabled != st.viewEnabled) st.mergedValid = false;
  if (!st.mergedValid && !rung) {
    const auto tm = std::chrono::steady_clock::now();
    mergeViewTables(st);
    seconds += since(tm);
  }
  st.frameGuards = st.rayGuards;
  return seconds;
}

// Stage "cull moving lamps" (FastPathOptions::moving_lamp_cutoff_cd_m2): per moving lamp that is
// on, the cone about its image outside which AirlightBound bounds its light by its share of the
// cutoff (the cutoff over the lamps on, per channel: together they lose at most the cutoff at any
// pixel), and whether that cone misses the view (the largest angle between the view's centre
// ray and a corner ray: a pinhole's rays all lie within it). Measured on a dense-traffic frame in
// docs/airlight.md ("Moving lamps that cannot matter").
void cullMovingLamps(State& st, const Lamps& lamps, const CameraFrame& cf, double kt, double albedo) {
  const std::size_t nq = st.pencilLamps.size();
  st.cullDir.assign(nq, Vec3(1, 0, 0));
  st.cullCos.assign(nq, -2.0);
  st.culled.assign(nq, 0);
  st.culledCount = 0;
  st.droppedCount = 0;
  const double cutoff = st.fast.moving_lamp_cutoff_cd_m2;
  if (nq == 0 || !st.bound) return;
  std::size_t on = 0;
  for (std::size_t q = 0; q < nq; ++q) on += st.enabled[st.pencilLamps[q]] ? 1u : 0u;
  if (on == 0) return;
  const double share = cutoff > 0.0 ? cutoff / static_cast<double>(on) : 0.0;
  const PixelRays rays(cf.cam);
  const Vec3 centre = rays.direction(cf.principal.x, cf.principal.y);
  const double w = cf.cam.width, h = cf.cam.height;
  double half = 0.0;  // the view's half-angle about its centre ray (to the farthest corner)
  for (const Vec2& c : {Vec2(0, 0), Vec2(w, 0), Vec2(0, h), Vec2(w, h)})
    half = std::max(half, std::acos(std::clamp(glm::dot(centre, rays.direction(c.x, c.y)), -1.0, 1.0)));
  st.ranked.clear();
  for (std::size_t q = 0; q < nq; ++q) {
    const std::size_t li = st.pencilLamps[q];
    if (!st.enabled[li]) continue;
    const Vec3 rel = lamps[li].lamp().position_m - cf.cam.position_m;
    const double d = glm::length(rel);
    if (!(d > 1e-6)) {  // the eye at the lamp: no bound, first for the budget
      st.ranked.emplace_back(std::numeric_limits<double>::infinity(), q);
      continue;
    }
    const double factor = AirlightBound::factor(st.pencilPeak[q], d, kt, albedo);
    st.ranked.emplace_back(factor, q);
    const double cone = st.bound->coneHalfAngle(factor, share);  // share 0: never
    if (cone > kPi) continue;
    st.cullDir[q] = rel / d;
    st.cullCos[q] = std::cos(cone);
    const double fromCentre = std::acos(std::clamp(glm::dot(centre, st.cullDir[q]), -1.0, 1.0));
    if (fromCentre - cone > half) {
      st.culled[q] = 1;
      ++st.culledCount;
    }
  }
  // The budget: of the lamps left, the brightest by their bound's factor (the eye at a lamp:
  // +inf, kept first); ties in scene order, so that equal frames drop the same lamps.
  const int budget = st.fast.max_moving_lamps;
  std::erase_if(st.ranked, [&](const auto& r) { return st.culled[r.second] != 0; });
  if (budget > 0 && st.ranked.size() > static_cast<std::size_t>(budget)) {
    // std::sort with the scene order as tie-break: the same order as a stable sort, without the
    // buffer std::stable_sort allocates (steady frames allocate nothing).
    std::sort(st.ranked.begin(), st.ranked.end(),
              [](const auto& a, const auto& b) { return a.first > b.first || (a.first == b.first && a.second < b.second); });
    for (std::size_t k = static_cast<std::size_t>(budget); k < st.ranked.size(); ++k) {
      const std::size_t q = st.ranked[k].second;
      st.culled[q] = 1;
      ++st.droppedCount;
    }
  }
}

// Stage "refresh pencils": moving lamps through the pencil get a new integrator state when the
// eye or the lamp moved (spokes are then sampled again as pixels need them; their memory is
// kept). An integrator that cannot be built leaves the lamp dark for the frame (its options
// were validated at build(), so this does not happen with valid lamps).
void refreshPencils(State& st, const Lamps& lamps, const Camera& cam) {
  st.pencils.resize(st.pencilLamps.size());
  st.pencilKeys.resize(st.pencilLamps.size());
  for (std::size_t q = 0; q < st.pencilLamps.size(); ++q) {
    if (st.culled[q]) continue;  // out of this frame: refreshed when it is back
    const AirlightEvaluator& ev = lamps[st.pencilLamps[q]];
    const State::PencilKey key{&ev, cam.position_m, ev.lamp().position_m, ev.lamp().worldFromLamp,
                               ev.medium().extinction_per_m, ev.medium().albedo};
    State::PencilKey& old = st.pencilKeys[q];
    const bool same = st.pencils[q] && old.lamp == key.lamp && old.eye == key.eye && old.position == key.position &&
                      old.axes == key.axes && old.kt == key.kt && old.albedo == key.albedo;
    if (same) continue;
    if (st.pencils[q] && old.lamp == key.lamp) {
      st.pencils[q]->reset(cam.position_m);
    } else {
      auto pa = PencilAirlight::build(ev, cam.position_m, st.fast.pencil_options);
      if (pa) st.pencils[q].emplace(std::move(pa).value());
      else st.pencils[q].reset();
    }
    old = key;
  }
}

// Stage "sample spokes" (MovingLampPath::Pencil): the spokes of every enabled pencil that this
// frame's rays read, sampled on all threads at once. Left to the rays, neighbouring pixels of
// one tile need the same spokes at the same time and the other threads wait while one samples
// them (measured: at 320×180 four oncoming low beams took 100 ms of airlight a frame, 66 ms
// through the per-lamp maps, which sample one lamp per thread). The azimuths read are those
// between the azimuths of neighbouring rays of an 8 px grid (the shorter way round), each
// widened by one spoke. Over them the pencil's adaptive plan (PencilAirlight::coarseStep):
// every 32nd spoke, then the middles of the intervals whose middle rays would read the blend of
// its ends wrongly (PencilAirlight::middleDiffers), level by level down to single spokes
// (measured on the traffic bench at 1280×720: 2 188 of the 5 760 spokes the four oncoming low
// beams read, 40 → ~17 ms a frame, the image's error against per ray unchanged). Returns the
// spokes sampled this frame; `kept` counts those the plan read that an earlier frame sampled
// (a pencil keeps them while the lamp's pose relative to the eye holds: PencilAirlight::reset).
std::size_t sampleSpokes(State& st, const CameraFrame& cf, ThreadPool& pool, std::size_t& kept) {
  kept = 0;
  if (st.fast.moving_lamps != MovingLampPath::Pencil) return 0;
  const Camera& cam = cf.cam;
  std::size_t sampled = 0;
  st.spokeJobs.clear();
  st.spokeIntervals.clear();
  constexpr int kStep = 8;
  // A grid cell's diagonal as an angle, with room to spare (pixels subtend at most 1/focal).
  const double margin = 2.0 * std::sqrt(2.0) * kStep / cf.focal;
  const int nx = (cam.width + kStep - 1) / kStep + 1, ny = (cam.height + kStep - 1) / kStep + 1;
  for (std::size_t q = 0; q < st.pencilLamps.size(); ++q) {
    if (!pencilOn(st, q)) continue;
    const PencilAirlight& pa = *st.pencils[q];
    const int n = pa.spokeCount();
    // Grid rays outside the lamp's cone (cullMovingLamps), widened by a grid cell's diagonal,
    // read no spoke: no pixel near them evaluates the lamp.
    const double outside = st.cullCos[q] < -1.0 ? -2.0 : std::cos(std::min(kPi, std::acos(st.cullCos[q]) + margin));
    st.gridSpokes.resize(static_cast<std::size_t>(nx) * static_cast<std::size_t>(ny));
    // One pointer to the pool (std::function keeps small captures without allocating).
    const struct {
      const PencilAirlight* pa;
      const Camera* cam;
      PixelRays rays;
      int* out;
      int nx, step;
      Vec3 dir;
      double outside;
    } grid{&pa, &cam, PixelRays(cam), st.gridSpokes.data(), nx, kStep, st.cullDir[q], outside};
    const auto* gp = &grid;
    pool.parallelFor(static_cast<std::size_t>(ny), [gp](std::size_t row) {
      const int j = static_cast<int>(row);
      for (int i = 0; i < gp->nx; ++i) {
        const double x = std::min(i * gp->step, gp->cam->width - 1) + 0.5, y = std::min(j * gp->step, gp->cam->height - 1) + 0.5;
        const Vec3 ray = gp->rays.direction(x, y);
        gp->out[row * static_cast<std::size_t>(gp->nx) + static_cast<std::size_t>(i)] =
            glm::dot(ray, gp->dir) <= gp->outside ? -1 : gp->pa->spokeOf(ray);
      }
    });
    // The azimuths read: per pair of neighbouring grid rays the spokes between theirs (the
    // shorter way round) widened by one, added as +1/−1 at the ends of a difference array and
    // summed once (~60 k pairs per lamp at 1280×720: marking spoke by spoke took ~3 ms a frame,
    // serial). Spoke indices are in [0, n); an interval's ends may pass 0 or n: split.
    st.spokeCover.assign(static_cast<std::size_t>(n) + 1, 0);
    auto cover = [&](int lo, int hi) {  // [lo, hi] within [0, n)
      ++st.spokeCover[static_cast<std::size_t>(lo)];
      --st.spokeCover[static_cast<std::size_t>(hi) + 1];
    };
    auto mark = [&](int a, int b) {
      if (a < 0 || b < 0) return;
      int d = b - a;
      if (d < 0) d += n;
      int from = a;
      if (d > n / 2) {
        from = b;
        d = n - d;
      }
      const int lo = from - 1, hi = from + d + 1;
      if (hi - lo + 1 >= n) {
        cover(0, n - 1);
      } else if (lo < 0) {
        cover(lo + n, n - 1);
        cover(0, hi);
      } else if (hi >= n) {
        cover(lo, n - 1);
        cover(0, hi - n);
      } else {
        cover(lo, hi);
      }
    };
    for (int j = 0; j < ny; ++j)
      for (int i = 0; i < nx; ++i) {
        const int a = st.gridSpokes[static_cast<std::size_t>(j) * static_cast<std::size_t>(nx) + static_cast<std::size_t>(i)];
        if (i + 1 < nx) mark(a, st.gridSpokes[static_cast<std::size_t>(j) * static_cast<std::size_t>(nx) + static_cast<std::size_t>(i + 1)]);
        if (j + 1 < ny) mark(a, st.gridSpokes[static_cast<std::size_t>(j + 1) * static_cast<std::size_t>(nx) + static_cast<std::size_t>(i)]);
      }
    st.spokeMask.assign(static_cast<std::size_t>(n), 0);
    for (int k = 0, run = 0; k < n; ++k) {
      run += st.spokeCover[static_cast<std::size_t>(k)];
      st.spokeMask[static_cast<std::size_t>(k)] = run > 0 ? 1 : 0;
    }
    // The plan: every coarseStep()-th spoke of the coarse intervals that hold an azimuth read
    // (with coarseStep() = 1 that is every spoke read, as before).
    const int step = pa.coarseStep();
    for (int a = 0; a < n; a += step) {
      bool read = false;
      for (int k = a; k < a + step && !read; ++k) read = st.spokeMask[static_cast<std::size_t>(k)] != 0;
      if (read) st.spokeIntervals.push_back({q, a, step});
    }
  }
  // Sampling passes, each on all threads: the coarse intervals' ends, then the middles of the
  // intervals still open, level by level; an interval whose middle is the blend of its ends
  // becomes two leaves, one of single spokes always does.
  auto sampleAll = [&] {
    if (st.spokeJobs.empty()) return;
    std::sort(st.spokeJobs.begin(), st.spokeJobs.end());  // interval ends are shared
    st.spokeJobs.erase(std::unique(st.spokeJobs.begin(), st.spokeJobs.end()), st.spokeJobs.end());
    std::atomic<std::size_t> fresh{0};
    pool.parallelFor(st.spokeJobs.size(), [&](std::size_t k) {
      const auto& [q, spoke] = st.spokeJobs[k];
      if (st.pencils[q]->prepareSpoke(spoke)) fresh.fetch_add(1, std::memory_order_relaxed);
    });
    sampled += fresh.load();
    kept += st.spokeJobs.size() - fresh.load();
    st.spokeJobs.clear();
  };
  for (const auto& iv : st.spokeIntervals) {
    const int n = st.pencils[iv.q]->spokeCount();
    st.spokeJobs.emplace_back(iv.q, iv.a);
    st.spokeJobs.emplace_back(iv.q, (iv.a + iv.w) % n);
  }
  while (true) {
    for (const auto& iv : st.spokeIntervals)
      if (iv.w > 1) st.spokeJobs.emplace_back(iv.q, iv.a + iv.w / 2);
    sampleAll();
    // The tests of the intervals' middles on all threads (middleDiffers reads the sampled
    // projections only): serial, they were ~3 ms of a traffic frame with the other thread idle.
    st.spokeDiffers.assign(st.spokeIntervals.size(), 0);
    pool.parallelFor(st.spokeIntervals.size(), [&](std::size_t k) {
      const auto& iv = st.spokeIntervals[k];
      st.spokeDiffers[k] = iv.w > 2 && st.pencils[iv.q]->middleDiffers(iv.a, iv.w) ? 1 : 0;
    });
    st.nextIntervals.clear();
    for (std::size_t k = 0; k < st.spokeIntervals.size(); ++k) {
      const auto& iv = st.spokeIntervals[k];
      PencilAirlight& pa = *st.pencils[iv.q];
      if (iv.w == 1) {
        pa.setLeaf(iv.a, 1);
      } else if (!st.spokeDiffers[k]) {
        pa.setLeaf(iv.a, iv.w / 2);
        pa.setLeaf(iv.a + iv.w / 2, iv.w / 2);
      } else {
        st.nextIntervals.push_back({iv.q, iv.a, iv.w / 2});
        st.nextIntervals.push_back({iv.q, iv.a + iv.w / 2, iv.w / 2});
      }
    }
    st.spokeIntervals.swap(st.nextIntervals);
    if (st.spokeIntervals.empty()) break;
  }
  return sampled;
}

// Stage "refresh lamp maps" (MovingLampPath::Map): each enabled moving lamp's own adaptive
// sampling of this frame, at the frame's distances (render/lamp_map.hpp): rebuilt every frame,
// since the surfaces in front of the lamps may change with nothing else moving. The distance
// edges are found once for all the maps, with the subsampling's own rule.
void refreshLampMaps(State& st, const Camera& cam, const SurfaceBuffers& surface, const SubsamplingOptions& opt,
                     double kt, ThreadPool& pool) {
  st.mapSeconds = 0.0;
  st.mapNodes = 0;
  if (st.fast.moving_lamps != MovingLampPath::Map) return;
  st.maps.resize(st.pencilLamps.size());
  bool any = false;
  for (std::size_t q = 0; q < st.pencilLamps.size(); ++q)
    any = any || pencilOn(st, q);
  if (!any) return;
  const auto t0 = std::chrono::steady_clock::now();
  const double far = opt.edge_transmittance > 0.0 && kt > 0.0 ? -std::log(opt.edge_transmittance) / kt : 0.0;
  st.depthEdges.build(surface.distance.data(), cam.width, cam.height, st.fast.lamp_map_options.coarse_px,
                      opt.depth_edge_rel, far, pool);
  for (std::size_t q = 0; q < st.pencilLamps.size(); ++q) {
    if (!pencilOn(st, q)) continue;
    LampMap& m = st.maps[q];
    m.build(*st.pencils[q], cam, st.depthEdges, st.fast.lamp_map_options, pool);
    st.mapNodes += m.stats().nodes;
  }
  st.mapSeconds = since(t0);
}

// Stage "locate lamps": the image positions (pixels, x right, y down) of the enabled lamps in
// front of the camera (st.lampPixels, capacity kept between frames). A lamp's own image is a
// peak of airlight that a block's corners cannot see: the block test splits blocks within
// lamp_guard_px of one.
void locateLampImages(State& st, const Lamps& lamps, const CameraFrame& cf) {
  st.lampPixels.clear();
  auto locate = [&](std::size_t li) {
    const Vec3 p = cf.toCamera(lamps[li].lamp().position_m);
    if (p.x <= 0.0) return;
    st.lampPixels.emplace_back(cf.principal.x - cf.focal * p.y / p.x, cf.principal.y - cf.focal * p.z / p.x);
  };
  // Every lamp is in exactly one routing list; moving lamps left out of the frame
  // (cullMovingLamps) have no image to guard.
  for (const std::vector<std::size_t>* group : {&st.isoLamps, &st.viewLamps, &st.rayLamps})
    for (std::size_t li : *group)
      if (st.enabled[li]) locate(li);
  // Not pencilOn(), deliberately: a lamp on and not culled whose integrator could not be built
  // this frame keeps the guard around its image all the same.
  for (std::size_t q = 0; q < st.pencilLamps.size(); ++q)
    if (st.enabled[st.pencilLamps[q]] && !st.culled[q]) locate(st.pencilLamps[q]);
}

// Stage "plan the image": the frame's context for the image stages: coarse step, the distance
// beyond which edges are ignored, the tiles and the coarse grid; `add`: Write::Add (the pixels go
// onto out's values).
FrameCtx planImage(const State& st, const Lamps& lamps, const Scene& scene, const SurfaceBuffers& surface,
                   const SubsamplingOptions& opt, AirlightImage& out, bool add, const CameraFrame& cf) {
  const Camera& cam = cf.cam;
  FrameCtx f{&st, &lamps, &cam, &surface, &out, add,
             kernels::PixelGeometry{static_cast<float>(cf.principal.x), static_cast<float>(cf.principal.y),
                                    static_cast<float>(1.0 / cf.focal)},
             &opt, PixelRays(cam)};
  f.step = opt.coarse_step > 0 ? std::max(2, opt.coarse_step) : autoCoarseStep(cam);
  // Distance edges wholly beyond d_far, where the fog's transmittance e^{−K_t d} is below
  // edge_transmittance, are ignored: whatever lies behind them reaches the eye dimmed by at
  // least that factor, below the block tolerance (the horizon, distant trees).
  const double etr = opt.edge_transmittance;
  if (etr > 0.0 && etr < 1.0 && scene.fog.extinction_per_m > 0.0)
    f.edgeFloor = static_cast<float>(scene.fog.extinction_per_m / -std::log(etr));
  f.tile = f.step * std::max(1, kTile / f.step);
  f.tilesX = tilesAlong(cam.width, f.tile);
  f.tilesY = tilesAlong(cam.height, f.tile);
  f.coarseX = cam.width <= 1 ? 1 : (cam.width - 1 + f.step - 1) / f.step + 1;
  f.coarseY = cam.height <= 1 ? 1 : (cam.height - 1 + f.step - 1) / f.step + 1;
  if (!opt.full && st.fast.moving_lamps == MovingLampPath::Pencil && !st.pencilLamps.empty()) {
    f.nq = st.pencilLamps.size();
    f.mlLum = st.pencilLum.data();
    if (opt.moving_lattice) {
      f.superX = (f.coarseX - 1) / 2;
      f.superY = (f.coarseY - 1) / 2;
      if (f.superX == 0 || f.superY == 0) f.superX = f.superY = 0;
      if (f.superX > 0 && opt.moving_lattice_levels >= 2) {
        f.hyperX = (f.coarseX - 1) / 4;
        f.hyperY = (f.coarseY - 1) / 4;
        if (f.hyperX == 0 || f.hyperY == 0) f.hyperX = f.hyperY = 0;
      }
    }
  }
  return f;
}

// Per-thread memory (Scratch), sized on the first frame and when the tile size grows, so that
// steady frames allocate nothing; the frame's figures are reset.
void ensureScratch(State& st, const FrameCtx& f, std::size_t threads, std::size_t lampCount) {
  const std::size_t side = static_cast<std::size_t>(f.tile) + 1;
  const std::size_t batch = kernels::paddedSize(std::max(side * side, kChunk));
  if (st.scratch.size() != threads || st.scratchBatch < batch || st.scratchTile < side || st.scratchNq < f.nq) {
    st.scratch.assign(threads, Scratch{});
    for (Scratch& sc : st.scratch) {
      for (auto* v : {&sc.x, &sc.y, &sc.d, &sc.r, &sc.g, &sc.b, &sc.sx, &sc.sy, &sc.sd, &sc.sr, &sc.sg, &sc.sb})
        v->assign(batch, 0.0f);
      sc.slot.assign(batch, 0);
      sc.sidx.assign(batch, 0);
      // Plane rows padded for whole vectors past the region (fillBlocks, distanceEdgeBits).
      sc.stride = (side + 16 + 15) / 16 * 16;
      sc.qStride = (side + 3 + 17 + 15) / 16 * 16;
      sc.edgeWords = (side + 2 + 63) / 64 + 1;
      for (auto* v : {&sc.pr, &sc.pg, &sc.pb}) v->assign(sc.stride * (side + 1), 0.0f);
      sc.done.assign(sc.stride * (side + 1), 0);
      sc.q.assign(sc.qStride * (side + 2), 0.0f);
      sc.edges.assign(sc.edgeWords * side, 0);
      sc.cur.reserve(side * side);
      sc.next.reserve(side * side);
      sc.leaves.reserve(side * side);
      sc.layered.reserve(side * side);
      sc.tileLamps.reserve(lampCount);
      sc.fill.reserve(side * side);
      sc.ml.assign(batch * f.nq, 0.0f);
      sc.dev.assign(f.nq, 0.0f);
      sc.order.assign(f.nq, 0);
      sc.grant.assign(f.nq, 0);
      sc.pml.assign(sc.stride * (side + 1) * f.nq, 0.0f);
    }
    st.scratchBatch = batch;
    st.scratchTile = side;
    st.scratchNq = f.nq;
  }
  for (Scratch& sc : st.scratch) {
    sc.evaluated = 0;
    sc.movingEvaluated = 0;
    sc.evalSeconds = sc.judgeSeconds = sc.fillSeconds = 0.0;
  }
}

// What the image stages hand to the pool: two pointers, which std::function stores without
// allocating (steady frames allocate nothing).
struct ImageJob {
  State* st;
  const FrameCtx* f;
};

std::size_t tileCount(const FrameCtx& f) {
  return static_cast<std::size_t>(f.tilesX) * static_cast<std::size_t>(f.tilesY);
}

// Coarse-grid corners per task: at least four tasks per thread where the grid allows (a frame's
// moving lamps gather in a few places, and with a handful of large tasks one thread is left with
// them), in whole SIMD vectors of any width (multiples of 64), 256 to kChunk.
std::size_t coarseChunk(const FrameCtx& f, std::size_t threads) {
  const std::size_t n = static_cast<std::size_t>(f.coarseX) * static_cast<std::size_t>(f.coarseY);
  const std::size_t want = (n + 4 * threads - 1) / (4 * std::max<std::size_t>(threads, 1));
  return std::clamp<std::size_t>((want + 63) / 64 * 64, 256, kChunk);
}

// Runs fn(tile, worker) over every tile, the costliest of the last frame first (State::tileOrder;
// the image does not depend on the order: each tile writes its own pixels), and keeps each
// tile's thread time for the next frame.
template <class Fn>
void runTiles(State& st, const FrameCtx& f, ThreadPool& pool, const Fn& fn) {
  const std::size_t n = tileCount(f);
  if (st.tileOrder.size() != n) {
    st.tileOrder.resize(n);
    st.tileSeconds.assign(n, 0.0);
    for (std::size_t t = 0; t < n; ++t) st.tileOrder[t] = static_cast<std::uint32_t>(t);
  } else {
    std::sort(st.tileOrder.begin(), st.tileOrder.end(), [&](std::uint32_t a, std::uint32_t b) {
      return st.tileSeconds[a] != st.tileSeconds[b] ? st.tileSeconds[a] > st.tileSeconds[b] : a < b;
    });
  }
  State* sp = &st;
  pool.parallelForIndexed(n, [sp, &fn](std::size_t k, unsigned w) {
    const std::size_t t = sp->tileOrder[k];
    const auto t0 = std::chrono::steady_clock::now();
    fn(t, w);
    sp->tileSeconds[t] = since(t0);
  });
}

// Stage "full tiles" (SubsamplingOptions::full): every pixel evaluated, tile by tile.
void evaluateFullTiles(State& st, const FrameCtx& f, ThreadPool& pool) {
  runTiles(st, f, pool, [&](std::size_t t, unsigned w) { fullTile(f, st.scratch[w], t); });
}

// The lattice passes' batches: coarse node (i, j) (pixel), `slot` its index from the chunk's
// first node b0, queued in sc after its moving lamps' known values (sc.ml, NaN: evaluate).
void queueCoarseNode(const FrameCtx& f, Scratch& sc, int i, int j, std::size_t slot) {
  sc.x[sc.n] = static_cast<float>(i) + 0.5f;
  sc.y[sc.n] = static_cast<float>(j) + 0.5f;
  sc.d[sc.n] = f.surf->distance[f.idx(i, j)];
  sc.slot[sc.n] = static_cast<std::uint32_t>(slot);
  ++sc.n;
}

// The queued nodes' moving lamps (the rest of each node is in the grid already; known values are
// read, not evaluated; no sky grouping: the pencil goes pixel by pixel), added to the coarse grid
// and its moving-lamp values; the queue emptied.
void addMovingToCoarseNodes(const FrameCtx& f, State& s, Scratch& sc, std::size_t b0) {
  if (sc.n == 0) return;
  const std::size_t m = f.nq;
  sc.mlActive = true;
  sc.movingOnly = true;
  evaluateBatch(f, sc);
  sc.movingOnly = false;
  sc.mlActive = false;
  for (std::size_t k = 0; k < sc.n; ++k) {
    const std::size_t node = b0 + sc.slot[k];
    float* p = s.coarse.data() + 3 * node;
    p[0] += sc.r[k];
    p[1] += sc.g[k];
    p[2] += sc.b[k];
    std::copy_n(sc.ml.data() + k * m, m, s.coarseMl.data() + node * m);
  }
  sc.n = 0;
}

// The lattice's second level (SubsamplingOptions::moving_lattice_levels = 2), before
// movingLattice. The first pass evaluated the moving lamps, inside whole cells of 4 × 4 coarse
// blocks, at the cells' corners and centres only. A cell passes for a lamp on the test of
// movingLattice one level up: no lamp imaged within lamp_guard_px + 4 coarse steps of it (near
// a lamp's image its light has structure a test at one centre per 32 px could miss), its 25
// nodes and 16 block centres in the centre's distance layer, and the lamp's value at its centre
// the bilinear prediction from its corners within what grantBudget grants. Then the first
// level's anchors inside the cell (the corners and centres of its 2 × 2 super-cells) take that
// interpolation where the cell passes (those on a side where a cell on either side passes: the
// interpolation along a side is linear between its corners from both), else they are
// evaluated; movingLattice then judges the super-cells as before (inside a passing cell they
// pass: their values are one bilinear function).
void hyperLattice(State& st, const FrameCtx& f, ThreadPool& pool) {
  const std::size_t nq = f.nq;
  st.hyperPass.assign(static_cast<std::size_t>(f.hyperX) * static_cast<std::size_t>(f.hyperY) * nq, 0);
  const ImageJob job{&st, &f};
  const ImageJob* jp = &job;
  pool.parallelForIndexed(static_cast<std::size_t>(f.hyperY), [jp](std::size_t row, unsigned w) {
    const FrameCtx& fc = *jp->f;
    State& s = *jp->st;
    const std::size_t m = fc.nq;
    const int b = static_cast<int>(row);
    const double guard = static_cast<double>(fc.opt->lamp_guard_px + 4 * fc.step);
    for (int a = 0; a < fc.hyperX; ++a) {
      const int x0 = fc.nodeX(4 * a), x4 = fc.nodeX(4 * a + 4), y0 = fc.nodeY(4 * b), y4 = fc.nodeY(4 * b + 4);
      bool ok = true;
      for (const auto& [lx, ly] : s.lampPixels)
        if (lx >= x0 - guard && lx <= x4 + 1 + guard && ly >= y0 - guard && ly <= y4 + 1 + guard) ok = false;
      const int xc = fc.nodeX(4 * a + 2), yc = fc.nodeY(4 * b + 2);
      const float qc = inverseDistanceAt(fc, xc, yc);
      for (int cj = 4 * b; cj <= 4 * b + 4 && ok; ++cj)
        for (int ci = 4 * a; ci <= 4 * a + 4 && ok; ++ci) {
          const int i = fc.nodeX(ci), j = fc.nodeY(cj);
          ok = sameLayer(inverseDistanceAt(fc, i, j), qc, fc.edgeFloor);
          if (ok && ci < 4 * a + 4 && cj < 4 * b + 4)  // the block centre to its lower right
            ok = sameLayer(inverseDistanceAt(fc, i + (fc.nodeX(ci + 1) - i) / 2, j + (fc.nodeY(cj + 1) - j) / 2), qc,
                           fc.edgeFloor);
        }
      if (!ok) continue;
      const std::size_t centre = static_cast<std::size_t>(4 * b + 2) * static_cast<std::size_t>(fc.coarseX) +
                                 static_cast<std::size_t>(4 * a + 2);
      const float* cp = s.coarse.data() + 3 * centre;
      const float budget = kMovingShare * (static_cast<float>(fc.opt->rel_tolerance) * (cp[0] + cp[1] + cp[2]) +
                                           static_cast<float>(fc.opt->abs_tolerance_cd_m2));
      Scratch& sc = s.scratch[w];
      for (std::size_t q = 0; q < m; ++q)
        sc.dev[q] = std::abs(s.coarseMl[centre * m + q] - hyperBilinear(fc, s, a, b, q, xc, yc)) * fc.mlLum[q];
      grantBudget(sc, m, budget);
      std::copy_n(sc.grant.data(), m,
                  s.hyperPass.data() + (static_cast<std::size_t>(b) * static_cast<std::size_t>(fc.hyperX) + static_cast<std::size_t>(a)) * m);
    }
  });
  // The first level's anchors that the first pass left: interpolated per lamp where their cell
  // (or, on a side, a cell either side) passes, else evaluated; added to the coarse grid.
  const std::size_t nCoarse = static_cast<std::size_t>(f.coarseX) * static_cast<std::size_t>(f.coarseY);
  pool.parallelForIndexed((nCoarse + f.chunk - 1) / f.chunk, [jp](std::size_t c, unsigned w) {
    const FrameCtx& fc = *jp->f;
    State& s = *jp->st;
    Scratch& sc = s.scratch[w];
    const std::size_t m = fc.nq;
    const std::size_t b0 = c * fc.chunk;
    const std::size_t e = std::min(b0 + fc.chunk, static_cast<std::size_t>(fc.coarseX) * static_cast<std::size_t>(fc.coarseY));
    auto passes = [&](int a, int b, std::size_t q) {
      return a >= 0 && b >= 0 && a < fc.hyperX && b < fc.hyperY &&
             s.hyperPass[(static_cast<std::size_t>(b) * static_cast<std::size_t>(fc.hyperX) + static_cast<std::size_t>(a)) * m + q] != 0;
    };
    auto ml = [&](int ci, int cj) {
      return s.coarseMl.data() + m * (static_cast<std::size_t>(cj) * static_cast<std::size_t>(fc.coarseX) + static_cast<std::size_t>(ci));
    };
    sc.n = 0;
    for (std::size_t k = b0; k < e; ++k) {
      const int ci = static_cast<int>(k % static_cast<std::size_t>(fc.coarseX));
      const int cj = static_cast<int>(k / static_cast<std::size_t>(fc.coarseX));
      if (!fc.inHyper(ci, cj) || !fc.movingAnchor(ci, cj) || fc.firstPassAnchor(ci, cj)) continue;
      const int i = fc.nodeX(ci), j = fc.nodeY(cj);
      float* known = sc.ml.data() + sc.n * m;
      for (std::size_t q = 0; q < m; ++q) {
        known[q] = std::numeric_limits<float>::quiet_NaN();
        if (ci % 2 == 1) {  // a super-cell's centre: inside one cell
          if (passes(ci / 4, cj / 4, q)) known[q] = hyperBilinear(fc, s, ci / 4, cj / 4, q, i, j);
        } else if (ci % 4 == 0) {  // on a cell's vertical side, between (ci, cj − 2) and (ci, cj + 2)
          if (!passes(ci / 4 - 1, cj / 4, q) && !passes(ci / 4, cj / 4, q)) continue;
          const int ya = fc.nodeY(cj - 2), yb = fc.nodeY(cj + 2);
          const float v = static_cast<float>(j - ya) / static_cast<float>(yb - ya);
          known[q] = (1 - v) * ml(ci, cj - 2)[q] + v * ml(ci, cj + 2)[q];
        } else {  // on a horizontal side, between (ci − 2, cj) and (ci + 2, cj)
          if (!passes(ci / 4, cj / 4 - 1, q) && !passes(ci / 4, cj / 4, q)) continue;
          const int xa = fc.nodeX(ci - 2), xb = fc.nodeX(ci + 2);
          const float u = static_cast<float>(i - xa) / static_cast<float>(xb - xa);
          known[q] = (1 - u) * ml(ci - 2, cj)[q] + u * ml(ci + 2, cj)[q];
        }
      }
      queueCoarseNode(fc, sc, i, j, k - b0);
    }
    addMovingToCoarseNodes(fc, s, sc, b0);
  });
}

// The coarse grid's second pass for the moving lamps' lattice (SubsamplingOptions::
// moving_lattice). A far moving lamp's light is smooth over most of the image, and the coarse
// grid with its block centres was ~half of a traffic frame's (pixel, moving lamp) evaluations
// (116 k of 226 k on the traffic bench at 1280×720, where the coarse step is 16 px). The first
// pass evaluated the moving lamps at the super-cells' corners and centres only; here each
// super-cell of 2 × 2 coarse blocks passes for a lamp when
//  * no lamp is imaged within lamp_guard_px of it,
//  * its nine nodes and four block centres lie in the centre's distance layer (sameLayer: the
//    light of a lamp along a ray depends on where the ray ends), and
//  * the lamp's value at its centre is the bilinear prediction from its corners within what
//    grantBudget grants it of a quarter of the block tolerance of the centre's whole luminance (as in
//    interpolateSmoothLamps).
// A node between two corners (the middle of a super-cell's side) then takes the lamp's linear
// interpolation when a super-cell on either side passes, else is evaluated; the tiles
// interpolate the block centres of passing super-cells (subsampleTile). Finer blocks still
// split wherever the whole pixel needs it, and there the lamp is judged again.
void movingLattice(State& st, const FrameCtx& f, ThreadPool& pool) {
  const std::size_t nq = f.nq;
  st.superPass.assign(static_cast<std::size_t>(f.superX) * static_cast<std::size_t>(f.superY) * nq, 0);
  const ImageJob job{&st, &f};
  const ImageJob* jp = &job;
  // Pass flags, one row of super-cells per job.
  pool.parallelForIndexed(static_cast<std::size_t>(f.superY), [jp](std::size_t row, unsigned w) {
    const FrameCtx& fc = *jp->f;
    State& s = *jp->st;
    const std::size_t m = fc.nq;
    const int b = static_cast<int>(row);
    const double guard = static_cast<double>(fc.opt->lamp_guard_px);
    for (int a = 0; a < fc.superX; ++a) {
      const int x0 = fc.nodeX(2 * a), x1 = fc.nodeX(2 * a + 1), x2 = fc.nodeX(2 * a + 2);
      const int y0 = fc.nodeY(2 * b), y1 = fc.nodeY(2 * b + 1), y2 = fc.nodeY(2 * b + 2);
      bool ok = true;
      for (const auto& [lx, ly] : s.lampPixels)
        if (lx >= x0 - guard && lx <= x2 + 1 + guard && ly >= y0 - guard && ly <= y2 + 1 + guard) ok = false;
      const float qc = inverseDistanceAt(fc, x1, y1);
      const int xs[5] = {x0, x0 + (x1 - x0) / 2, x1, x1 + (x2 - x1) / 2, x2};
      const int ys[5] = {y0, y0 + (y1 - y0) / 2, y1, y1 + (y2 - y1) / 2, y2};
      for (int jj = 0; jj < 5 && ok; ++jj)
        for (int ii = 0; ii < 5 && ok; ++ii) {
          // The nodes (even indices) and the block centres (odd, odd).
          if ((ii % 2) != (jj % 2)) continue;
          ok = sameLayer(inverseDistanceAt(fc, xs[ii], ys[jj]), qc, fc.edgeFloor);
        }
      if (!ok) continue;
      const std::size_t centre = static_cast<std::size_t>(2 * b + 1) * static_cast<std::size_t>(fc.coarseX) +
                                 static_cast<std::size_t>(2 * a + 1);
      const float* cp = s.coarse.data() + 3 * centre;
      const float budget = kMovingShare * (static_cast<float>(fc.opt->rel_tolerance) * (cp[0] + cp[1] + cp[2]) +
                                   static_cast<float>(fc.opt->abs_tolerance_cd_m2));
      std::uint8_t* pass = s.superPass.data() + (static_cast<std::size_t>(b) * static_cast<std::size_t>(fc.superX) +
                                                 static_cast<std::size_t>(a)) * m;
      Scratch& sc = s.scratch[w];
      for (std::size_t q = 0; q < m; ++q)
        sc.dev[q] = std::abs(s.coarseMl[centre * m + q] - superBilinear(fc, s, a, b, q, x1, y1)) * fc.mlLum[q];
      grantBudget(sc, m, budget);
      std::copy_n(sc.grant.data(), m, pass);
    }
  });
  // The nodes between corners: interpolated per lamp where a neighbouring super-cell passes,
  // else evaluated; either way their moving lamps' light is added to the coarse grid.
  const std::size_t nCoarse = static_cast<std::size_t>(f.coarseX) * static_cast<std::size_t>(f.coarseY);
  pool.parallelForIndexed((nCoarse + f.chunk - 1) / f.chunk, [jp](std::size_t c, unsigned w) {
    const FrameCtx& fc = *jp->f;
    State& s = *jp->st;
    Scratch& sc = s.scratch[w];
    const std::size_t m = fc.nq;
    const std::size_t b0 = c * fc.chunk;
    const std::size_t e = std::min(b0 + fc.chunk, static_cast<std::size_t>(fc.coarseX) * static_cast<std::size_t>(fc.coarseY));
    auto passes = [&](int a, int b, std::size_t q) {
      return a >= 0 && b >= 0 && a < fc.superX && b < fc.superY &&
             s.superPass[(static_cast<std::size_t>(b) * static_cast<std::size_t>(fc.superX) + static_cast<std::size_t>(a)) * m + q] != 0;
    };
    auto ml = [&](int ci, int cj) {
      return s.coarseMl.data() + m * (static_cast<std::size_t>(cj) * static_cast<std::size_t>(fc.coarseX) + static_cast<std::size_t>(ci));
    };
    sc.n = 0;
    for (std::size_t k = b0; k < e; ++k) {
      const int ci = static_cast<int>(k % static_cast<std::size_t>(fc.coarseX));
      const int cj = static_cast<int>(k / static_cast<std::size_t>(fc.coarseX));
      if (fc.movingAnchor(ci, cj)) continue;
      const int i = fc.nodeX(ci), j = fc.nodeY(cj);
      float* known = sc.ml.data() + sc.n * m;
      for (std::size_t q = 0; q < m; ++q) {
        known[q] = std::numeric_limits<float>::quiet_NaN();
        if (ci % 2 == 1) {  // on a row of corners, between (ci − 1, cj) and (ci + 1, cj)
          if (!passes((ci - 1) / 2, cj / 2 - 1, q) && !passes((ci - 1) / 2, cj / 2, q)) continue;
          const int xa = fc.nodeX(ci - 1), xb = fc.nodeX(ci + 1);
          const float u = static_cast<float>(i - xa) / static_cast<float>(xb - xa);
          known[q] = (1 - u) * ml(ci - 1, cj)[q] + u * ml(ci + 1, cj)[q];
        } else {  // on a column of corners, between (ci, cj − 1) and (ci, cj + 1)
          if (!passes(ci / 2 - 1, (cj - 1) / 2, q) && !passes(ci / 2, (cj - 1) / 2, q)) continue;
          const int ya = fc.nodeY(cj - 1), yb = fc.nodeY(cj + 1);
          const float v = static_cast<float>(j - ya) / static_cast<float>(yb - ya);
          known[q] = (1 - v) * ml(ci, cj - 1)[q] + v * ml(ci, cj + 1)[q];
        }
      }
      queueCoarseNode(fc, sc, i, j, k - b0);
    }
    addMovingToCoarseNodes(fc, s, sc, b0);
  });
}

// Stage "coarse grid": the corners of the coarse blocks (every step-th pixel, and the last
// column and row), shared by neighbouring tiles: evaluated once, in chunks of kChunk as whole
// SIMD batches, into st.coarse (3 floats per corner, row-major over the grid).
void evaluateCoarseGrid(State& st, const FrameCtx& f, ThreadPool& pool) {
  const std::size_t nCoarse = static_cast<std::size_t>(f.coarseX) * static_cast<std::size_t>(f.coarseY);
  st.coarse.resize(3 * nCoarse);
  st.coarseMl.resize(f.nq * nCoarse);
  const ImageJob job{&st, &f};
  const ImageJob* jp = &job;
  pool.parallelForIndexed((nCoarse + f.chunk - 1) / f.chunk, [jp](std::size_t c, unsigned w) {
    const FrameCtx& fc = *jp->f;
    Scratch& sc = jp->st->scratch[w];
    const std::size_t b = c * fc.chunk;
    const std::size_t e = std::min(b + fc.chunk, static_cast<std::size_t>(fc.coarseX) * static_cast<std::size_t>(fc.coarseY));
    sc.n = 0;
    for (std::size_t k = b; k < e; ++k) {
      const int i = std::min(static_cast<int>(k % static_cast<std::size_t>(fc.coarseX)) * fc.step, fc.cam->width - 1);
      const int j = std::min(static_cast<int>(k / static_cast<std::size_t>(fc.coarseX)) * fc.step, fc.cam->height - 1);
      sc.x[sc.n] = static_cast<float>(i) + 0.5f;
      sc.y[sc.n] = static_cast<float>(j) + 0.5f;
      sc.d[sc.n] = fc.surf->distance[fc.idx(i, j)];
      sc.slot[sc.n] = static_cast<std::uint32_t>(k - b);
      ++sc.n;
    }
    groupSky(sc);
    const std::size_t nq = fc.nq;
    sc.mlActive = nq > 0;
    std::fill_n(sc.ml.data(), sc.n * nq, std::numeric_limits<float>::quiet_NaN());
    if (fc.superX > 0)
      for (std::size_t k = 0; k < sc.n; ++k) {
        const std::size_t node = b + sc.slot[k];
        const int ci = static_cast<int>(node % static_cast<std::size_t>(fc.coarseX));
        const int cj = static_cast<int>(node / static_cast<std::size_t>(fc.coarseX));
        // Not at an anchor: the moving lamps come in the lattice's later passes.
        if (!fc.firstPassAnchor(ci, cj)) std::fill_n(sc.ml.data() + k * nq, nq, 0.0f);
      }
    evaluateBatch(fc, sc);
    sc.mlActive = false;
    float* dst = jp->st->coarse.data() + 3 * b;
    for (std::size_t k = 0; k < sc.n; ++k) {
      float* p = dst + 3 * static_cast<std::size_t>(sc.slot[k]);
      p[0] = sc.r[k];
      p[1] = sc.g[k];
      p[2] = sc.b[k];
      if (nq > 0) std::copy_n(sc.ml.data() + k * nq, nq, jp->st->coarseMl.data() + (b + sc.slot[k]) * nq);
    }
    sc.n = 0;
  });
  if (f.hyperX > 0) hyperLattice(st, f, pool);
  if (f.superX > 0) movingLattice(st, f, pool);
}

// Stage "tiles": each tile refined from the coarse grid, filled and written to the image by one
// thread (subsampleTile: the header comment's block test, level by level).
void refineTiles(State& st, const FrameCtx& f, ThreadPool& pool) {
  runTiles(st, f, pool, [&](std::size_t t, unsigned w) { subsampleTile(f, st.scratch[w], st.coarse, t); });
}

// The frame's figures (AirlightImage): pixels evaluated, and thread time per stage divided by
// the threads (wall time when the threads are kept busy).
void reportFigures(const State& st, std::size_t threadCount, AirlightImage& out) {
  std::size_t evaluated = 0, movingEvaluated = 0;
  double ev = 0.0, ju = 0.0, fi = 0.0;
  for (const Scratch& sc : st.scratch) {
    evaluated += sc.evaluated;
    movingEvaluated += sc.movingEvaluated;
    ev += sc.evalSeconds;
    ju += sc.judgeSeconds;
    fi += sc.fillSeconds;
  }
  const double threads = static_cast<double>(threadCount);
  out.eval_seconds = ev / threads;
  out.judge_seconds = ju / threads;
  out.fill_seconds = fi / threads;
  out.evaluated = evaluated;
  out.moving_evaluated = movingEvaluated;
}

}  // namespace

void AirlightImageEvaluator::evaluate(const Scene& scene, const SurfaceBuffers& surface, const SubsamplingOptions& opt,
                                      AirlightImage& out, Write write) {
  const auto t0 = std::chrono::steady_clock::now();
  State& st = *state_;
  const CameraFrame cf(scene.camera);
  const auto n = static_cast<std::size_t>(cf.cam.width) * static_cast<std::size_t>(cf.cam.height);
  bool add = write == Write::Add;
  if (out.width != cf.cam.width || out.height != cf.cam.height || out.rgb.size() != 3 * n) {
    out.width = cf.cam.width;
    out.height = cf.cam.height;
    out.rgb.assign(3 * n, 0.0f);
    add = false;  // nothing there to add to
  }

  // Lamps and tables for this camera pose: what the kernels read.
  prepareIsoLamps(st, lamps_, cf);
  out.table_seconds = refreshSkyTables(st, *pool_);
  st.tablesLoaded = 0;
  out.table_seconds += refreshViewTables(st, lamps_, *pool_, cf);
  out.view_tables_loaded = st.tablesLoaded;
  out.fog_rungs = st.fogRungs;
  out.bending_rungs = st.bendingRungs;
  if (!st.tableCacheError.empty()) out.table_cache_error.swap(st.tableCacheError);
  cullMovingLamps(st, lamps_, cf, scene.fog.extinction_per_m, scene.fog.albedo);
  out.moving_culled = st.culledCount;
  out.moving_dropped = st.droppedCount;
  refreshPencils(st, lamps_, cf.cam);
  const auto tSpokes = std::chrono::steady_clock::now();
  out.spokes = sampleSpokes(st, cf, *pool_, out.spokes_kept);
  out.spoke_seconds = since(tSpokes);
  refreshLampMaps(st, cf.cam, surface, opt, scene.fog.extinction_per_m, *pool_);
  out.map_seconds = st.mapSeconds;
  out.map_nodes = st.mapNodes;
  locateLampImages(st, lamps_, cf);

  // The image: tiling and per-thread memory, then the pixels (every one, or the coarse grid and
  // the tiles' refinement).
  FrameCtx f = planImage(st, lamps_, scene, surface, opt, out, add, cf);
  f.chunk = coarseChunk(f, pool_->size());
  ensureScratch(st, f, pool_->size(), lamps_.size());
  if (opt.full) {
    evaluateFullTiles(st, f, *pool_);
  } else {
    evaluateCoarseGrid(st, f, *pool_);
    refineTiles(st, f, *pool_);
  }
  reportFigures(st, pool_->size(), out);
  out.seconds = since(t0);
}

Result<std::shared_ptr<const FogTables>> AirlightImageEvaluator::buildFogTables(const Scene& scene,
                                                                                 const FastPathOptions& fast,
                                                                                 std::shared_ptr<ThreadPool> pool,
                                                                                 const std::vector<char>& enabled) {
  if (!enabled.empty() && enabled.size() != scene.lamps.size())
    return Error{"buildFogTables: " + std::to_string(enabled.size()) + " enabled flags for " +
                 std::to_string(scene.lamps.size()) + " lamps"};
  // An evaluator of the vehicle lamps alone (the rest need no view tables), whose view-table
  // stage runs once; its tables, keys and guards become the rung.
  Scene s = scene;
  s.lamps.clear();
  std::vector<char> on;
  for (std::size_t i = 0; i < scene.lamps.size(); ++i) {
    const SceneLamp& l = scene.lamps[i];
    if (l.mount == LampMount::Vehicle && !std::holds_alternative<IsotropicProfile>(l.lamp.profile->model())) {
      s.lamps.push_back(l);
      on.push_back(enabled.empty() || enabled[i] != 0 ? 1 : 0);
    }
  }
  auto e = build(s, AirlightMethod::Accurate, AirlightOptions{}, std::move(pool), fast);
  if (!e) return e.error();
  State& st = *e->state_;
  for (std::size_t i = 0; i < on.size(); ++i) st.enabled[i] = on[i];
  const CameraFrame cf(s.camera);
  refreshViewTables(st, e->lamps_, *e->pool_, cf, /*rung=*/true);
  auto rung = std::make_shared<FogTables>();
  rung->kt = s.fog.extinction_per_m;
  rung->albedo = s.fog.albedo;
  for (std::size_t v = 0; v < st.viewLamps.size(); ++v) {
    rung->profiles.push_back(e->lamps_[st.viewLamps[v]].lamp().profile);
    rung->colours.push_back(e->lamps_[st.viewLamps[v]].lamp().color);
  }
  rung->keys = st.viewKeys;
  rung->tables = std::move(st.viewTables);
  rung->guards = st.rayGuards;
  rung->built.assign(st.viewValid.begin(), st.viewValid.end());
  rung->table_cache_error = std::move(st.tableCacheError);
  // Merged for `enabled` (the uses point into the rung's own vectors, which do not move again).
  std::vector<std::vector<std::size_t>> members;
  if (st.fast.enabled && on.size() == st.viewLamps.size()) {
    rung->mergedFor = on;
    mergeTables(rung->tables.data(), rung->mergedFor, rung->merged, members, rung->uses);
  }
  return std::shared_ptr<const FogTables>(std::move(rung));
}

void AirlightImageEvaluator::setFogLadder(std::vector<std::shared_ptr<const FogTables>> rungs, double maxRatio,
                                          double maxBendingDeg) {
  State& st = *state_;
  std::sort(rungs.begin(), rungs.end(), [](const auto& a, const auto& b) { return a->kt < b->kt; });
  // Merges of rungs that leave the ladder are dropped: a new rung may be built at the address of
  // one freed.
  for (State::RungMerge& m : st.rungMerges) {
    const bool kept = std::any_of(rungs.begin(), rungs.end(), [&](const auto& r) { return r.get() == m.rung; });
    if (!kept) m = State::RungMerge{};
  }
  st.ladder = std::move(rungs);
  st.ladderMaxRatio = std::max(1.0, maxRatio);
  st.ladderMaxBendingRad = std::max(0.0, maxBendingDeg) * kPi / 180.0;
}

bool AirlightImageEvaluator::viewTablesReady(const Camera& camera) const {
  const State& st = *state_;
  const CameraFrame cf(camera);
  return ownTablesServe(st, lamps_, cf) || pickRungs(st, lamps_, cf).has_value();
}

std::string_view fogTablesCacheError(const FogTables& rung) noexcept { return rung.table_cache_error; }

}  // namespace fogbeam
