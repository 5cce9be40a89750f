#include <fogbeam/render/airlight_image.hpp>

#include <fogbeam/physics/airlight_pencil.hpp>
#include <fogbeam/render/airlight_kernels.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <limits>
#include <optional>
#include <sstream>

namespace fogbeam {

namespace {

// Batches are cut into chunks of this many pixels for the thread pool; a multiple of 64 so
// every chunk starts on a whole SIMD vector of any width (kernels::paddedSize).
constexpr std::size_t kChunk = 2048;
// View tables per vehicle lamp: the frustum table and two insets around the lamp's image.
constexpr std::size_t kTablesPerLamp = 3;

struct Block {
  int i0, j0, i1, j1;  // inclusive corner pixels, all four already evaluated
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
  };
  std::vector<PencilKey> pencilKeys;
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
  std::vector<kernels::IsoLamp> isoParams;  // this frame, capacity kept
  std::vector<char> enabled;                 // per lamp (scene order)
  std::vector<char> viewEnabled;             // per viewLamps entry, this frame

  // Per-frame buffers, sized once per image size.
  std::vector<unsigned char> done;  // per pixel: evaluated (1)
  std::vector<float> bx, by, bd, br, bg, bb;  // the batch being evaluated (padded)
  std::vector<std::uint32_t> bidx;            // its pixel indices
  std::size_t bn = 0;
  std::vector<Block> cur, next, leaves;
  std::vector<unsigned char> split;
  std::vector<std::pair<double, double>> lampPixels;
  std::vector<float> fullX, fullY;  // pixel centres for full mode
  std::vector<std::uint32_t> edgeSat;  // summed-area table of the distance-edge mask, (W+1)×(H+1)
  std::vector<float> invDist;          // 1/d per pixel, 0 for the sky
  // Compacted sub-batches for tables and guards that cover a small disc (same layout as bx…).
  std::vector<float> sx, sy, sd, sr, sg, sb;
  std::vector<std::uint32_t> sidx;
  int fullW = 0, fullH = 0;
};

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
    else if (useFast && fast.moving_lamps == MovingLampPath::Pencil)
      st.pencilLamps.push_back(i);
    else
      st.rayLamps.push_back(i);
  }
  if (!st.isoLamps.empty()) st.isoTable = kernels::IsoTable::get(scene.fog.phase);
  if (!st.pencilLamps.empty()) {
    // The pencil's options are checked here, once: an integrator built per frame must not fail.
    if (Status v = PencilAirlight::validate(fast.pencil_options); !v) return Error{"fast path: " + v.error().message};
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
      << " vehicle lamp(s) by view table, " << st.pencilLamps.size() << " moving lamp(s) by pencil, "
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
  for (const auto& g : st.rayGuards)
    if (g.r2 >= 0.0) v.guards.push_back({g.a, g.b, g.r2});
  v.complete = st.rayLamps.empty() && st.pencilLamps.empty();
  return v;
}

std::size_t AirlightImageEvaluator::fastTableBytes() const noexcept {
  std::size_t n = state_->isoTable ? state_->isoTable->bytes() : 0;  // shared per phase
  for (const auto& vt : state_->viewTables) n += vt.bytes();
  return n;
}

namespace {

float lum(const float* p) { return p[0] + p[1] + p[2]; }

// One frame's evaluation context: the evaluator's state plus this frame's inputs.
struct FrameCtx {
  const AirlightImageEvaluator::State* st;
  const std::vector<AirlightEvaluator>* lamps;
  const Camera* cam;
  const SurfaceBuffers* surf;
  AirlightImage* out;
  kernels::PixelGeometry geo;
  const SubsamplingOptions* opt;
  std::size_t idx(int i, int j) const {
    return static_cast<std::size_t>(j) * static_cast<std::size_t>(cam->width) + static_cast<std::size_t>(i);
  }
};

}  // namespace

// Evaluates pixels [begin, end) of the batch held in `st` (its x, y, d arrays) and writes
// their airlight into `out` (scattered through bidx unless `identity`).
static void evaluateBatchChunk(AirlightImageEvaluator::State& st, const FrameCtx& f, std::size_t begin,
                               std::size_t end, bool identity) {
  const std::size_t n = end - begin;
  if (n == 0) return;
  const std::size_t padded = kernels::paddedSize(n);
  std::fill_n(st.br.data() + begin, padded, 0.0f);
  std::fill_n(st.bg.data() + begin, padded, 0.0f);
  std::fill_n(st.bb.data() + begin, padded, 0.0f);
  const kernels::PixelBatch px{st.bx.data() + begin, st.by.data() + begin, st.bd.data() + begin, n};
  float* r = st.br.data() + begin;
  float* g = st.bg.data() + begin;
  float* b = st.bb.data() + begin;
  if (!st.isoParams.empty())
    kernels::accumulateIsoLamps(*st.isoTable, st.isoParams.data(), st.isoParams.size(), f.geo, px, r, g, b);
  // The chunk's extent on the tangent plane: inset tables and per-ray guards cover a small
  // disc, and most chunks do not reach it.
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
  // Tables and guards that cover a small disc run on the chunk's pixels inside it only,
  // compacted into the scratch arrays at the same offset (chunks do not overlap).
  auto compact = [&](double ca, double cb, double r2) {
    std::size_t m = 0;
    for (std::size_t k = 0; k < n; ++k) {
      const double a = (static_cast<double>(f.geo.cx) - static_cast<double>(px.x[k])) * static_cast<double>(f.geo.invF);
      const double bb = (static_cast<double>(f.geo.cy) - static_cast<double>(px.y[k])) * static_cast<double>(f.geo.invF);
      if ((a - ca) * (a - ca) + (bb - cb) * (bb - cb) > r2) continue;
      st.sx[begin + m] = px.x[k];
      st.sy[begin + m] = px.y[k];
      st.sd[begin + m] = px.d[k];
      st.sidx[begin + m] = static_cast<std::uint32_t>(k);
      ++m;
    }
    return m;
  };
  for (std::size_t ti = 0; ti < st.viewTables.size(); ++ti) {
    const kernels::ViewTable& vt = st.viewTables[ti];
    if (vt.data.empty() || !st.viewEnabled[ti / kTablesPerLamp]) continue;
    if (vt.outerR2 >= 1e30f) {
      kernels::accumulateViewTable(vt, f.geo, px, r, g, b);
      continue;
    }
    const double r2 = static_cast<double>(vt.outerR2);
    if (!reaches(static_cast<double>(vt.guardA), static_cast<double>(vt.guardB), r2)) continue;
    const std::size_t m = compact(static_cast<double>(vt.guardA), static_cast<double>(vt.guardB), r2);
    if (m == 0) continue;
    float* sr = st.sr.data() + begin;
    float* sg = st.sg.data() + begin;
    float* sb = st.sb.data() + begin;
    std::fill_n(sr, kernels::paddedSize(m), 0.0f);
    std::fill_n(sg, kernels::paddedSize(m), 0.0f);
    std::fill_n(sb, kernels::paddedSize(m), 0.0f);
    kernels::accumulateViewTable(vt, f.geo, {st.sx.data() + begin, st.sy.data() + begin, st.sd.data() + begin, m}, sr,
                                 sg, sb);
    for (std::size_t k = 0; k < m; ++k) {
      const std::size_t t = st.sidx[begin + k];
      r[t] += sr[k];
      g[t] += sg[k];
      b[t] += sb[k];
    }
  }
  // Pixels at the image of a vehicle lamp: per ray (see State::rayGuards).
  for (std::size_t v = 0; v < st.rayGuards.size(); ++v) {
    const auto& gd = st.rayGuards[v];
    if (gd.r2 < 0.0 || !st.viewEnabled[v] || !reaches(gd.a, gd.b, gd.r2)) continue;
    const std::size_t m = compact(gd.a, gd.b, gd.r2);
    const AirlightEvaluator& ev = (*f.lamps)[st.viewLamps[v]];
    for (std::size_t c = 0; c < m; ++c) {
      const std::size_t k = st.sidx[begin + c];
      const Ray ray{f.cam->position_m,
                    f.cam->rayDirection(static_cast<double>(px.x[k]), static_cast<double>(px.y[k])),
                    static_cast<double>(px.d[k])};
      const double l = ev.evaluate(ray);
      r[k] += static_cast<float>(l * ev.lamp().color[0]);
      g[k] += static_cast<float>(l * ev.lamp().color[1]);
      b[k] += static_cast<float>(l * ev.lamp().color[2]);
    }
  }
  if (!st.rayLamps.empty() || !st.pencilLamps.empty()) {
    for (std::size_t k = 0; k < n; ++k) {
      const Ray ray{f.cam->position_m,
                    f.cam->rayDirection(static_cast<double>(px.x[k]), static_cast<double>(px.y[k])),
                    static_cast<double>(px.d[k])};
      double acc[3] = {0.0, 0.0, 0.0};
      for (std::size_t li : st.rayLamps) {
        if (!st.enabled[li]) continue;
        const AirlightEvaluator& ev = (*f.lamps)[li];
        const double l = ev.evaluate(ray);
        for (int c = 0; c < 3; ++c) acc[c] += l * ev.lamp().color[c];
      }
      for (std::size_t q = 0; q < st.pencilLamps.size(); ++q) {
        if (!st.enabled[st.pencilLamps[q]] || !st.pencils[q]) continue;
        const PencilAirlight& pa = *st.pencils[q];
        const double l = pa.evaluate(ray.direction, ray.distance_m);
        for (int c = 0; c < 3; ++c) acc[c] += l * pa.lamp().lamp().color[c];
      }
      r[k] += static_cast<float>(acc[0]);
      g[k] += static_cast<float>(acc[1]);
      b[k] += static_cast<float>(acc[2]);
    }
  }
  float* dst = f.out->rgb.data();
  for (std::size_t k = 0; k < n; ++k) {
    const std::size_t p = identity ? begin + k : st.bidx[begin + k];
    dst[3 * p] = r[k];
    dst[3 * p + 1] = g[k];
    dst[3 * p + 2] = b[k];
  }
}

namespace {

// Adds pixel (i, j) to the batch unless it was evaluated already.
void request(AirlightImageEvaluator::State& st, const FrameCtx& f, int i, int j) {
  const std::size_t k = f.idx(i, j);
  if (st.done[k]) return;
  st.done[k] = 1;
  st.bx[st.bn] = static_cast<float>(i) + 0.5f;
  st.by[st.bn] = static_cast<float>(j) + 0.5f;
  st.bd[st.bn] = f.surf->distance[k];
  st.bidx[st.bn] = static_cast<std::uint32_t>(k);
  ++st.bn;
}

// The block test of the header comment: centre against the corners' bilinear prediction,
// distance-buffer edges, lamp images.
bool smoothBlock(const FrameCtx& f, const Block& bl) {
  const SubsamplingOptions& o = *f.opt;
  const int w = bl.i1 - bl.i0, h = bl.j1 - bl.j0;
  const float* rgb = f.out->rgb.data();
  auto px = [&](int i, int j) { return rgb + 3 * f.idx(i, j); };
  const int im = bl.i0 + w / 2, jm = bl.j0 + h / 2;
  const float um = w > 0 ? static_cast<float>(im - bl.i0) / static_cast<float>(w) : 0.0f;
  const float vm = h > 0 ? static_cast<float>(jm - bl.j0) / static_cast<float>(h) : 0.0f;
  const float predicted = (1 - um) * (1 - vm) * lum(px(bl.i0, bl.j0)) + um * (1 - vm) * lum(px(bl.i1, bl.j0)) +
                          (1 - um) * vm * lum(px(bl.i0, bl.j1)) + um * vm * lum(px(bl.i1, bl.j1));
  const float actual = lum(px(im, jm));
  if (std::abs(actual - predicted) >
      static_cast<float>(o.rel_tolerance) * actual + static_cast<float>(o.abs_tolerance_cd_m2))
    return false;
  // A lamp imaged inside the block makes a peak that the corners cannot see.
  for (const auto& [x, y] : f.st->lampPixels)
    if (x >= bl.i0 - o.lamp_guard_px && x <= bl.i1 + 1 + o.lamp_guard_px && y >= bl.j0 - o.lamp_guard_px &&
        y <= bl.j1 + 1 + o.lamp_guard_px)
      return false;
  // Distance edges inside the block (a car's silhouette, the horizon) change θd abruptly:
  // any pixel of the edge mask (buildEdgeSat) in the closed block splits it.
  const std::size_t w1 = static_cast<std::size_t>(f.cam->width) + 1;
  const std::uint32_t* S = f.st->edgeSat.data();
  auto at = [&](int i, int j) { return S[static_cast<std::size_t>(j) * w1 + static_cast<std::size_t>(i)]; };
  const std::uint32_t edges = at(bl.i1 + 1, bl.j1 + 1) - at(bl.i0, bl.j1 + 1) - at(bl.i1 + 1, bl.j0) + at(bl.i0, bl.j0);
  return edges == 0;
}

// Fills the pixels a leaf owns (columns [i0, i1), rows [j0, j1), plus the image's last column
// and row) that were not evaluated, by bilinear interpolation of its corners. Ownership is
// exclusive, so leaves can be filled in parallel without two threads writing one pixel.
void fillLeaf(const FrameCtx& f, const std::vector<unsigned char>& done, const Block& bl) {
  const int w = bl.i1 - bl.i0, h = bl.j1 - bl.j0;
  float* rgb = f.out->rgb.data();
  const float* c00 = rgb + 3 * f.idx(bl.i0, bl.j0);
  const float* c10 = rgb + 3 * f.idx(bl.i1, bl.j0);
  const float* c01 = rgb + 3 * f.idx(bl.i0, bl.j1);
  const float* c11 = rgb + 3 * f.idx(bl.i1, bl.j1);
  const int iEnd = bl.i1 == f.cam->width - 1 ? bl.i1 : bl.i1 - 1;
  const int jEnd = bl.j1 == f.cam->height - 1 ? bl.j1 : bl.j1 - 1;
  const float invW = w > 0 ? 1.0f / static_cast<float>(w) : 0.0f, invH = h > 0 ? 1.0f / static_cast<float>(h) : 0.0f;
  for (int j = bl.j0; j <= jEnd; ++j) {
    // The row's two ends on the block's left and right edges, then linear across.
    const float v = static_cast<float>(j - bl.j0) * invH;
    float left[3], step[3];
    for (int c = 0; c < 3; ++c) {
      left[c] = c00[c] + v * (c01[c] - c00[c]);
      step[c] = (c10[c] + v * (c11[c] - c10[c]) - left[c]) * invW;
    }
    const std::size_t row = f.idx(0, j);
    for (int i = bl.i0; i <= iEnd; ++i) {
      const std::size_t k = row + static_cast<std::size_t>(i);
      if (done[k]) continue;
      const float u = static_cast<float>(i - bl.i0);
      float* p = rgb + 3 * k;
      p[0] = left[0] + u * step[0];
      p[1] = left[1] + u * step[1];
      p[2] = left[2] + u * step[2];
    }
  }
}

// The distance-edge mask and its summed-area table, once per frame. A pixel is an edge when
// the second difference of 1/d across it (in x or in y) exceeds depth_edge_rel of the largest
// 1/d involved: over a plane 1/d is affine in the pixel coordinates up to the slowly varying
// 1/|ray| factor (second differences ~1e-7 relative), a silhouette or the sky line gives
// differences of order 1, a crease between two surfaces flags the pixels along it.
void buildEdgeSat(ThreadPool& pool, AirlightImageEvaluator::State& st, const Camera& cam, const SurfaceBuffers& surf,
                  float tol) {
  const std::size_t W = static_cast<std::size_t>(cam.width), H = static_cast<std::size_t>(cam.height);
  const std::size_t w1 = W + 1;
  st.edgeSat.resize(w1 * (H + 1));
  st.invDist.resize(W * H);
  std::fill_n(st.edgeSat.begin(), w1, 0u);  // row 0 of the table
  struct Job {
    AirlightImageEvaluator::State* st;
    const SurfaceBuffers* surf;
    std::size_t W, H;
    float tol;
  } job{&st, &surf, W, H, tol};
  const Job* jp = &job;
  // 1/d per pixel (0 for the sky), rows in parallel; branch-free so the loop vectorises.
  pool.parallelFor(H, [jp](std::size_t j) {
    const float* d = jp->surf->distance.data() + j * jp->W;
    float* q = jp->st->invDist.data() + j * jp->W;
    for (std::size_t i = 0; i < jp->W; ++i) q[i] = 1.0f / d[i];  // 1/+inf = 0
  });
  // The mask and its prefix sum along each row, into table row j + 1.
  pool.parallelFor(H, [jp](std::size_t j) {
    const std::size_t nw = jp->W, nh = jp->H;
    const float* q = jp->st->invDist.data();
    const float* c = q + j * nw;
    const float* up = j > 0 ? c - nw : c;           // rows beyond the image: no y test
    const float* dn = j + 1 < nh ? c + nw : c;
    const bool yTest = j > 0 && j + 1 < nh;
    std::uint32_t* out = jp->st->edgeSat.data() + (j + 1) * (nw + 1);
    out[0] = 0;
    kernels::markDistanceEdges(yTest ? up : nullptr, c, yTest ? dn : nullptr, nw, jp->tol, out + 1);
    for (std::size_t i = 1; i <= nw; ++i) out[i] += out[i - 1];
  });
  // Columns: accumulate the rows, in strips of columns in parallel.
  constexpr std::size_t kStrip = 256;
  pool.parallelFor((w1 + kStrip - 1) / kStrip, [jp](std::size_t strip) {
    const std::size_t nw1 = jp->W + 1;
    const std::size_t i0 = strip * kStrip, i1 = std::min(nw1, i0 + kStrip);
    std::uint32_t* S = jp->st->edgeSat.data();
    for (std::size_t j = 2; j <= jp->H; ++j) {
      std::uint32_t* row = S + j * nw1;
      const std::uint32_t* prev = row - nw1;
      for (std::size_t i = i0; i < i1; ++i) row[i] += prev[i];
    }
  });
}

}  // namespace

void AirlightImageEvaluator::evaluate(const Scene& scene, const SurfaceBuffers& surface, const SubsamplingOptions& opt,
                                      AirlightImage& out) {
  const auto t0 = std::chrono::steady_clock::now();
  State& st = *state_;
  const Camera& cam = scene.camera;
  const auto n = static_cast<std::size_t>(cam.width) * static_cast<std::size_t>(cam.height);
  if (out.width != cam.width || out.height != cam.height || out.rgb.size() != 3 * n) {
    out.width = cam.width;
    out.height = cam.height;
    out.rgb.assign(3 * n, 0.0f);
  }
  out.table_seconds = 0.0;
  const Mat3 camFromWorld = glm::transpose(cam.worldFromCamera);
  const double focal = cam.focalLengthPixels();
  const Vec2 principal = cam.principalPoint();  // (W/2, H/2) for a centred camera

  // Lamps in camera coordinates: isotropic kernel parameters, view-table validity.
  st.isoParams.clear();
  for (std::size_t li : st.isoLamps) {
    if (!st.enabled[li]) continue;
    const AirlightEvaluator& ev = lamps_[li];
    const Vec3 p = camFromWorld * (ev.lamp().position_m - cam.position_m);
    const double kt = ev.medium().extinction_per_m;
    if (kt * glm::length(p) > kernels::kMaxIsoOpticalDistance) continue;
    const double i0 = std::get<IsotropicProfile>(ev.lamp().profile->model()).intensity_cd;
    kernels::IsoLamp l;
    for (int c = 0; c < 3; ++c) {
      l.pos[c] = static_cast<float>(p[c]);
      l.weight[c] = static_cast<float>(ev.medium().albedo * kt * i0 * ev.lamp().color[c]);
    }
    l.kt = static_cast<float>(kt);
    st.isoParams.push_back(l);
  }
  for (std::size_t v = 0; v < st.viewLamps.size(); ++v) {
    st.viewEnabled[v] = st.enabled[st.viewLamps[v]];
    const AirlightEvaluator& ev = lamps_[st.viewLamps[v]];
    const ViewKey key{camFromWorld * (ev.lamp().position_m - cam.position_m),
                      camFromWorld * ev.lamp().worldFromLamp,
                      cam.fov_x,
                      static_cast<double>(cam.height) / cam.width,
                      principal.x / cam.width,
                      principal.y / cam.height,
                      ev.medium().extinction_per_m,
                      ev.medium().albedo};
    if (st.viewValid[v] && st.viewKeys[v].sameAs(key)) continue;
    kernels::ViewTable* tables = st.viewTables.data() + kTablesPerLamp * v;
    tables[0] = kernels::ViewTable::build(ev, cam, st.fast.view_table_step_deg, st.fast.view_table_distances, *pool_);
    for (std::size_t t = 1; t < kTablesPerLamp; ++t) tables[t] = kernels::ViewTable{};
    st.rayGuards[v] = {};
    if (key.lampInCamera.x > 0.0) {
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
        in = kernels::ViewTable::buildWindow(ev, cam, la - outer - 2.0 * step, lb - outer - 2.0 * step, nodes, nodes,
                                             step, st.fast.view_table_distances, *pool_);
        in.guardA = static_cast<float>(la);
        in.guardB = static_cast<float>(lb);
        in.outerR2 = static_cast<float>(outer * outer);
        in.innerR2 = static_cast<float>(inner * inner);
        outer = inner;
      }
      st.rayGuards[v] = {la, lb, outer * outer};
    }
    st.viewKeys[v] = key;
    st.viewValid[v] = true;
    for (std::size_t t = 0; t < kTablesPerLamp; ++t) out.table_seconds += tables[t].build_seconds;
  }
  // Moving lamps through the pencil: a new integrator state when the eye or the lamp moved
  // (spokes are then sampled again as pixels need them; their memory is kept).
  st.pencils.resize(st.pencilLamps.size());
  st.pencilKeys.resize(st.pencilLamps.size());
  for (std::size_t q = 0; q < st.pencilLamps.size(); ++q) {
    const AirlightEvaluator& ev = lamps_[st.pencilLamps[q]];
    const State::PencilKey key{&ev, cam.position_m, ev.lamp().position_m, ev.lamp().worldFromLamp};
    State::PencilKey& old = st.pencilKeys[q];
    const bool same = st.pencils[q] && old.lamp == key.lamp && old.eye == key.eye && old.position == key.position &&
                      old.axes == key.axes;
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
  // Image positions of lamps in front of the camera (capacity kept between frames).
  st.lampPixels.clear();
  for (std::size_t li = 0; li < lamps_.size(); ++li) {
    if (!st.enabled[li]) continue;
    const AirlightEvaluator& ev = lamps_[li];
    const Vec3 p = camFromWorld * (ev.lamp().position_m - cam.position_m);
    if (p.x <= 0.0) continue;
    st.lampPixels.emplace_back(principal.x - focal * p.y / p.x, principal.y - focal * p.z / p.x);
  }

  const std::size_t cap = kernels::paddedSize(n) + kChunk;
  if (st.bx.size() < cap) {
    for (auto* v : {&st.bx, &st.by, &st.bd, &st.br, &st.bg, &st.bb, &st.sx, &st.sy, &st.sd, &st.sr, &st.sg, &st.sb})
      v->assign(cap, 0.0f);
    st.bidx.assign(cap, 0);
    st.sidx.assign(cap, 0);
  }
  st.done.assign(n, 0);  // no reallocation once sized
  FrameCtx f{&st, &lamps_, &cam, &surface, &out,
             kernels::PixelGeometry{static_cast<float>(principal.x), static_cast<float>(principal.y),
                                    static_cast<float>(1.0 / focal)},
             &opt};
  std::size_t evaluated = 0;

  // Evaluates the batch st.bx/by/bd[0, st.bn) over the pool. The closure holds two pointers,
  // which std::function stores without allocating.
  out.eval_seconds = out.judge_seconds = out.fill_seconds = 0.0;
  auto since = [](std::chrono::steady_clock::time_point t) {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
  };
  auto runBatch = [&](bool identity) {
    const auto tb = std::chrono::steady_clock::now();
    const std::size_t chunks = (st.bn + kChunk - 1) / kChunk;
    struct Job {
      State* st;
      const FrameCtx* f;
      bool identity;
    } job{&st, &f, identity};
    const Job* jp = &job;
    pool_->parallelFor(chunks, [jp](std::size_t c) {
      const std::size_t b = c * kChunk, e = std::min(jp->st->bn, b + kChunk);
      evaluateBatchChunk(*jp->st, *jp->f, b, e, jp->identity);
    });
    evaluated += st.bn;
    st.bn = 0;
    out.eval_seconds += since(tb);
  };

  if (opt.full) {
    if (st.fullW != cam.width || st.fullH != cam.height) {
      st.fullX.resize(n);
      st.fullY.resize(n);
      for (std::size_t k = 0; k < n; ++k) {
        st.fullX[k] = static_cast<float>(k % static_cast<std::size_t>(cam.width)) + 0.5f;
        st.fullY[k] = static_cast<float>(k / static_cast<std::size_t>(cam.width)) + 0.5f;
      }
      st.fullW = cam.width;
      st.fullH = cam.height;
    }
    std::copy(st.fullX.begin(), st.fullX.end(), st.bx.begin());
    std::copy(st.fullY.begin(), st.fullY.end(), st.by.begin());
    std::copy(surface.distance.begin(), surface.distance.begin() + static_cast<std::ptrdiff_t>(n), st.bd.begin());
    st.bn = n;
    runBatch(true);
  } else {
    const int s = std::max(2, opt.coarse_step);
    {
      const auto tj = std::chrono::steady_clock::now();
      buildEdgeSat(*pool_, st, cam, surface, static_cast<float>(opt.depth_edge_rel));
      out.judge_seconds += since(tj);
    }
    // Level 0: the coarse grid's corners.
    st.cur.clear();
    st.leaves.clear();
    for (int j0 = 0; j0 < cam.height - 1 || j0 == 0; j0 += s) {
      const int j1 = std::min(j0 + s, cam.height - 1);
      for (int i0 = 0; i0 < cam.width - 1 || i0 == 0; i0 += s) {
        const int i1 = std::min(i0 + s, cam.width - 1);
        request(st, f, i0, j0);
        request(st, f, i1, j0);
        request(st, f, i0, j1);
        request(st, f, i1, j1);
        st.cur.push_back(Block{i0, j0, i1, j1});
        if (i1 == cam.width - 1) break;
      }
      if (j1 == cam.height - 1) break;
    }
    runBatch(false);
    while (!st.cur.empty()) {
      // Centres of the blocks that have pixels besides their corners.
      std::size_t kept = 0;
      for (const Block& bl : st.cur) {
        const int w = bl.i1 - bl.i0, h = bl.j1 - bl.j0;
        if (w <= 1 && h <= 1) continue;  // every pixel is a corner
        request(st, f, bl.i0 + w / 2, bl.j0 + h / 2);
        st.cur[kept++] = bl;
      }
      st.cur.resize(kept);
      runBatch(false);
      // Judge every block in parallel.
      const auto tj = std::chrono::steady_clock::now();
      st.split.assign(st.cur.size(), 0);
      {
        struct Job {
          State* st;
          const FrameCtx* f;
        } job{&st, &f};
        const Job* jp = &job;
        const std::size_t nb = st.cur.size(), chunks = (nb + 255) / 256;
        pool_->parallelFor(chunks, [jp](std::size_t c) {
          const std::size_t b = c * 256, e = std::min(jp->st->cur.size(), b + 256);
          for (std::size_t k = b; k < e; ++k) jp->st->split[k] = smoothBlock(*jp->f, jp->st->cur[k]) ? 0 : 1;
        });
      }
      out.judge_seconds += since(tj);
      // Split blocks: the new corners become the next batch, the quadrants the next level.
      st.next.clear();
      for (std::size_t k = 0; k < st.cur.size(); ++k) {
        const Block bl = st.cur[k];
        if (!st.split[k]) {
          st.leaves.push_back(bl);
          continue;
        }
        const int w = bl.i1 - bl.i0, h = bl.j1 - bl.j0;
        const int im = bl.i0 + w / 2, jm = bl.j0 + h / 2;
        for (int j : {bl.j0, jm, bl.j1})
          for (int i : {bl.i0, im, bl.i1}) request(st, f, i, j);
        if (w <= 1) {
          st.next.push_back(Block{bl.i0, bl.j0, bl.i1, jm});
          st.next.push_back(Block{bl.i0, jm, bl.i1, bl.j1});
        } else if (h <= 1) {
          st.next.push_back(Block{bl.i0, bl.j0, im, bl.j1});
          st.next.push_back(Block{im, bl.j0, bl.i1, bl.j1});
        } else {
          st.next.push_back(Block{bl.i0, bl.j0, im, jm});
          st.next.push_back(Block{im, bl.j0, bl.i1, jm});
          st.next.push_back(Block{bl.i0, jm, im, bl.j1});
          st.next.push_back(Block{im, jm, bl.i1, bl.j1});
        }
      }
      runBatch(false);
      std::swap(st.cur, st.next);
    }
    // Interpolate what was not evaluated.
    const auto tf = std::chrono::steady_clock::now();
    struct Job {
      State* st;
      const FrameCtx* f;
    } job{&st, &f};
    const Job* jp = &job;
    const std::size_t chunks = (st.leaves.size() + 255) / 256;
    pool_->parallelFor(chunks, [jp](std::size_t c) {
      const std::size_t b = c * 256, e = std::min(jp->st->leaves.size(), b + 256);
      for (std::size_t k = b; k < e; ++k) fillLeaf(*jp->f, jp->st->done, jp->st->leaves[k]);
    });
    out.fill_seconds = since(tf);
  }
  out.evaluated = evaluated;
  out.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace fogbeam
