// `fogbeam bench`: the paper's headline scene (config/scenes/bench.toml) at simulator sizes.
//
// For each image size: median and spread (min–max) over repeated frames of every stage
// (surface pass, airlight subsampled, airlight full per-pixel, composite) and frames per second
// of the subsampled pipeline; then, on the last frame, the error of every method against the
// reference method over a fixed random sample of pixels, and the brute-force ray marcher at the
// step count whose error matches the accurate method's. Output: a table, and JSON (--json).
// Each airlight stage gets a time budget (--stage-budget): it runs fewer frames than asked (at
// least one) when they do not fit. The first airlight frame of a size builds the view tables of
// the vehicle-mounted lamps; it is reported on its own line, not among the timed frames.
// After the sizes, at one size each: the GPU airlight stage of the GL surface pass (--gpu-size;
// llvmpipe runs it on the CPU where there is no GPU) against the CPU's accurate method on the
// same frame, and near-field (aperture) lamps (--aperture-size).
#include "cmd_bench.hpp"
#include "road_model.hpp"

#include <fogbeam/gl/surface_pass.hpp>
#include <fogbeam/physics/photometry_io.hpp>

#include <fogbeam/render/airlight_image.hpp>
#include <fogbeam/render/airlight_kernels.hpp>
#include <fogbeam/render/frame.hpp>
#include <fogbeam/render/pixel_pack.hpp>
#include <fogbeam/render/lamp_effects.hpp>
#include <fogbeam/render/raymarch.hpp>
#include <fogbeam/render/surface.hpp>
#include <fogbeam/render/surface_shading.hpp>
#include <fogbeam/scene/scene.hpp>
#include <fogbeam/util/thread_pool.hpp>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <ctime>
#include <chrono>
#include <cmath>
#include <cstring>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <memory>
#include <numeric>
#include <random>
#include <string>
#include <thread>
#include <vector>

#ifndef FOGBEAM_BENCH_TRAFFIC_SCENE
#define FOGBEAM_BENCH_TRAFFIC_SCENE "config/scenes/traffic.toml"
#endif
#ifndef FOGBEAM_BENCH_SCENE
#define FOGBEAM_BENCH_SCENE "config/scenes/bench.toml"
#endif
#ifndef FOGBEAM_BUILD_TYPE
#define FOGBEAM_BUILD_TYPE "unknown"
#endif
#ifndef FOGBEAM_CXX_FLAGS
#define FOGBEAM_CXX_FLAGS "unknown"
#endif

namespace fogbeam::cli {

// BenchOptions::scene's default (cmd_bench.hpp): defined here, the one source that gets the path
// from plugin/CMakeLists.txt.
const char* const kBenchDefaultScene = FOGBEAM_BENCH_SCENE;
const char* const kBenchTrafficScene = FOGBEAM_BENCH_TRAFFIC_SCENE;

namespace {

using Clock = std::chrono::steady_clock;
using json = nlohmann::json;

// Figures of one stage over repeated frames, in milliseconds.
struct StageStats {
  std::vector<double> ms;
  [[nodiscard]] double median() const {
    std::vector<double> v = ms;
    std::sort(v.begin(), v.end());
    const std::size_t n = v.size();
    if (n == 0) return 0.0;
    return n % 2 == 1 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
  }
  [[nodiscard]] double min() const { return ms.empty() ? 0.0 : *std::min_element(ms.begin(), ms.end()); }
  [[nodiscard]] double max() const { return ms.empty() ? 0.0 : *std::max_element(ms.begin(), ms.end()); }
  [[nodiscard]] json toJson() const {
    return {{"median_ms", median()}, {"min_ms", min()}, {"max_ms", max()}, {"frames", ms.size()}};
  }
};

double msSince(Clock::time_point t0) { return std::chrono::duration<double, std::milli>(Clock::now() - t0).count(); }

// CPU time of the whole process (every thread, llvmpipe's included), ms.
double processCpuMs() {
  timespec t{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
  return 1e3 * static_cast<double>(t.tv_sec) + 1e-6 * static_cast<double>(t.tv_nsec);
}

struct ErrorStats {
  double median = 0.0, p95 = 0.0, max = 0.0;
  std::size_t counted = 0;
  [[nodiscard]] json toJson() const { return {{"median", median}, {"p95", p95}, {"max", max}, {"pixels", counted}}; }
};

// Percentile by the nearest-rank rule on a sorted copy.
double percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const auto rank = static_cast<std::size_t>(std::ceil(q * static_cast<double>(v.size())));
  return v[std::min(v.size() - 1, rank == 0 ? 0 : rank - 1)];
}

// Relative error of `value` against `ref` (luminance: mean of the channels) over the pixels
// whose reference luminance exceeds `floor` (cd/m²).
constexpr double kRefThresholdCdM2 = 1e-4;
ErrorStats relativeErrors(const std::vector<double>& value, const std::vector<double>& ref,
                          double floor = kRefThresholdCdM2) {
  std::vector<double> rel;
  for (std::size_t k = 0; k < ref.size(); ++k)
    if (ref[k] > floor) rel.push_back(std::abs(value[k] - ref[k]) / ref[k]);
  ErrorStats e;
  e.counted = rel.size();
  e.median = percentile(rel, 0.5);
  e.p95 = percentile(rel, 0.95);
  e.max = rel.empty() ? 0.0 : *std::max_element(rel.begin(), rel.end());
  return e;
}

double luminance(const float rgb[3]) {
  return (static_cast<double>(rgb[0]) + static_cast<double>(rgb[1]) + static_cast<double>(rgb[2])) / 3.0;
}

struct SamplePixel {
  int i, j;
};

// Evaluates `fn` (a per-ray "sum over lamps") on every sample pixel in parallel; returns the
// luminances and the wall time in ms.
template <class Fn>
double evaluateSample(ThreadPool& pool, const Camera& cam, const SurfaceBuffers& surf, const std::vector<SamplePixel>& px,
                      const Fn& fn, std::vector<double>& out) {
  out.assign(px.size(), 0.0);
  const auto t0 = Clock::now();
  pool.parallelFor(px.size(), [&](std::size_t k) {
    const SamplePixel p = px[k];
    const std::size_t idx =
        static_cast<std::size_t>(p.j) * static_cast<std::size_t>(cam.width) + static_cast<std::size_t>(p.i);
    const Ray ray{cam.position_m, cam.rayDirection(p.i + 0.5, p.j + 0.5), static_cast<double>(surf.distance[idx])};
    float rgb[3];
    fn(ray, rgb);
    out[k] = luminance(rgb);
  });
  return msSince(t0);
}

std::string cpuModel() {
  std::ifstream in("/proc/cpuinfo");
  std::string line;
  while (std::getline(in, line))
    if (line.rfind("model name", 0) == 0) {
      const auto colon = line.find(':');
      if (colon != std::string::npos) return line.substr(line.find_first_not_of(" \t", colon + 1));
    }
  return "unknown";
}

// The compile flags as CMake composed them, without the blanks an empty CMAKE_CXX_FLAGS leaves.
std::string compileFlags() {
  std::string f = FOGBEAM_CXX_FLAGS;
  const auto b = f.find_first_not_of(' '), e = f.find_last_not_of(' ');
  return b == std::string::npos ? std::string() : f.substr(b, e - b + 1);
}

bool parseSize(const std::string& s, int& w, int& h) {
  const auto x = s.find('x');
  if (x == std::string::npos) return false;
  try {
    std::size_t a = 0, b = 0;
    w = std::stoi(s.substr(0, x), &a);
    h = std::stoi(s.substr(x + 1), &b);
    return a == x && b == s.size() - x - 1 && w > 0 && h > 0 && w <= 16384 && h <= 16384;
  } catch (...) {
    return false;
  }
}

struct Evaluators {
  AirlightImageEvaluator reference, seed, accurate;
};

/// The scene at another image size (an off-axis camera keeps its frustum).
Scene resized(Scene scene, int width, int height) {
  if (scene.camera.principal_px)
    *scene.camera.principal_px *= Vec2(static_cast<double>(width) / scene.camera.width,
                                       static_cast<double>(height) / scene.camera.height);
  scene.camera.width = width;
  scene.camera.height = height;
  return scene;
}

// ---------------------------------------------------------------------------------------------
// One image size, stage by stage. Each stage below times one part of a frame (or measures its
// error) and returns its figures as JSON; benchSize() runs them in order and collects them into
// the size's table, which printSize() prints. The stages share the frame through SizeRun: the
// surface buffers the airlight stages read, the airlight images and the composite.

struct SizeRun {
  SizeRun(Scene s, const BenchOptions& opt, Evaluators& e, ThreadPool& p, GlSurfacePass* g)
      : scene(std::move(s)), o(opt), ev(e), pool(p), gl(g),
        nPixels(static_cast<std::size_t>(scene.camera.width) * static_cast<std::size_t>(scene.camera.height)) {}

  const Scene scene;  // the bench scene at this size
  const BenchOptions& o;
  Evaluators& ev;
  ThreadPool& pool;
  GlSurfacePass* gl;  // null without EGL
  std::size_t nPixels;
  SurfaceBuffers surface;  // the surfaces the airlight stages read (the GL pass's when it works)
  AirlightImage sub;       // the last subsampled airlight image
  AirlightImage full;      // the last full per-pixel airlight image
  FrameLayers layers;      // the last composite
};

// Surface pass: CPU planes (the analytic null renderer), rows over the bench's pool. Its
// buffers feed the airlight stages unless the GL pass works.
json surfaceCpuStage(SizeRun& run) {
  StageStats stats;
  for (int f = 0; f < run.o.frames; ++f) {
    const auto t0 = Clock::now();
    renderSurfacesCpu(run.scene, run.surface, &run.pool);
    stats.ms.push_back(msSince(t0));
  }
  return stats.toJson();
}

// The CPU surface pass the service and `render --surface cpu` run without GL: SurfaceShader's
// SIMD path (planes and the bonnet cast in double, lit in float). The stage above is its
// double-precision oracle.
json surfaceCpuFastStage(SizeRun& run) {
  StageStats stats;
  SurfaceShader shader;
  kernels::ShadeFrame frame;
  SurfaceBuffers out;
  for (int f = 0; f < run.o.frames; ++f) {
    const auto t0 = Clock::now();
    shader.render(run.scene, frame, out, &run.pool);
    stats.ms.push_back(msSince(t0));
  }
  return stats.toJson();
}

// The same with the fog's scattered light on the surfaces (render/fog_light.hpp: [glow] on, its
// `surfaces` key): its table and the profiles' annulus maps are built by a first frame outside
// the timing (they are built once per phase function and profile).
json surfaceCpuFogLightStage(SizeRun& run) {
  Scene scene = run.scene;
  scene.effects.glow.enabled = true;
  scene.effects.glow.surfaces = true;
  StageStats stats;
  SurfaceShader shader;
  kernels::ShadeFrame frame;
  SurfaceBuffers out;
  const auto t0 = Clock::now();
  shader.render(scene, frame, out, &run.pool);
  const double firstMs = msSince(t0);
  if (frame.fog_light.table == nullptr) return {{"available", false}, {"note", "no multiple-scattering table for the fog"}};
  for (int f = 0; f < run.o.frames; ++f) {
    const auto t1 = Clock::now();
    shader.render(scene, frame, out, &run.pool);
    stats.ms.push_back(msSince(t1));
  }
  json j = stats.toJson();
  j["available"] = true;
  j["first_frame_ms"] = firstMs;
  return j;
}

// Times `frames` GL surface passes of `scene`: the whole render() call (upload, draw, PBO
// readback) and, from the pass's own counters, GPU draw, readback and CPU shading; on a GL
// failure the stage's "not available" answer (`available` false).
json timeGlSurfaces(SizeRun& run, const Scene& scene, SurfaceBuffers& buffers) {
  StageStats total, draw, readback, shade;
  for (int f = 0; f < run.o.frames; ++f) {
    const auto t0 = Clock::now();
    if (Status st = run.gl->render(scene, buffers); !st)
      return {{"available", false}, {"note", "GL failed: " + st.error().message}};
    total.ms.push_back(msSince(t0));
    draw.ms.push_back(run.gl->stats().surface_ms);
    readback.ms.push_back(run.gl->stats().readback_ms);
    shade.ms.push_back(run.gl->stats().shade_ms);
  }
  return {{"available", true}, {"total", total.toJson()}, {"draw", draw.toJson()},
          {"readback", readback.toJson()}, {"shade", shade.toJson()}};
}

// GL surface pass (fogbeam_gl, EGL). When it works, the stages below use its buffers, as
// `fogbeam render` does.
json surfaceGlStage(SizeRun& run) {
  if (!run.gl) return {{"available", false}, {"note", "GL: not available (no EGL)"}};
  SurfaceBuffers glBuffers;
  json j = timeGlSurfaces(run, run.scene, glBuffers);
  if (!j["available"].get<bool>()) return j;
  run.surface = std::move(glBuffers);
  j["note"] = run.gl->description();
  j["shading"] = run.gl->shading() == SurfaceShading::Cpu ? "cpu" : "gpu";
  return j;
}

// The same pass with the fog's scattered light on the surfaces ([glow] surfaces): on a GPU the
// fragment shaders evaluate it per pixel (common_photometry.glsl's fogLight), with CPU shading
// the SIMD grid does. A first frame outside the timing builds the table and the profiles'
// annulus maps. Its buffers are not kept: the stages below take the scene as it is.
json surfaceGlFogLightStage(SizeRun& run) {
  if (!run.gl) return {{"available", false}, {"note", "GL: not available (no EGL)"}};
  Scene scene = run.scene;
  scene.effects.glow.enabled = true;
  scene.effects.glow.surfaces = true;
  SurfaceBuffers buffers;
  const auto tf = Clock::now();
  if (Status st = run.gl->render(scene, buffers); !st)
    return {{"available", false}, {"note", "GL failed: " + st.error().message}};
  const double firstMs = msSince(tf);
  json j = timeGlSurfaces(run, scene, buffers);
  if (!j["available"].get<bool>()) return j;
  j["first_frame_ms"] = firstMs;
  return j;
}

// Airlight, accurate method, first frame at this size: it builds the view tables of the
// vehicle-mounted lamps (their pose relative to the camera is fixed, so later frames reuse
// them), so it is timed on its own and reported as the table build, not as a frame.
json airlightFirstFrameStage(SizeRun& run) {
  const auto t0 = Clock::now();
  run.ev.accurate.evaluate(run.scene, run.surface, SubsamplingOptions{}, run.sub);
  const double ms = msSince(t0);
  return {{"ms", ms}, {"view_table_build_ms", 1e3 * run.sub.table_seconds}};
}

// Adaptive subsampling: at least one frame; further frames while they fit the stage budget.
// With the evaluator's own split of a frame: evaluation, block tests and edges, interpolation.
json airlightSubsampledStage(SizeRun& run) {
  StageStats frame, eval, judge, fill;
  double totalMs = 0.0;
  for (int f = 0; f < run.o.frames; ++f) {
    if (f > 0 && totalMs + frame.ms.back() > 1e3 * run.o.stageBudgetSeconds) break;
    const auto t0 = Clock::now();
    run.ev.accurate.evaluate(run.scene, run.surface, SubsamplingOptions{}, run.sub);
    frame.ms.push_back(msSince(t0));
    eval.ms.push_back(1e3 * run.sub.eval_seconds);
    judge.ms.push_back(1e3 * run.sub.judge_seconds);
    fill.ms.push_back(1e3 * run.sub.fill_seconds);
    totalMs += frame.ms.back();
  }
  json s = frame.toJson();
  s["evaluated_pixels"] = run.sub.evaluated;
  s["evaluate"] = eval.toJson();
  s["judge"] = judge.toJson();
  s["fill"] = fill.toJson();
  return s;
}

// Full per-pixel: whole frames, as many as fit the budget (at least one).
json airlightFullStage(SizeRun& run) {
  StageStats frame;
  double totalMs = 0.0;
  for (int f = 0; f < run.o.frames; ++f) {
    if (f > 0 && totalMs + frame.ms.back() > 1e3 * run.o.stageBudgetSeconds) break;
    const auto t0 = Clock::now();
    run.ev.accurate.evaluate(run.scene, run.surface, SubsamplingOptions{.full = true}, run.full);
    frame.ms.push_back(msSince(t0));
    totalMs += frame.ms.back();
  }
  json s = frame.toJson();
  s["evaluated_pixels"] = run.full.evaluated;
  return s;
}

// The SIMD kernels on every compiled target against the scalar definition (double
// arithmetic, one pixel at a time): isotropic lamps and the vehicle lamps' frustum tables on
// the frame's first 65 536 pixels, one thread.
json kernelsByTargetStage(SizeRun& run) {
  const Camera& cam = run.scene.camera;
  const auto view = run.ev.accurate.fastPathView();
  const std::size_t n = std::min<std::size_t>(run.nPixels, 65536), padded = kernels::paddedSize(n);
  std::vector<float> bx(padded, 0.5f), by(padded, 0.5f), bd(padded, 1.0f), kr(padded), kg(padded), kb(padded);
  for (std::size_t k = 0; k < n; ++k) {
    bx[k] = static_cast<float>(k % static_cast<std::size_t>(cam.width)) + 0.5f;
    by[k] = static_cast<float>(k / static_cast<std::size_t>(cam.width)) + 0.5f;
    bd[k] = run.surface.distance[k];
  }
  const kernels::PixelBatch px{bx.data(), by.data(), bd.data(), n};
  const kernels::PixelGeometry geo{static_cast<float>(cam.principalPoint().x), static_cast<float>(cam.principalPoint().y),
                                   static_cast<float>(1.0 / cam.focalLengthPixels())};
  auto runOnce = [&](bool scalar) {
    std::fill(kr.begin(), kr.end(), 0.0f);
    std::fill(kg.begin(), kg.end(), 0.0f);
    std::fill(kb.begin(), kb.end(), 0.0f);
    const auto t0 = Clock::now();
    if (view.isoTable && !view.isoLamps->empty()) {
      if (scalar)
        kernels::accumulateIsoLampsScalar(*view.isoTable, view.isoLamps->data(), view.isoLamps->size(), geo, px,
                                          kr.data(), kg.data(), kb.data());
      else
        kernels::accumulateIsoLamps(*view.isoTable, view.isoLamps->data(), view.isoLamps->size(), geo, px, kr.data(),
                                    kg.data(), kb.data());
    }
    for (const auto& t : *view.viewTables) {
      if (t.data.empty() || t.outerR2 < 1e30f) continue;  // frustum tables; insets cover a few pixels
      if (scalar)
        kernels::accumulateViewTableScalar(t, geo, px, kr.data(), kg.data(), kb.data());
      else
        kernels::accumulateViewTable(t, geo, px, kr.data(), kg.data(), kb.data());
    }
    return msSince(t0);
  };
  json simd = json::array();
  StageStats scalarStats;
  for (int f = 0; f < 3; ++f) scalarStats.ms.push_back(runOnce(true));
  const double scalarNs = 1e6 * scalarStats.median() / static_cast<double>(n);
  simd.push_back({{"target", "scalar (double, reference)"}, {"ns_per_pixel", scalarNs}, {"speedup", 1.0}});
  for (const std::string& t : kernels::availableTargets()) {
    kernels::forceTarget(t);
    StageStats st;
    for (int f = 0; f < 5; ++f) st.ms.push_back(runOnce(false));
    const double ns = 1e6 * st.median() / static_cast<double>(n);
    simd.push_back({{"target", t}, {"ns_per_pixel", ns}, {"speedup", scalarNs / ns}});
  }
  kernels::forceTarget("");
  return simd;
}

// Composite of the surfaces and the subsampled airlight, over the bench's pool.
json compositeStage(SizeRun& run) {
  StageStats stats;
  for (int f = 0; f < run.o.frames; ++f) {
    const auto t0 = Clock::now();
    compositeFrame(run.scene.fog, run.surface, run.sub, run.layers, {}, &run.pool);
    stats.ms.push_back(msSince(t0));
  }
  return stats.toJson();
}

// Glow and glare, both on, with the bench's defaults, on the bench's pool.
Result<LampEffects> glowAndGlare(SizeRun& run) {
  GlowOptions glowOpt;
  glowOpt.enabled = true;
  GlareOptions glareOpt;
  glareOpt.enabled = true;
  auto fxPool = std::shared_ptr<ThreadPool>(&run.pool, [](ThreadPool*) {});  // borrowed: outlives the effects
  return LampEffects::build(run.scene, glowOpt, glareOpt, fxPool);
}

// Packing the composite into the shared-memory formats a channel publishes (docs/shm.md): RGBA8
// sRGB (tone-mapped) and the RGBA16F overlay (in-scattered light + transmittance); the larger
// of the two is what a channel pays per frame.
json packStage(SizeRun& run) {
  StageStats rgba8, overlay;
  std::vector<std::uint8_t> bytes(4 * run.nPixels);
  std::vector<std::uint16_t> halves(4 * run.nPixels);
  for (int f = 0; f < run.o.frames; ++f) {
    auto t0 = Clock::now();
    packRgba8Srgb(run.layers.composite.data(), run.nPixels, 0.0, bytes.data());
    rgba8.ms.push_back(msSince(t0));
    t0 = Clock::now();
    packRgba16F(run.layers.overlay.data(), run.layers.transmittance.data(), 1.0f, run.nPixels, halves.data());
    overlay.ms.push_back(msSince(t0));
  }
  return {{"rgba8_srgb", rgba8.toJson()}, {"rgba16f_overlay", overlay.toJson()}};
}

// The whole frame (issue 17) as a channel runs it, stage after stage, o.frames times: the GL
// surface pass (or the CPU one without GL), the subsampled airlight, glow, glare, the composite
// and the RGBA8 packing. Per stage the wall time and the cores it kept busy (process CPU time /
// wall time): where a stage leaves cores idle, overlapping it with another frame's stages (a
// pipeline) could use them; the frame's total CPU time / the core count bounds what any such
// overlap can reach.
json wholeFrameStage(SizeRun& run) {
  auto fx = glowAndGlare(run);
  if (!fx) return {{"error", fx.error().message}};
  SurfaceShader cpuShader;
  kernels::ShadeFrame cpuFrame;
  SurfaceBuffers surface;
  AirlightImage air;
  FrameLayers layers;
  std::vector<float> glow, glare;
  LampEffectsReport rep;
  std::vector<std::uint8_t> bytes(4 * run.nPixels);
  const char* names[] = {"surface", "airlight", "glow_glare", "composite", "pack"};
  constexpr int kStages = 5;
  std::vector<double> wall[kStages + 1], cpu[kStages + 1];
  for (int f = 0; f < run.o.frames + 1; ++f) {  // the first frame warms up (buffers sized)
    double w[kStages], c[kStages];
    auto stage = [&](int k, auto&& fn) {
      const double c0 = processCpuMs();
      const auto t0 = Clock::now();
      fn();
      w[k] = msSince(t0);
      c[k] = processCpuMs() - c0;
    };
    bool glOk = true;
    stage(0, [&] {
      if (run.gl) glOk = static_cast<bool>(run.gl->render(run.scene, surface));
      if (!run.gl || !glOk) cpuShader.render(run.scene, cpuFrame, surface, &run.pool);
    });
    stage(1, [&] { run.ev.accurate.evaluate(run.scene, surface, SubsamplingOptions{}, air); });
    stage(2, [&] { fx->evaluate(run.scene, surface, glow, glare, rep); });
    stage(3, [&] { compositeFrame(run.scene.fog, surface, air, layers, EffectLayers{&glow, &glare}, &run.pool); });
    stage(4, [&] { packRgba8Srgb(layers.composite.data(), run.nPixels, 0.0, bytes.data()); });
    if (f == 0) continue;
    double tw = 0.0, tc = 0.0;
    for (int k = 0; k < kStages; ++k) {
      wall[k].push_back(w[k]);
      cpu[k].push_back(c[k]);
      tw += w[k];
      tc += c[k];
    }
    wall[kStages].push_back(tw);
    cpu[kStages].push_back(tc);
  }
  auto median = [](std::vector<double> v) {
    StageStats s;
    s.ms = std::move(v);
    return s.median();
  };
  json out = json::object();
  for (int k = 0; k <= kStages; ++k) {
    const double mw = median(wall[k]), mc = median(cpu[k]);
    out[k < kStages ? names[k] : "frame"] = {{"median_ms", mw}, {"cpu_ms", mc}, {"cores_busy", mw > 0.0 ? mc / mw : 0.0}};
  }
  const double cores = static_cast<double>(run.pool.size());
  out["cores"] = cores;
  out["overlap_bound_ms"] = out["frame"]["cpu_ms"].get<double>() / cores;
  return out;
}

// Glow and glare (issue 7) on the same frame: their layers' time, and their effect as the
// share of the composite's light they add (Σ over pixels, luminance) and the glare figures.
json glowGlareStage(SizeRun& run) {
  auto fx = glowAndGlare(run);
  if (!fx) return {{"error", fx.error().message}};
  StageStats glowStats, glareStats;
  std::vector<float> glowLayer, glareLayer;
  LampEffectsReport rep;
  double veilBuildMs = 0.0;  // the road veil of the driver's lamps, made in the first frame
  for (int f = 0; f < run.o.frames; ++f) {
    fx->evaluate(run.scene, run.surface, glowLayer, glareLayer, rep);
    glowStats.ms.push_back(1e3 * rep.glow_seconds);
    glareStats.ms.push_back(1e3 * rep.glare_seconds);
    veilBuildMs = std::max(veilBuildMs, 1e3 * rep.ground_veil_build_seconds);
  }
  const bool veil = rep.ground_veil;
  double sumBase = 0.0, sumGlow = 0.0, sumGlare = 0.0;
  for (std::size_t k = 0; k < run.nPixels; ++k) {
    sumBase += luminance(&run.layers.composite[3 * k]);
    sumGlow += luminance(&glowLayer[3 * k]);
    sumGlare += luminance(&glareLayer[3 * k]);
  }
  int visible = 0, glowing = 0, ownGlowing = 0;
  for (const auto& l : rep.lamps) {
    visible += l.visible ? 1 : 0;
    glowing += !l.own && l.visible && l.glow_peak_cd_m2 > 0.0 ? 1 : 0;
    ownGlowing += l.own && l.glow_peak_cd_m2 > 0.0 ? 1 : 0;
  }
  // Issue 18's cost figure: the glow of a dozen lamps (the bench scene's, then street lamps of
  // 4 000 cd every 25 m along both sides of the road, 8 m high, until there are 12 lamps that are
  // not the ego's; those hidden behind a surface do not glow), glare off. The
  // lamps move 0.5 m a frame, so every frame computes every lamp's curve anew.
  StageStats dozenStats, dozenInfStats;
  int dozen = 0;
  LampEffectsReport::Tiles dozenTiles;  // the last frame's (tile, lamp) pairs by how each was taken
  {
    Scene many = run.scene;
    auto street = makeProfile(IsotropicProfile{4000.0});
    int added = 0;
    auto glowingLamps = [&] {
      int n = 0;
      for (const auto& l : many.lamps) n += l.mount == LampMount::Vehicle ? 0 : 1;
      return n;
    };
    while (street && glowingLamps() < 12) {
      SceneLamp l;
      l.name = "street " + std::to_string(added);
      l.lamp.position_m = many.camera.position_m + Vec3(20.0 + 25.0 * (added / 2), (added % 2) ? 6.0 : -6.0, 8.0);
      l.lamp.worldFromLamp = worldFromAxis(Vec3(0, 0, -1));
      l.lamp.profile = *street;
      many.lamps.push_back(l);
      ++added;
    }
    GlowOptions glowOpt;
    glowOpt.enabled = true;
    auto fxPool = std::shared_ptr<ThreadPool>(&run.pool, [](ThreadPool*) {});
    auto fx12 = LampEffects::build(many, glowOpt, GlareOptions{}, fxPool);
    // The same frames in infinite fog (no ground factor), alternated with them: what the factor costs.
    GlowOptions infOpt = glowOpt;
    infOpt.ground_reflectance = -1.0;
    auto fx12inf = LampEffects::build(many, infOpt, GlareOptions{}, fxPool);
    if (fx12 && fx12inf) {
      LampEffectsReport repInf;
      for (int f = 0; f < run.o.frames + 1; ++f) {
        for (auto& l : many.lamps)
          if (l.mount != LampMount::Vehicle) l.lamp.position_m.x -= 0.5;
        fx12->evaluate(many, run.surface, glowLayer, glareLayer, rep);
        if (f > 0) dozenStats.ms.push_back(1e3 * rep.glow_seconds);  // the first sizes the buffers
        fx12inf->evaluate(many, run.surface, glowLayer, glareLayer, repInf);
        if (f > 0) dozenInfStats.ms.push_back(1e3 * repInf.glow_seconds);
      }
      for (const auto& l : rep.lamps) dozen += !l.own && l.glow_peak_cd_m2 > 0.0 ? 1 : 0;
      dozenTiles = rep.glow_tiles;
    }
  }
  return {{"glow", glowStats.toJson()},
          {"ground_veil", veil},
          {"ground_veil_build_ms", veilBuildMs},
          {"glow_dozen_lamps", dozenStats.toJson()},
          {"glow_dozen_lamps_infinite_fog", dozenInfStats.toJson()},
          {"lamps_glowing_in_dozen", dozen},
          {"dozen_tiles", {{"bilinear", dozenTiles.bilinear}, {"half_cells", dozenTiles.half}, {"per_pixel", dozenTiles.exact}}},
          {"glare", glareStats.toJson()},
          {"lamps_in_view", visible},
          {"lamps_with_glow", glowing},
          {"own_lamps_with_glow", ownGlowing},
          {"glow_light_share", sumBase > 0.0 ? sumGlow / sumBase : 0.0},
          {"glare_light_share", sumBase > 0.0 ? sumGlare / sumBase : 0.0},
          {"eye_illuminance_lx", rep.eye_illuminance_lx},
          {"veiling_luminance_centre_cd_m2", rep.veiling_luminance_cd_m2}};
}

// A fixed random sample of pixels (seed o.seed) for the error figures.
std::vector<SamplePixel> samplePixels(const SizeRun& run) {
  std::mt19937 rng(run.o.seed);
  std::uniform_int_distribution<int> di(0, run.scene.camera.width - 1), dj(0, run.scene.camera.height - 1);
  std::vector<SamplePixel> px(static_cast<std::size_t>(run.o.samplePixels));
  for (SamplePixel& p : px) {
    p.i = di(rng);
    p.j = dj(rng);
  }
  return px;
}

// The ray marcher: the smallest power-of-two step count whose p95 against the reference
// (`lRef` on the sample `px`) matches the accurate method's (`accurateP95`), and its cost
// extrapolated to the frame against the accurate full frame (`accurateFullMs`).
json rayMarcherStage(SizeRun& run, const std::vector<SamplePixel>& px, const std::vector<double>& lRef,
                     double accurateP95, double accurateFullMs) {
  const double perPixel = 1.0 / static_cast<double>(px.size());
  json tried = json::array();
  json rm;
  bool matched = false;
  for (int steps = 16; steps <= run.o.maxRayMarchSteps; steps *= 2) {
    auto marcher = RayMarchEvaluator::build(run.scene, steps);
    if (!marcher) {
      rm["error"] = marcher.error().message;
      break;
    }
    std::vector<double> lRm;
    const double rmMs = evaluateSample(run.pool, run.scene.camera, run.surface, px,
                                       [&m = *marcher](const Ray& ray, float rgb[3]) { m.evaluateRay(ray, rgb); }, lRm);
    const ErrorStats e = relativeErrors(lRm, lRef);
    const double usPerPixel = 1e3 * rmMs * perPixel;
    tried.push_back({{"steps", steps}, {"median", e.median}, {"p95", e.p95}, {"us_per_pixel", usPerPixel}});
    rm = {{"steps", steps}, {"median", e.median}, {"p95", e.p95}, {"us_per_pixel", usPerPixel},
          {"full_frame_ms_extrapolated", 1e-3 * usPerPixel * static_cast<double>(run.nPixels)}};
    if (e.p95 <= accurateP95) {
      matched = true;
      break;
    }
  }
  rm["matched_accurate_p95"] = matched;
  rm["accurate_full_frame_ms"] = accurateFullMs;
  if (rm.contains("full_frame_ms_extrapolated") && accurateFullMs > 0.0)
    rm["speed_ratio"] = rm["full_frame_ms_extrapolated"].get<double>() / accurateFullMs;
  rm["tried"] = tried;
  return rm;
}

// Accuracy on this frame: every method against the reference on the sample of pixels (the
// images' pixels for the full and subsampled images), the subsampled image against the full
// one over every pixel, the cost per pixel of each method and of each lamp alone, and the ray
// marcher at equal error. `accurateFullMs`: the full image's median frame time.
json accuracyStage(SizeRun& run, double accurateFullMs) {
  const Camera& cam = run.scene.camera;
  const std::vector<SamplePixel> px = samplePixels(run);
  auto rayFn = [](const AirlightImageEvaluator& e) {
    return [&e](const Ray& ray, float rgb[3]) { e.evaluateRay(ray, rgb); };
  };
  std::vector<double> lRef, lSeed, lRay, lAcc(px.size()), lSub(px.size());
  const double refMs = evaluateSample(run.pool, cam, run.surface, px, rayFn(run.ev.reference), lRef);
  const double seedMs = evaluateSample(run.pool, cam, run.surface, px, rayFn(run.ev.seed), lSeed);
  const double accMs = evaluateSample(run.pool, cam, run.surface, px, rayFn(run.ev.accurate), lRay);
  std::vector<double> lFullAll(run.nPixels), lSubAll(run.nPixels);
  for (std::size_t k = 0; k < run.nPixels; ++k) {
    lFullAll[k] = luminance(&run.full.rgb[3 * k]);
    lSubAll[k] = luminance(&run.sub.rgb[3 * k]);
  }
  for (std::size_t k = 0; k < px.size(); ++k) {
    const std::size_t idx = static_cast<std::size_t>(px[k].j) * static_cast<std::size_t>(cam.width) +
                            static_cast<std::size_t>(px[k].i);
    lAcc[k] = lFullAll[idx];
    lSub[k] = lSubAll[idx];
  }
  // Subsampled against full over every pixel of the frame, not just the sample.
  const ErrorStats eSeed = relativeErrors(lSeed, lRef), eAcc = relativeErrors(lAcc, lRef),
                   eRay = relativeErrors(lRay, lRef), eSub = relativeErrors(lSub, lRef),
                   eSubFull = relativeErrors(lSubAll, lFullAll);
  const double perPixel = 1.0 / static_cast<double>(px.size());
  json acc;
  acc["sample_pixels"] = px.size();
  acc["seed"] = run.o.seed;
  acc["reference_threshold_cd_m2"] = kRefThresholdCdM2;
  acc["luminance"] = "mean of R, G, B (white lamps: cd/m2)";
  acc["seed_method"] = eSeed.toJson();
  acc["accurate_full"] = eAcc.toJson();
  acc["accurate_per_ray"] = eRay.toJson();
  acc["accurate_subsampled"] = eSub.toJson();
  acc["subsampled_vs_full"] = eSubFull.toJson();
  acc["cost_us_per_pixel"] = {{"reference", 1e3 * refMs * perPixel},
                              {"seed", 1e3 * seedMs * perPixel},
                              {"accurate_per_ray", 1e3 * accMs * perPixel},
                              {"accurate_image_full", accurateFullMs * 1e3 / static_cast<double>(run.nPixels)}};
  // Where the per-ray accurate method's time goes: each lamp alone on the same sample.
  json byLamp = json::array();
  for (const SceneLamp& sl : run.scene.lamps) {
    auto one = AirlightEvaluator::build(sl.lamp, run.scene.fog, AirlightMethod::Accurate);
    if (!one) continue;
    std::vector<double> l;
    const double ms = evaluateSample(run.pool, cam, run.surface, px,
                                     [&e = *one](const Ray& ray, float rgb[3]) {
                                       rgb[0] = rgb[1] = rgb[2] = static_cast<float>(e.evaluate(ray));
                                     },
                                     l);
    byLamp.push_back({{"lamp", sl.name}, {"us_per_pixel", 1e3 * ms * perPixel}});
  }
  acc["accurate_cost_us_per_pixel_by_lamp"] = byLamp;
  acc["raymarch"] = rayMarcherStage(run, px, lRef, eAcc.p95, accurateFullMs);
  return acc;
}

// One image size: every stage in the order a frame runs them, each stage's figures under its
// key (the table printSize() prints), then the pipeline of the subsampled frame and the errors.
json benchSize(const Scene& original, int width, int height, const BenchOptions& o, Evaluators& ev, ThreadPool& pool,
               GlSurfacePass* gl) {
  SizeRun run(resized(original, width, height), o, ev, pool, gl);
  json r;
  r["width"] = width;
  r["height"] = height;
  r["pixels"] = run.nPixels;

  json& stages = r["stages"];
  stages["surface_cpu_planes"] = surfaceCpuStage(run);
  stages["surface_cpu_fast"] = surfaceCpuFastStage(run);
  stages["surface_cpu_fog_light"] = surfaceCpuFogLightStage(run);
  stages["surface_gl_fog_light"] = surfaceGlFogLightStage(run);
  stages["surface_gl"] = surfaceGlStage(run);
  stages["airlight_first_frame"] = airlightFirstFrameStage(run);
  stages["airlight_subsampled"] = airlightSubsampledStage(run);
  stages["airlight_full"] = airlightFullStage(run);
  stages["airlight_kernels_by_target"] = kernelsByTargetStage(run);
  stages["composite"] = compositeStage(run);
  r["glow_glare"] = glowGlareStage(run);
  stages["pack"] = packStage(run);
  r["whole_frame"] = wholeFrameStage(run);

  // The frame as `fogbeam render` runs it: the surfaces the airlight stages read (GL when it
  // works), the subsampled airlight, the composite.
  const bool glUsed = stages["surface_gl"]["available"].get<bool>();
  const double surfaceMs = glUsed ? stages["surface_gl"]["total"]["median_ms"].get<double>()
                                  : stages["surface_cpu_fast"]["median_ms"].get<double>();
  const double pipelineMs = surfaceMs + stages["airlight_subsampled"]["median_ms"].get<double>() +
                            stages["composite"]["median_ms"].get<double>();
  r["pipeline_subsampled_ms"] = pipelineMs;
  r["pipeline_surface"] = glUsed ? "surface GL" : "surface CPU";
  r["fps_subsampled"] = pipelineMs > 0.0 ? 1e3 / pipelineMs : 0.0;
  // The whole frame (issue 17): the pipeline above plus glow, glare and packing into the slower
  // of the two shm formats — every stage a channel with glow and glare on runs per frame, one
  // after the other (medians).
  const json& gg = r["glow_glare"];
  const double effectsMs = gg.contains("glow") ? gg["glow"]["median_ms"].get<double>() + gg["glare"]["median_ms"].get<double>() : 0.0;
  const double packMs = std::max(stages["pack"]["rgba8_srgb"]["median_ms"].get<double>(),
                                 stages["pack"]["rgba16f_overlay"]["median_ms"].get<double>());
  r["whole_frame_ms"] = pipelineMs + effectsMs + packMs;
  r["whole_frame_fps"] = 1e3 / (pipelineMs + effectsMs + packMs);

  r["accuracy"] = accuracyStage(run, stages["airlight_full"]["median_ms"].get<double>());
  return r;
}

void printStage(const char* name, const json& s, const char* note = "") {
  std::printf("  %-30s %9.2f ms  [%9.2f – %9.2f]  %2d frame%s%s\n", name, s["median_ms"].get<double>(),
              s["min_ms"].get<double>(), s["max_ms"].get<double>(), s["frames"].get<int>(),
              s["frames"].get<int>() == 1 ? " " : "s", note);
}

void printError(const char* name, const json& e) {
  std::printf("  %-30s median %8.2e   p95 %8.2e   max %8.2e   (%d pixels)\n", name, e["median"].get<double>(),
              e["p95"].get<double>(), e["max"].get<double>(), e["pixels"].get<int>());
}

void printEffects(const json& e) {
  if (e.contains("error")) {
    std::printf("  %-30s %s\n", "glow, glare", e["error"].get<std::string>().c_str());
    return;
  }
  char note[320];
  std::snprintf(note, sizeof note, "  %d of %d lamps in view glow, and %d of the driver's; +%.1f %% of the frame's light",
                e["lamps_with_glow"].get<int>(), e["lamps_in_view"].get<int>(), e.value("own_lamps_with_glow", 0),
                100.0 * e["glow_light_share"].get<double>());
  if (e.value("ground_veil", false)) {
    const std::size_t used = std::strlen(note);
    std::snprintf(note + used, sizeof note - used, "; the road veil of the driver's lamps made in %.1f ms (first frame)",
                  e.value("ground_veil_build_ms", 0.0));
  }
  printStage("glow", e["glow"], note);
  if (e.contains("glow_dozen_lamps") && e["glow_dozen_lamps"]["frames"].get<std::size_t>() > 0) {
    std::snprintf(note, sizeof note, "  12 lamps, %d glowing (the rest hidden), all moving: curves anew each frame",
                  e["lamps_glowing_in_dozen"].get<int>());
    if (e.contains("dozen_tiles")) {
      const auto& t = e["dozen_tiles"];
      const std::size_t used = std::strlen(note);
      std::snprintf(note + used, sizeof note - used, "; (tile, lamp) pairs %zu from the grid, %zu half-cells, %zu per pixel",
                    t["bilinear"].get<std::size_t>(), t["half_cells"].get<std::size_t>(), t["per_pixel"].get<std::size_t>());
    }
    printStage("glow, a dozen lamps", e["glow_dozen_lamps"], note);
    if (e.contains("glow_dozen_lamps_infinite_fog"))
      printStage("  the same, infinite fog", e["glow_dozen_lamps_infinite_fog"],
                 "  no ground factor ([glow] ground = false), frames alternated with the above");
  }
  std::snprintf(note, sizeof note, "  E at the eye %.3g lx, L_v at the centre %.3g cd/m2; +%.1f %% of the light",
                e["eye_illuminance_lx"].get<double>(), e["veiling_luminance_centre_cd_m2"].get<double>(),
                100.0 * e["glare_light_share"].get<double>());
  printStage("glare (CIE 146)", e["glare"], note);
}

void printSize(const json& r) {
  const int w = r["width"].get<int>(), h = r["height"].get<int>();
  const double n = r["pixels"].get<double>();
  const json& s = r["stages"];
  std::printf("\n%d x %d (%.0f pixels)       median       [min – max]\n", w, h, n);
  printStage("surface CPU (SIMD, no GL)", s["surface_cpu_fast"], "  planes + bonnet: the fallback");
  if (s["surface_cpu_fog_light"].value("available", false)) {
    char note[160];
    std::snprintf(note, sizeof note, "  with the fog's light on the surfaces (first frame, its tables: %.0f ms)",
                  s["surface_cpu_fog_light"]["first_frame_ms"].get<double>());
    printStage("surface CPU + fog light", s["surface_cpu_fog_light"], note);
  }
  printStage("surface CPU planes (double)", s["surface_cpu_planes"], "  the oracle");
  if (s["surface_gl"]["available"].get<bool>()) {
    printStage("surface GL: render() total", s["surface_gl"]["total"]);
    printStage("  of which GPU draw", s["surface_gl"]["draw"]);
    printStage("  of which readback", s["surface_gl"]["readback"]);
    if (s["surface_gl"].value("shading", "") == "cpu")
      printStage("    of which CPU shading", s["surface_gl"]["shade"], "  (SIMD, the pass's geometry buffer)");
    const json& fl = s["surface_gl_fog_light"];
    if (fl.value("available", false)) {
      char note[120];
      std::snprintf(note, sizeof note, "  (first frame, its tables: %.0f ms)", fl["first_frame_ms"].get<double>());
      printStage("surface GL + fog light: total", fl["total"], note);
      printStage("  of which GPU draw", fl["draw"]);
      if (s["surface_gl"].value("shading", "") == "cpu")
        printStage("    of which CPU shading", fl["shade"]);
    }
  } else {
    std::printf("  %-30s %s\n", "surface (GL)", s["surface_gl"]["note"].get<std::string>().c_str());
  }
  char note[160];
  std::snprintf(note, sizeof note, "  %zu px evaluated (%.1f %%)", s["airlight_subsampled"]["evaluated_pixels"].get<std::size_t>(),
                100.0 * s["airlight_subsampled"]["evaluated_pixels"].get<double>() / n);
  printStage("airlight accurate, subsampled", s["airlight_subsampled"], note);
  printStage("  of which evaluation", s["airlight_subsampled"]["evaluate"]);
  printStage("  of which block tests, edges", s["airlight_subsampled"]["judge"]);
  printStage("  of which interpolation", s["airlight_subsampled"]["fill"]);
  printStage("airlight accurate, full", s["airlight_full"], "  all px, whole frames");
  std::printf("  %-30s %9.2f ms  (of which view-table build %.2f ms; reused by later frames)\n",
              "airlight first frame", s["airlight_first_frame"]["ms"].get<double>(),
              s["airlight_first_frame"]["view_table_build_ms"].get<double>());
  std::printf("  %-30s", "kernels, 1 thread (ns/px)");
  for (const json& t : s["airlight_kernels_by_target"])
    std::printf(" %s %.1f (%.1fx);", t["target"].get<std::string>().c_str(), t["ns_per_pixel"].get<double>(),
                t["speedup"].get<double>());
  std::printf("\n");
  printStage("composite", s["composite"]);
  printEffects(r["glow_glare"]);
  printStage("pack RGBA8 sRGB", s["pack"]["rgba8_srgb"]);
  printStage("pack RGBA16F overlay", s["pack"]["rgba16f_overlay"]);
  std::printf("  %-30s %9.2f ms  = %.1f frames/s (%s + airlight subsampled + composite)\n", "pipeline, subsampled",
              r["pipeline_subsampled_ms"].get<double>(), r["fps_subsampled"].get<double>(),
              r["pipeline_surface"].get<std::string>().c_str());
  std::printf("  %-30s %9.2f ms  = %.1f frames/s (the medians above: + glow + glare + packing)\n", "whole frame, by stage",
              r["whole_frame_ms"].get<double>(), r["whole_frame_fps"].get<double>());
  const json& wf = r["whole_frame"];
  if (!wf.contains("error")) {
    std::printf("  %-30s %9.2f ms  = %.1f frames/s, %.2f of %.0f cores busy; stages (ms, cores):",
                "whole frame, run in sequence", wf["frame"]["median_ms"].get<double>(),
                1e3 / wf["frame"]["median_ms"].get<double>(), wf["frame"]["cores_busy"].get<double>(),
                wf["cores"].get<double>());
    for (const char* k : {"surface", "airlight", "glow_glare", "composite", "pack"})
      std::printf(" %s %.1f (%.2f)", k, wf[k]["median_ms"].get<double>(), wf[k]["cores_busy"].get<double>());
    std::printf("; overlapping frames could reach at best %.1f ms (its CPU time / cores)\n",
                wf["overlap_bound_ms"].get<double>());
  }

  const json& a = r["accuracy"];
  std::printf("  error vs reference on %d random pixels (seed %u), counted where reference > %.0e cd/m2:\n",
              a["sample_pixels"].get<int>(), a["seed"].get<unsigned>(), a["reference_threshold_cd_m2"].get<double>());
  printError("seed", a["seed_method"]);
  printError("accurate per ray (no tables)", a["accurate_per_ray"]);
  printError("accurate image, full", a["accurate_full"]);
  printError("accurate image, subsampled", a["accurate_subsampled"]);
  printError("subsampled vs full, all px", a["subsampled_vs_full"]);
  const json& c = a["cost_us_per_pixel"];
  std::printf("  %-30s reference %.1f, seed %.2f, accurate per ray %.2f, accurate image %.4f us (wall, all threads)\n",
              "cost per pixel", c["reference"].get<double>(), c["seed"].get<double>(),
              c["accurate_per_ray"].get<double>(), c["accurate_image_full"].get<double>());
  std::printf("  %-30s", "per-ray accurate, by lamp (us/px)");
  for (const json& l : a["accurate_cost_us_per_pixel_by_lamp"])
    std::printf(" %s %.1f;", l["lamp"].get<std::string>().c_str(), l["us_per_pixel"].get<double>());
  std::printf("\n");
  const json& rm = a["raymarch"];
  std::printf("  ray marcher (midpoint rule, fixed N), p95 per N:");
  for (const json& t : rm["tried"]) std::printf(" %d:%.1e", t["steps"].get<int>(), t["p95"].get<double>());
  std::printf("\n");
  if (rm.contains("steps")) {
    std::printf("  %-30s N = %d%s: p95 %.2e (accurate %.2e), %.2f us/px -> %.0f ms/frame vs accurate full %.1f ms",
                "ray marcher at equal error", rm["steps"].get<int>(), rm["matched_accurate_p95"].get<bool>() ? "" : " (largest tried: NOT matched)",
                rm["p95"].get<double>(), a["accurate_full"]["p95"].get<double>(), rm["us_per_pixel"].get<double>(),
                rm["full_frame_ms_extrapolated"].get<double>(), rm["accurate_full_frame_ms"].get<double>());
    if (rm.contains("speed_ratio"))
      std::printf(" = accurate %.1fx %s", rm["speed_ratio"].get<double>(), rm["matched_accurate_p95"].get<bool>() ? "faster" : "faster (lower bound)");
    std::printf("\n");
  }
}

std::vector<double> luminances(const std::vector<float>& rgb) {
  std::vector<double> l(rgb.size() / 3);
  for (std::size_t k = 0; k < l.size(); ++k) l[k] = luminance(&rgb[3 * k]);
  return l;
}

double sumOf(const std::vector<double>& v) { return std::accumulate(v.begin(), v.end(), 0.0); }

/// Accurate-method evaluator for `scene`, its first frame (view tables) and then steady frames
/// (subsampled, then full): what a frame of this scene costs on the CPU.
struct CpuFrames {
  double firstMs = 0.0, tableMs = 0.0;
  StageStats sub, full;
  AirlightImage fullImage;
};
Result<CpuFrames> cpuFrames(const Scene& scene, const SurfaceBuffers& surface, unsigned threads, const BenchOptions& o) {
  FastPathOptions fast;
  fast.view_table_step_deg = o.viewTableStepDeg;
  auto ev = AirlightImageEvaluator::build(scene, AirlightMethod::Accurate, {}, threads, fast);
  if (!ev) return ev.error();
  CpuFrames c;
  AirlightImage img;
  auto t0 = Clock::now();
  ev->evaluate(scene, surface, SubsamplingOptions{}, img);
  c.firstMs = msSince(t0);
  c.tableMs = 1e3 * img.table_seconds;
  for (int f = 0; f < o.frames; ++f) {
    t0 = Clock::now();
    ev->evaluate(scene, surface, SubsamplingOptions{}, img);
    c.sub.ms.push_back(msSince(t0));
  }
  for (int f = 0; f < o.frames; ++f) {
    t0 = Clock::now();
    ev->evaluate(scene, surface, SubsamplingOptions{.full = true}, c.fullImage);
    c.full.ms.push_back(msSince(t0));
  }
  return c;
}

// Issue 7's GPU airlight stage (GlSurfacePass::setAirlight) at `o.gpuSize`: the surface pass
// alone, then with the stage (its first frame compiles the shader and uploads the G-moment
// table, timed on its own), the stage's GPU time, and its image against the CPU's accurate
// method (full and subsampled frames timed beside it) on the same surfaces.
json gpuAirlightStage(const Scene& base, const BenchOptions& o, unsigned threads, GlSurfacePass* gl) {
  json gpu = {{"available", false}};
  int w = 0, h = 0;
  if (!gl) {
    gpu["note"] = "GL: not available (no EGL)";
    return gpu;
  }
  if (!parseSize(o.gpuSize, w, h)) return gpu;
  const Scene scene = resized(base, w, h);
  SurfaceBuffers surface, surfaceGpu;
  std::vector<float> air;
  StageStats surfaceOnly, total, airGpu;
  std::string failure;
  for (int f = 0; f < o.frames && failure.empty(); ++f) {
    const auto t0 = Clock::now();
    if (Status st = gl->render(scene, surface); !st) failure = st.error().message;
    surfaceOnly.ms.push_back(msSince(t0));
  }
  GpuAirlightOptions opt;
  if (Status st = gl->setAirlight(opt); !st && failure.empty()) failure = st.error().message;
  const auto tWarm = Clock::now();
  if (failure.empty())
    if (Status st = gl->render(scene, surfaceGpu, air); !st) failure = st.error().message;
  const double warmMs = msSince(tWarm);
  for (int f = 0; f < o.frames && failure.empty(); ++f) {
    const auto t0 = Clock::now();
    if (Status st = gl->render(scene, surfaceGpu, air); !st) failure = st.error().message;
    total.ms.push_back(msSince(t0));
    airGpu.ms.push_back(gl->stats().airlight_ms);
  }
  (void)gl->setAirlight(std::nullopt);
  auto cpu = cpuFrames(scene, surface, threads, o);
  if (!failure.empty()) {
    gpu["note"] = "GPU airlight failed: " + failure;
  } else if (!cpu) {
    gpu["note"] = "CPU accurate failed: " + cpu.error().message;
  } else {
    const std::vector<double> lg = luminances(air), lc = luminances(cpu->fullImage.rgb);
    const double sc = sumOf(lc);
    gpu = {{"available", true},
           {"note", gl->description()},
           {"width", w},
           {"height", h},
           {"pieces", opt.pieces},
           {"first_frame_ms", warmMs},
           {"surface_only", surfaceOnly.toJson()},
           {"surface_and_airlight", total.toJson()},
           {"airlight_gpu_time", airGpu.toJson()},
           {"cpu_accurate_full", cpu->full.toJson()},
           {"cpu_accurate_subsampled", cpu->sub.toJson()},
           {"vs_cpu_full", relativeErrors(lg, lc).toJson()},
           {"sum_ratio", sc > 0.0 ? sumOf(lg) / sc : 0.0}};
  }
  return gpu;
}

// Near-field lamps at `o.apertureSize`: the scene's vehicle lamps given a 0.20 × 0.10 m face
// (Gauss rules of point lamps) against the point lamps, on the same CPU surfaces: the cost of
// the first and steady frames, and the airlight's change.
json nearFieldStage(const Scene& base, const BenchOptions& o, unsigned threads) {
  json ap;
  int w = 0, h = 0;
  if (!parseSize(o.apertureSize, w, h)) return ap;
  const Scene scene = resized(base, w, h);
  Scene faced = scene;
  faced.lamps.clear();
  int vehicle = 0;
  for (SceneLamp l : scene.lamps) {
    if (l.mount == LampMount::Vehicle) {
      l.aperture = Aperture{ApertureShape::Rectangle, 0.20, 0.10, kDefaultApertureSamples};
      ++vehicle;
    }
    for (SceneLamp& p : expandSceneLamp(l)) faced.lamps.push_back(std::move(p));
  }
  SurfaceBuffers surface;
  renderSurfacesCpu(scene, surface);  // the same surfaces for both: the airlight's difference only
  auto point = cpuFrames(scene, surface, threads, o);
  auto face = cpuFrames(faced, surface, threads, o);
  if (!point || !face) {
    ap["note"] = !point ? point.error().message : face.error().message;
    return ap;
  }
  const std::vector<double> lp = luminances(point->fullImage.rgb), lf = luminances(face->fullImage.rgb);
  const double sp = sumOf(lp);
  return {{"width", w},
          {"height", h},
          {"vehicle_lamps", vehicle},
          {"face_m", {0.20, 0.10}},
          {"samples_per_axis", kDefaultApertureSamples},
          {"point_lamps", faced.lamps.size()},
          {"point", {{"first_frame_ms", point->firstMs}, {"view_tables_ms", point->tableMs},
                     {"subsampled", point->sub.toJson()}, {"full", point->full.toJson()}}},
          {"aperture", {{"first_frame_ms", face->firstMs}, {"view_tables_ms", face->tableMs},
                        {"subsampled", face->sub.toJson()}, {"full", face->full.toJson()}}},
          {"aperture_vs_point_full", relativeErrors(lf, lp).toJson()},
          {"sum_ratio", sp > 0.0 ? sumOf(lf) / sp : 0.0}};
}

// Issue 15: lamps that move relative to the eye. The shipped traffic scene (kBenchTrafficScene)
// at o.trafficSize: a drive of 1 + o.frames frames at 30 Hz in which both oncoming cars come
// towards the ego car at 15 m/s (their four measured low beams take a new pose every frame),
// for each moving-lamp path (per-frame lamp maps, per-pixel pencil), and the same frames with
// the cars removed (ego low beams and street lamps: the static frame). The first frame of each
// builds the ego lamps' view tables and is not timed. Then the last frame of each path against
// the per-ray accurate method (every lamp per ray, no tables: the definition) on sample pixels
// above 1 % of the frame's 99.5th percentile of luminance.
struct TrafficRun {
  StageStats airlight;
  double firstMs = 0.0;  // the untimed first frame: the ego lamps' view tables built
  std::size_t evaluated = 0, mapNodes = 0, spokes = 0, movingEvaluated = 0, culled = 0, dropped = 0;
  double mapMs = 0.0;
  // Medians over the frames, ms: the spokes' stage, and the thread time per stage / threads.
  double spokeMs = 0.0, evalMs = 0.0, judgeMs = 0.0, fillMs = 0.0;
  AirlightImage last;
  Scene lastScene;  // the poses of the last frame
};

Result<TrafficRun> trafficFrames(Scene scene, const SurfaceBuffers& surface, const std::vector<std::size_t>& cars,
                                 MovingLampPath path, unsigned threads, const BenchOptions& o,
                                 double cutoff = FastPathOptions{}.moving_lamp_cutoff_cd_m2,
                                 const SubsamplingOptions& sub = {}, int budget = 0) {
  FastPathOptions fast;
  fast.view_table_step_deg = o.viewTableStepDeg;
  fast.moving_lamps = path;
  fast.moving_lamp_cutoff_cd_m2 = cutoff;
  fast.max_moving_lamps = budget;
  auto ev = AirlightImageEvaluator::build(scene, AirlightMethod::Accurate, {}, threads, fast);
  if (!ev) return ev.error();
  TrafficRun run;
  AirlightImage img;
  const auto tf = Clock::now();
  ev->evaluate(scene, surface, sub, img);  // view tables of the ego lamps
  run.firstMs = msSince(tf);
  constexpr double kStepM = 15.0 / 30.0;                     // 15 m/s at 30 Hz
  std::vector<double> mapMs, spokeMs, evalMs, judgeMs, fillMs;
  for (int f = 0; f < o.frames; ++f) {
    for (std::size_t i : cars) {
      Lamp& l = scene.lamps[i].lamp;
      l.position_m += kStepM * (l.worldFromLamp * Vec3(1.0, 0.0, 0.0));  // along the lamp's own axis
    }
    if (Status st = ev->setLampPoses(scene); !st) return st.error();
    const auto t0 = Clock::now();
    ev->evaluate(scene, surface, sub, run.last);
    run.airlight.ms.push_back(msSince(t0));
    run.culled = run.last.moving_culled;
    run.dropped = run.last.moving_dropped;
    run.evaluated = run.last.evaluated;
    run.mapNodes = run.last.map_nodes;
    run.spokes = run.last.spokes;
    run.movingEvaluated = run.last.moving_evaluated;
    mapMs.push_back(1e3 * run.last.map_seconds);
    spokeMs.push_back(1e3 * run.last.spoke_seconds);
    evalMs.push_back(1e3 * run.last.eval_seconds);
    judgeMs.push_back(1e3 * run.last.judge_seconds);
    fillMs.push_back(1e3 * run.last.fill_seconds);
  }
  run.mapMs = percentile(mapMs, 0.5);
  run.spokeMs = percentile(spokeMs, 0.5);
  run.evalMs = percentile(evalMs, 0.5);
  run.judgeMs = percentile(judgeMs, 0.5);
  run.fillMs = percentile(fillMs, 0.5);
  run.lastScene = std::move(scene);
  return run;
}

// An image against the per-ray accurate method (`reference`, every lamp per ray: the
// definition) on up to o.samplePixels of its pixels above 1 % of its 99.5th percentile of
// luminance (that threshold to `threshold`), drawn with o.seed.
json againstPerRay(const AirlightImageEvaluator& reference, const Scene& scene, const SurfaceBuffers& surface,
                   const AirlightImage& img, ThreadPool& pool, const BenchOptions& o, json& threshold) {
  const std::vector<double> lum = luminances(img.rgb);
  const double floor = 0.01 * percentile(lum, 0.995);
  std::vector<SamplePixel> px;
  std::mt19937 rng(o.seed);
  std::vector<std::size_t> bright;
  for (std::size_t k = 0; k < lum.size(); ++k)
    if (lum[k] > floor) bright.push_back(k);
  std::shuffle(bright.begin(), bright.end(), rng);
  bright.resize(std::min<std::size_t>(bright.size(), static_cast<std::size_t>(o.samplePixels)));
  const auto w = static_cast<std::size_t>(img.width);
  for (std::size_t k : bright) px.push_back({static_cast<int>(k % w), static_cast<int>(k / w)});
  std::vector<double> want, got;
  evaluateSample(pool, scene.camera, surface, px, [&](const Ray& ray, float rgb[3]) { reference.evaluateRay(ray, rgb); },
                 want);
  for (const SamplePixel& p : px) got.push_back(lum[static_cast<std::size_t>(p.j) * w + static_cast<std::size_t>(p.i)]);
  threshold = floor;
  return relativeErrors(got, want).toJson();
}

// Issue 15, item 2: a fog that changes every frame and lamps that bend, on the traffic scene
// without its cars (the ego's low beams, the street lamps). A steady frame reads the ego lamps
// from view tables, which take a build per fog and bending angle (the first frame's table time).
// `base` is the steady run (trafficFrames of `still`): its frames and its first frame's table
// build are reported here. A frame whose fog or bending has no tables yet (the service's pending frames, [render]
// pending_tables = "per-pixel") evaluates them per pixel through one evaluator kept from frame to
// frame, given each frame's fog and poses (setFog, setLampPoses), as the service does. The run:
// the visibility falls log-linearly from 150 m to 50 m (a new fog every frame) while the ego
// lamps bend 1° further every 4 frames (a swivel about the vertical through the lamp); one
// untimed frame first. Then the last frame against per ray.
// The fog ladder (docs/airlight.md, "The fog ladder"): changesStage's fogs without the bending
// (bending has no ladder), on an evaluator like the steady frames' (the ego lamps on view
// tables, its own built for the first frame's fog) given the rungs of K_t = 1.2^m per metre
// around the ramp, built first one by one (the service builds them in the background, nearest
// first). Each frame reads the two rungs around its fog. The last frame against per ray and
// against tables built at its own fog.
// With `bendDegPerFrame` > 0 the ego lamps also bend continuously, that many degrees further
// each frame (not on the rungs' angles), and the ladder has rungs every kBendStepDeg of bending
// at each fog (docs/airlight.md, "Bending on the ladder"): each frame reads four rungs, each
// turned rung through its rotation.
json ladderRun(const Scene& still, const SurfaceBuffers& surface, unsigned threads, const BenchOptions& o, int n,
               double steadyMs, double bendDegPerFrame = 0.0) {
  constexpr double kRatio = 1.2, kBendStepDeg = 1.0;
  FastPathOptions fast;
  fast.view_table_step_deg = o.viewTableStepDeg;
  auto pool = std::make_shared<ThreadPool>(threads);
  auto bent = [&](Scene fs, double deg) {
    const Mat3 turn = worldFromYawPitchRoll(radians(deg), 0.0, 0.0);
    for (SceneLamp& l : fs.lamps)
      if (l.mount == LampMount::Vehicle) l.lamp.worldFromLamp = turn * l.lamp.worldFromLamp;
    return fs;
  };
  auto sceneAt = [&](int f) {
    Scene fs = bent(still, bendDegPerFrame * f);
    fs.fog.extinction_per_m = extinctionFromVisibility(150.0 * std::pow(50.0 / 150.0, static_cast<double>(f) / (n - 1)));
    return fs;
  };
  const double lr = std::log(kRatio);
  const int m0 = static_cast<int>(std::floor(std::log(sceneAt(0).fog.extinction_per_m) / lr));
  const int m1 = static_cast<int>(std::ceil(std::log(sceneAt(n - 1).fog.extinction_per_m) / lr));
  const int bends = bendDegPerFrame > 0.0 ? static_cast<int>(std::ceil(bendDegPerFrame * (n - 1) / kBendStepDeg)) : 0;
  std::vector<std::shared_ptr<const FogTables>> rungs;
  StageStats rungMs;
  std::size_t bytes = 0;
  for (int m = m0; m <= m1; ++m)
    for (int b = 0; b <= bends; ++b) {
      Scene rs = bent(still, kBendStepDeg * b);
      rs.fog.extinction_per_m = std::pow(kRatio, m);
      const auto t0 = Clock::now();
      auto r = AirlightImageEvaluator::buildFogTables(rs, fast, pool);
      if (!r) return {{"note", r.error().message}};
      rungMs.ms.push_back(msSince(t0));
      bytes += fogTablesBytes(**r);
      rungs.push_back(std::move(r).value());
    }
  const Scene first = sceneAt(0);
  auto ev = AirlightImageEvaluator::build(first, AirlightMethod::Accurate, {}, pool, fast);
  if (!ev) return {{"note", ev.error().message}};
  AirlightImage img;
  ev->evaluate(first, surface, SubsamplingOptions{}, img);  // untimed: its own tables
  ev->setFogLadder(rungs, kRatio, bendDegPerFrame > 0.0 ? kBendStepDeg : 0.0);
  StageStats frames;
  int blended = 0, turned = 0;
  Scene last;
  for (int f = 0; f < n; ++f) {
    last = sceneAt(f);
    const auto t0 = Clock::now();
    if (Status st = ev->setFog(last.fog); !st) return {{"note", st.error().message}};
    if (Status st = ev->setLampPoses(last); !st) return {{"note", st.error().message}};
    ev->evaluate(last, surface, SubsamplingOptions{}, img);
    frames.ms.push_back(msSince(t0));
    blended += img.fog_rungs == 2 ? 1 : 0;
    turned += img.bending_rungs == 2 ? 1 : 0;
  }
  json out = frames.toJson();
  out["ratio"] = kRatio;
  out["bend_step_deg"] = kBendStepDeg;
  out["bend_deg_per_frame"] = bendDegPerFrame;
  out["frames_turned"] = turned;
  out["rungs"] = rungs.size();
  out["rung_build"] = rungMs.toJson();
  out["rung_mb"] = static_cast<double>(bytes) / 1e6 / static_cast<double>(rungs.size());
  out["frames_blended"] = blended;
  out["vs_steady_median"] = steadyMs > 0.0 ? frames.median() / steadyMs : 0.0;
  out["vs_steady_worst"] = steadyMs > 0.0 ? frames.max() / steadyMs : 0.0;
  auto reference = AirlightImageEvaluator::build(last, AirlightMethod::Accurate, {}, threads, FastPathOptions{});
  auto exact = AirlightImageEvaluator::build(last, AirlightMethod::Accurate, {}, pool, fast);
  if (!reference || !exact) return {{"note", !reference ? reference.error().message : exact.error().message}};
  ThreadPool rpool(threads);
  out["vs_per_ray"] = againstPerRay(*reference, last, surface, img, rpool, o, out["threshold_cd_m2"]);
  // Against tables at the last frame's fog, every pixel above the same threshold.
  AirlightImage at;
  exact->evaluate(last, surface, SubsamplingOptions{}, at);
  out["vs_tables_at_fog"] =
      relativeErrors(luminances(img.rgb), luminances(at.rgb), out["threshold_cd_m2"].get<double>()).toJson();
  return out;
}

json changesStage(const Scene& still, const SurfaceBuffers& surface, unsigned threads, const BenchOptions& o,
                  const TrafficRun& base) {
  json out;
  FastPathOptions fast;
  fast.view_table_step_deg = o.viewTableStepDeg;
  out["table_build_ms"] = base.firstMs;
  const StageStats& steadyStats = base.airlight;
  out["steady"] = steadyStats.toJson();
  AirlightImage img;

  Scene s = still;
  std::vector<std::size_t> ego;
  for (std::size_t i = 0; i < s.lamps.size(); ++i) {
    if (s.lamps[i].mount == LampMount::Vehicle) ego.push_back(i);
    s.lamps[i].mount = LampMount::World;  // per pixel, as a pending frame evaluates them
  }
  const int n = std::max(8, 4 * o.frames);
  auto frameScene = [&](int f) {
    Scene fs = s;
    const double v = 150.0 * std::pow(50.0 / 150.0, static_cast<double>(f) / (n - 1));
    fs.fog.extinction_per_m = extinctionFromVisibility(v);
    const Mat3 bend = worldFromYawPitchRoll(radians(static_cast<double>(f / 4)), 0.0, 0.0);
    for (std::size_t i : ego) fs.lamps[i].lamp.worldFromLamp = bend * s.lamps[i].lamp.worldFromLamp;
    return fs;
  };
  auto changing = AirlightImageEvaluator::build(frameScene(0), AirlightMethod::Accurate, {}, threads, fast);
  if (!changing) return {{"note", changing.error().message}};
  changing->evaluate(frameScene(0), surface, SubsamplingOptions{}, img);  // untimed: per-phase tables
  StageStats stats;
  std::vector<double> sampled, kept;
  Scene last;
  for (int f = 0; f < n; ++f) {
    last = frameScene(f);
    const auto t0 = Clock::now();
    if (Status st = changing->setFog(last.fog); !st) return {{"note", st.error().message}};
    if (Status st = changing->setLampPoses(last); !st) return {{"note", st.error().message}};
    changing->evaluate(last, surface, SubsamplingOptions{}, img);
    stats.ms.push_back(msSince(t0));
    sampled.push_back(static_cast<double>(img.spokes));
    kept.push_back(static_cast<double>(img.spokes_kept));
  }
  // The same frames with an evaluator built for each (the service's pending frames before
  // 2026-11-25): every spoke sampled again every frame.
  StageStats rebuilt;
  for (int f = 0; f < n; ++f) {
    const Scene fs = frameScene(f);
    const auto t0 = Clock::now();
    auto e = AirlightImageEvaluator::build(fs, AirlightMethod::Accurate, {}, threads, fast);
    if (!e) return {{"note", e.error().message}};
    AirlightImage scratch;
    e->evaluate(fs, surface, SubsamplingOptions{}, scratch);
    rebuilt.ms.push_back(msSince(t0));
  }
  out["rebuilt_each_frame"] = rebuilt.toJson();
  out["ladder"] = ladderRun(still, surface, threads, o, n, steadyStats.median());
  out["bending_ladder"] = ladderRun(still, surface, threads, o, n, steadyStats.median(), 0.1);
  json c = stats.toJson();
  const double steadyMs = steadyStats.median();
  c["vs_steady_median"] = steadyMs > 0.0 ? stats.median() / steadyMs : 0.0;
  c["vs_steady_worst"] = steadyMs > 0.0 ? stats.max() / steadyMs : 0.0;
  c["spokes_sampled_median"] = percentile(sampled, 0.5);
  c["spokes_kept_median"] = percentile(kept, 0.5);
  auto reference = AirlightImageEvaluator::build(last, AirlightMethod::Accurate, {}, threads, FastPathOptions{});
  if (!reference) return {{"note", reference.error().message}};
  ThreadPool pool(threads);
  c["vs_per_ray"] = againstPerRay(*reference, last, surface, img, pool, o, c["threshold_cd_m2"]);
  out["changing"] = c;
  out["frames"] = n;
  return out;
}

json denseTrafficStage(const Scene& scene, const std::vector<std::size_t>& cars0, const SurfaceBuffers& surface,
                       unsigned threads, const BenchOptions& o);

json trafficStage(const BenchOptions& o, unsigned threads, GlSurfacePass* gl) {
  json out;
  int w = 0, h = 0;
  if (!parseSize(o.trafficSize, w, h)) return out;
  auto loaded = loadScene(o.trafficScene);
  if (!loaded) {
    out["note"] = loaded.error().message;
    return out;
  }
  const Scene scene = resized(*loaded, w, h);
  std::vector<std::size_t> cars;  // measured lamps not fixed to the camera: the traffic
  Scene still = scene;
  still.lamps.clear();
  for (std::size_t i = 0; i < scene.lamps.size(); ++i) {
    const SceneLamp& l = scene.lamps[i];
    if (l.mount != LampMount::Vehicle && !std::holds_alternative<IsotropicProfile>(l.lamp.profile->model()))
      cars.push_back(i);
    else
      still.lamps.push_back(l);
  }
  SurfaceBuffers surface;
  std::string surfaceNote = "CPU planes";
  if (gl && gl->render(scene, surface)) surfaceNote = "GL";
  else renderSurfacesCpu(scene, surface);
  out = {{"scene", o.trafficScene}, {"width", w}, {"height", h}, {"surface", surfaceNote},
         {"moving_lamps", cars.size()}, {"lamps", scene.lamps.size()}};
  auto base = trafficFrames(still, surface, {}, MovingLampPath::Map, threads, o);
  if (!base) {
    out["note"] = base.error().message;
    return out;
  }
  out["static"] = base->airlight.toJson();
  out["static"]["evaluated_pixels"] = base->evaluated;
  if (!o.onlyPencil) out["changes"] = changesStage(still, surface, threads, o, *base);
  ThreadPool pool(threads);
  auto reference = AirlightImageEvaluator::build(scene, AirlightMethod::Accurate, {}, threads, FastPathOptions{});
  for (MovingLampPath path : {MovingLampPath::Map, MovingLampPath::Pencil}) {
    if (o.onlyPencil && path == MovingLampPath::Map) continue;
    auto run = trafficFrames(scene, surface, cars, path, threads, o);
    if (!run || !reference) {
      out["note"] = !run ? run.error().message : reference.error().message;
      return out;
    }
    json r = run->airlight.toJson();
    r["evaluated_pixels"] = run->evaluated;
    r["map_nodes"] = run->mapNodes;
    r["spokes"] = run->spokes;
    r["moving_evaluated"] = run->movingEvaluated;
    r["map_ms"] = run->mapMs;
    r["spoke_ms"] = run->spokeMs;
    r["eval_ms"] = run->evalMs;
    r["judge_ms"] = run->judgeMs;
    r["fill_ms"] = run->fillMs;
    r["vs_static"] = base->airlight.median() > 0.0 ? run->airlight.median() / base->airlight.median() : 0.0;
    // The last frame's poses, per ray, on sample pixels above 1 % of its 99.5th percentile.
    const Scene& moved = run->lastScene;
    if (Status st = reference->setLampPoses(moved); !st) {
      out["note"] = st.error().message;
      return out;
    }
    r["vs_per_ray"] = againstPerRay(*reference, moved, surface, run->last, pool, o, r["threshold_cd_m2"]);
    out[std::string(toString(path))] = r;
  }
  out["dense"] = denseTrafficStage(scene, cars, surface, threads, o);
  return out;
}

// Issue 15, dense traffic: the traffic scene with a queue of oncoming cars (low beams) every
// 20 m from station 80 m to 340 m and cars ahead in the ego lane (tail lamps, ECE R7 style) every
// 30 m from 40 m to 340 m, on the default road (road_model.hpp): 26 cars, 54 moving lamps, all
// driving on at 15 m/s. Timed with FastPathOptions::moving_lamp_cutoff_cd_m2 at its default and
// at 0 (every lamp at every pixel), alternated; then both per pixel (--full) at a quarter of the
// size, where the difference is the cutoff's alone (subsampling decides alike): its largest
// value per channel against the cutoff, which bounds it.
// The lamp files are the shipped ones, next to the traffic scene (config/lamps).
Result<Scene> denseTraffic(const Scene& scene, const std::string& sceneFile, std::vector<std::size_t>& cars) {
  Scene dense = scene;
  const road::RoadParams rp;
  const std::filesystem::path lamps = std::filesystem::path(sceneFile).parent_path() / ".." / "lamps";
  auto low = loadProfileFile((lamps / "low_beam.ies").string());
  if (!low) return low.error();
  auto tail = loadProfileFile((lamps / "tail_lamp.ies").string());
  if (!tail) return tail.error();
  auto add = [&](double s, double d, double z, std::shared_ptr<const Profile> profile, const char* name, glm::dvec3 colour) {
    SceneLamp l;
    l.name = name;
    l.lamp.position_m = road::roadPoint(rp, s, d) + Vec3(0.0, 0.0, z);
    // Facing the ego car: against the road's heading (low beams of oncoming cars, tail lamps of
    // cars ahead; the tail lamp's axis is mounted backwards, yaw 180° on its car).
    l.lamp.worldFromLamp = worldFromYawPitchRoll(road::centreLine(rp, s).heading + kPi, 0.0, 0.0);
    l.lamp.profile = std::move(profile);
    l.lamp.color = colour;
    cars.push_back(dense.lamps.size());
    dense.lamps.push_back(std::move(l));
  };
  const double lane = 0.5 * rp.lane_width_m;
  for (double s = 80.0; s <= 340.0; s += 20.0) {  // oncoming lane: d = +lane/2
    add(s, lane - 0.7, 0.65, *low, "queued oncoming left low beam", glm::dvec3(1.0));
    add(s, lane + 0.7, 0.65, *low, "queued oncoming right low beam", glm::dvec3(1.0));
  }
  for (double s = 40.0; s <= 340.0; s += 30.0) {  // ego lane: d = −lane/2; red tail lamps
    add(s, -lane + 0.7, 0.8, *tail, "car ahead left tail", glm::dvec3(1.0, 0.05, 0.02));
    add(s, -lane - 0.7, 0.8, *tail, "car ahead right tail", glm::dvec3(1.0, 0.05, 0.02));
  }
  return dense;
}

json denseTrafficStage(const Scene& scene, const std::vector<std::size_t>& cars0, const SurfaceBuffers& surface,
                       unsigned threads, const BenchOptions& o) {
  json out;
  std::vector<std::size_t> cars = cars0;
  auto made = denseTraffic(scene, o.trafficScene, cars);
  if (!made) {
    out["note"] = made.error().message;
    return out;
  }
  const Scene& dense = *made;
  out["moving_lamps"] = cars.size();
  const double cutoff = FastPathOptions{}.moving_lamp_cutoff_cd_m2;
  out["cutoff_cd_m2"] = cutoff;
  // Alternated, each a drive of o.frames frames: the figures share the machine's state.
  StageStats with, without;
  std::size_t culled = 0, evalWith = 0, evalWithout = 0, spokesWith = 0, spokesWithout = 0;
  double spokeMsWith = 0.0, spokeMsWithout = 0.0;  // the last run's median spoke stage
  for (int rep = 0; rep < 2; ++rep) {
    for (double c : {cutoff, 0.0}) {
      auto run = trafficFrames(dense, surface, cars, MovingLampPath::Pencil, threads, o, c);
      if (!run) {
        out["note"] = run.error().message;
        return out;
      }
      StageStats& into = c > 0.0 ? with : without;
      into.ms.insert(into.ms.end(), run->airlight.ms.begin(), run->airlight.ms.end());
      (c > 0.0 ? evalWith : evalWithout) = run->movingEvaluated;
      (c > 0.0 ? spokesWith : spokesWithout) = run->spokes;
      (c > 0.0 ? spokeMsWith : spokeMsWithout) = run->spokeMs;
      if (c > 0.0) culled = run->culled;
    }
  }
  out["with_cutoff"] = with.toJson();
  out["with_cutoff"]["moving_evaluated"] = evalWith;
  out["with_cutoff"]["spokes"] = spokesWith;
  out["with_cutoff"]["culled"] = culled;
  out["with_cutoff"]["spoke_ms"] = spokeMsWith;
  out["without"] = without.toJson();
  out["without"]["spoke_ms"] = spokeMsWithout;
  out["without"]["moving_evaluated"] = evalWithout;
  out["without"]["spokes"] = spokesWithout;
  out["speedup"] = with.median() > 0.0 ? without.median() / with.median() : 0.0;
  // Per pixel at a quarter of the size: the cutoff's own difference, one frame each.
  Scene small = resized(dense, std::max(1, dense.camera.width / 4), std::max(1, dense.camera.height / 4));
  SurfaceBuffers smallSurface;
  renderSurfacesCpu(small, smallSurface);
  BenchOptions one = o;
  one.frames = 1;
  SubsamplingOptions full;
  full.full = true;
  auto a = trafficFrames(small, smallSurface, cars, MovingLampPath::Pencil, threads, one, cutoff, full);
  auto b = trafficFrames(small, smallSurface, cars, MovingLampPath::Pencil, threads, one, 0.0, full);
  if (!a || !b) {
    out["note"] = !a ? a.error().message : b.error().message;
    return out;
  }
  double maxDiff = 0.0, maxValue = 0.0;
  for (std::size_t k = 0; k < a->last.rgb.size(); ++k) {
    maxDiff = std::max(maxDiff, static_cast<double>(std::abs(a->last.rgb[k] - b->last.rgb[k])));
    maxValue = std::max(maxValue, static_cast<double>(b->last.rgb[k]));
  }
  out["full_check"] = {{"width", small.camera.width}, {"height", small.camera.height}, {"max_diff_cd_m2", maxDiff},
                       {"max_value_cd_m2", maxValue}, {"ms_with", a->airlight.median()}, {"ms_without", b->airlight.median()}};
  // The budget (FastPathOptions::max_moving_lamps, the service's [render] max_moving_lamps): the
  // dimmest lamps by their bound left out beyond kBudget, timed at full size; per pixel at the
  // quarter size against no budget (same cutoff): what it loses, which nothing bounds.
  constexpr int kBudget = 16;
  auto budgeted = trafficFrames(dense, surface, cars, MovingLampPath::Pencil, threads, o, cutoff, {}, kBudget);
  auto cSmall = trafficFrames(small, smallSurface, cars, MovingLampPath::Pencil, threads, one, cutoff, full, kBudget);
  if (!budgeted || !cSmall) {
    out["note"] = !budgeted ? budgeted.error().message : cSmall.error().message;
    return out;
  }
  std::vector<double> lost;  // per pixel: luminance lost ÷ luminance with every lamp
  double lostMax = 0.0;
  for (std::size_t k = 0; k + 2 < a->last.rgb.size(); k += 3) {
    double full3 = 0.0, budget3 = 0.0;
    for (int c = 0; c < 3; ++c) {
      full3 += static_cast<double>(a->last.rgb[k + static_cast<std::size_t>(c)]);
      budget3 += static_cast<double>(cSmall->last.rgb[k + static_cast<std::size_t>(c)]);
    }
    lostMax = std::max(lostMax, (full3 - budget3) / 3.0);
    if (full3 > 0.0) lost.push_back((full3 - budget3) / full3);
  }
  out["budget"] = budgeted->airlight.toJson();
  out["budget"]["max_moving_lamps"] = kBudget;
  out["budget"]["dropped"] = budgeted->dropped;
  out["budget"]["moving_evaluated"] = budgeted->movingEvaluated;
  out["budget"]["spokes"] = budgeted->spokes;
  out["budget"]["lost_p95"] = percentile(lost, 0.95);
  out["budget"]["lost_max"] = lost.empty() ? 0.0 : *std::max_element(lost.begin(), lost.end());
  out["budget"]["lost_max_cd_m2"] = lostMax;
  return out;
}

void printDenseTraffic(const json& d) {
  if (d.is_null()) return;
  if (d.contains("note")) {
    std::printf("  dense traffic: %s\n", d["note"].get<std::string>().c_str());
    return;
  }
  std::printf("dense traffic (the same drive with a queue of 14 oncoming cars every 20 m, 11 cars ahead showing tail "
              "lamps every 30 m, up to 340 m: %zu moving lamps)\n",
              d["moving_lamps"].get<std::size_t>());
  char note[200];
  std::snprintf(note, sizeof note, "  %zu lamps out of the frame, %zu (pixel, lamp) pairs, %zu spokes (%.1f ms)",
                d["with_cutoff"]["culled"].get<std::size_t>(), d["with_cutoff"]["moving_evaluated"].get<std::size_t>(),
                d["with_cutoff"]["spokes"].get<std::size_t>(), d["with_cutoff"]["spoke_ms"].get<double>());
  const std::string name = "cutoff " + std::to_string(d["cutoff_cd_m2"].get<double>()).substr(0, 6) + " cd/m2";
  printStage(name.c_str(), d["with_cutoff"], note);
  std::snprintf(note, sizeof note, "  %zu (pixel, lamp) pairs, %zu spokes (%.1f ms); %.2f x the time with the cutoff",
                d["without"]["moving_evaluated"].get<std::size_t>(), d["without"]["spokes"].get<std::size_t>(),
                d["without"]["spoke_ms"].get<double>(), d["speedup"].get<double>());
  printStage("no cutoff (every lamp, every pixel)", d["without"], note);
  if (d.contains("full_check")) {
    const json& f = d["full_check"];
    std::printf("  %-30s %d x %d per pixel: largest difference %.2e cd/m2 (bound: the cutoff), largest value %.1f cd/m2; "
                "%.0f vs %.0f ms\n",
                "  cutoff vs none", f["width"].get<int>(), f["height"].get<int>(), f["max_diff_cd_m2"].get<double>(),
                f["max_value_cd_m2"].get<double>(), f["ms_with"].get<double>(), f["ms_without"].get<double>());
  }
  if (d.contains("budget")) {
    const json& b = d["budget"];
    std::snprintf(note, sizeof note, "  %zu lamps left out, %zu (pixel, lamp) pairs, %zu spokes",
                  b["dropped"].get<std::size_t>(), b["moving_evaluated"].get<std::size_t>(), b["spokes"].get<std::size_t>());
    const std::string bname = "budget of " + std::to_string(b["max_moving_lamps"].get<int>()) + " lamps";
    printStage(bname.c_str(), b, note);
    std::printf("  %-30s per pixel (quarter size): light lost p95 %.2e, max %.2e of the pixel, largest %.2e cd/m2\n",
                "  budget vs none", b["lost_p95"].get<double>(), b["lost_max"].get<double>(), b["lost_max_cd_m2"].get<double>());
  }
}

void printTraffic(const json& t) {
  if (t.is_null()) return;
  if (t.contains("note")) {
    std::printf("\nmoving lamps (issue 15): %s\n", t["note"].get<std::string>().c_str());
    return;
  }
  std::printf("\nmoving lamps (issue 15): %s at %d x %d (%s surfaces), %zu lamps of which %zu measured lamps move "
              "every frame (15 m/s, 30 Hz)\n",
              t["scene"].get<std::string>().c_str(), t["width"].get<int>(), t["height"].get<int>(),
              t["surface"].get<std::string>().c_str(), t["lamps"].get<std::size_t>(), t["moving_lamps"].get<std::size_t>());
  {
    char note[100];
    std::snprintf(note, sizeof note, "  %zu px evaluated", t["static"]["evaluated_pixels"].get<std::size_t>());
    printStage("static frame (no cars)", t["static"], note);
  }
  for (const char* k : {"map", "pencil"}) {
    if (!t.contains(k)) continue;  // --only-pencil
    const json& r = t[k];
    char note[200];
    std::snprintf(note, sizeof note, "  %zu px evaluated; %.1f x the static frame", r["evaluated_pixels"].get<std::size_t>(),
                  r["vs_static"].get<double>());
    const std::string name = std::string("with the cars, ") + k;
    printStage(name.c_str(), r, note);
    if (std::string(k) == "map")
      std::printf("  %-30s %9.2f ms  (%zu pixels evaluated for the maps)\n", "  of which lamp maps", r["map_ms"].get<double>(),
                  r["map_nodes"].get<std::size_t>());
    else
      std::printf("  %-30s %zu a frame; %zu (pixel, moving lamp) pairs evaluated\n", "  spokes sampled",
                  r["spokes"].get<std::size_t>(), r["moving_evaluated"].get<std::size_t>());
    // Where the frame goes: the spokes' stage (pencil path; wall time), then thread time per
    // stage divided by the threads (AirlightImage::eval_seconds …).
    char spokes[40] = "";
    if (std::string(k) == "pencil") std::snprintf(spokes, sizeof spokes, "spokes %.2f, then ", r["spoke_ms"].get<double>());
    std::printf("  %-30s %sper thread: evaluating %.2f, judging %.2f, filling %.2f (medians)\n", "  of which, ms", spokes,
                r["eval_ms"].get<double>(), r["judge_ms"].get<double>(), r["fill_ms"].get<double>());
    printError(("  " + std::string(k) + " vs per ray").c_str(), r["vs_per_ray"]);
  }
  if (t.contains("dense")) printDenseTraffic(t["dense"]);
  if (!t.contains("changes")) return;  // --only-pencil
  const json& c = t["changes"];
  if (c.contains("note")) {
    std::printf("  changing fog and bending: %s\n", c["note"].get<std::string>().c_str());
    return;
  }
  std::printf("changing fog and bending (the cars removed; visibility 150 -> 50 m over %d frames, a new fog every "
              "frame, the ego lamps bending 1 deg every 4 frames)\n",
              c["frames"].get<int>());
  std::printf("  %-30s %9.1f ms  (a build per fog or bending angle)\n", "ego view tables, one build", c["table_build_ms"].get<double>());
  printStage("steady frame (view tables)", c["steady"], "");
  const json& ch = c["changing"];
  char note[200];
  std::snprintf(note, sizeof note, "  %.1f x the steady frame (median), %.1f x (worst)", ch["vs_steady_median"].get<double>(),
                ch["vs_steady_worst"].get<double>());
  printStage("changing, ego lamps per pixel", ch, note);
  std::snprintf(note, sizeof note, "  %.1f x the steady frame (median)",
                c["rebuilt_each_frame"]["median_ms"].get<double>() / std::max(1e-9, c["steady"]["median_ms"].get<double>()));
  printStage("  the same, new evaluator a frame", c["rebuilt_each_frame"], note);
  std::printf("  %-30s %.0f sampled, %.0f kept a frame (median)\n", "  spokes", ch["spokes_sampled_median"].get<double>(),
              ch["spokes_kept_median"].get<double>());
  printError("  changing vs per ray", ch["vs_per_ray"]);
  const json& l = c["ladder"];
  if (l.contains("note")) {
    std::printf("  fog ladder: %s\n", l["note"].get<std::string>().c_str());
    return;
  }
  std::printf("fog ladder (the same fogs without bending; rungs K_t = %.1f^m /m, built first; each frame reads the "
              "two around its fog)\n",
              l["ratio"].get<double>());
  std::snprintf(note, sizeof note, "  %zu rungs of %.1f MB", l["rungs"].get<std::size_t>(), l["rung_mb"].get<double>());
  printStage("rung build, one at a time", l["rung_build"], note);
  std::snprintf(note, sizeof note, "  %.1f x the steady frame (median), %.1f x (worst); %d read two rungs",
                l["vs_steady_median"].get<double>(), l["vs_steady_worst"].get<double>(), l["frames_blended"].get<int>());
  printStage("changing fog, two rungs", l, note);
  printError("  ladder vs per ray", l["vs_per_ray"]);
  printError("  ladder vs tables at its fog", l["vs_tables_at_fog"]);
  if (!c.contains("bending_ladder")) return;
  const json& b = c["bending_ladder"];
  if (b.contains("note")) {
    std::printf("  bending ladder: %s\n", b["note"].get<std::string>().c_str());
    return;
  }
  std::printf("fog and bending on the ladder (the same fogs, the ego lamps bending %.2f deg further every frame; "
              "rungs every %.0f deg of bending at each fog, built first; each frame reads four, the turned ones through "
              "their rotation)\n",
              b["bend_deg_per_frame"].get<double>(), b["bend_step_deg"].get<double>());
  std::snprintf(note, sizeof note, "  %zu rungs of %.1f MB", b["rungs"].get<std::size_t>(), b["rung_mb"].get<double>());
  printStage("rung build, one at a time", b["rung_build"], note);
  std::snprintf(note, sizeof note, "  %.1f x the steady frame (median), %.1f x (worst); %d read turned rungs",
                b["vs_steady_median"].get<double>(), b["vs_steady_worst"].get<double>(), b["frames_turned"].get<int>());
  printStage("changing fog and bending", b, note);
  printError("  ladder vs per ray", b["vs_per_ray"]);
  printError("  ladder vs tables at its pose", b["vs_tables_at_fog"]);
}

/// Issue 7's additions beyond the paper, each at its own size.
json benchAdditions(const Scene& base, const BenchOptions& o, unsigned threads, GlSurfacePass* gl) {
  json out;
  out["gpu_airlight"] = gpuAirlightStage(base, o, threads, gl);
  out["near_field"] = nearFieldStage(base, o, threads);
  out["traffic"] = trafficStage(o, threads, gl);
  return out;
}

void printAdditions(const json& a) {
  std::printf("\nbeyond the paper (issue 7); glow and glare are in each size's table above\n");
  const json& g = a["gpu_airlight"];
  if (!g["available"].get<bool>()) {
    std::printf("  %-30s %s\n", "GPU airlight", g["note"].get<std::string>().c_str());
  } else {
    std::printf("  GPU airlight at %d x %d (%s; llvmpipe runs it on this CPU), %d pieces per measured lamp:\n",
                g["width"].get<int>(), g["height"].get<int>(), g["note"].get<std::string>().c_str(),
                g["pieces"].get<int>());
    printStage("  surface pass alone", g["surface_only"]);
    printStage("  surface + GPU airlight", g["surface_and_airlight"]);
    printStage("    of which airlight (GPU time)", g["airlight_gpu_time"]);
    printStage("  CPU accurate, full", g["cpu_accurate_full"]);
    printStage("  CPU accurate, subsampled", g["cpu_accurate_subsampled"]);
    printError("  GPU vs CPU full", g["vs_cpu_full"]);
    std::printf("  %-30s %.6f\n", "  GPU / CPU, sum over pixels", g["sum_ratio"].get<double>());
  }
  const json& n = a["near_field"];
  if (n.contains("note")) {
    std::printf("  %-30s %s\n", "near-field lamps", n["note"].get<std::string>().c_str());
  } else if (!n.is_null()) {
    std::printf("  near-field lamps at %d x %d: the %d vehicle lamps with a 0.20 x 0.10 m face, %d x %d points "
                "(%zu point lamps in all):\n",
                n["width"].get<int>(), n["height"].get<int>(), n["vehicle_lamps"].get<int>(),
                n["samples_per_axis"].get<int>(), n["samples_per_axis"].get<int>(), n["point_lamps"].get<std::size_t>());
    for (const char* k : {"point", "aperture"}) {
      const json& c = n[k];
      std::printf("  %-30s first frame %.0f ms (view tables %.0f ms)\n", k, c["first_frame_ms"].get<double>(),
                  c["view_tables_ms"].get<double>());
      printStage("    subsampled", c["subsampled"]);
      printStage("    full", c["full"]);
    }
    printError("  aperture vs point, full", n["aperture_vs_point_full"]);
    std::printf("  %-30s %.6f\n", "  aperture / point, sum", n["sum_ratio"].get<double>());
  }
  printTraffic(a["traffic"]);
}

/// Writes `root` to `path` (nothing when empty) and says so; false, with the reason on stderr,
/// when it cannot.
bool writeJson(const json& root, const std::string& path) {
  if (path.empty()) return true;
  std::ofstream out(path);
  out << root.dump(2) << '\n';
  if (!out) {
    std::fprintf(stderr, "fogbeam bench: %s: cannot write\n", path.c_str());
    return false;
  }
  std::printf("\nwrote %s\n", path.c_str());
  return true;
}

}  // namespace

int runBench(const BenchOptions& options) {
  BenchOptions o = options;  // --quick replaces some of them
  if (o.quick) {
    o.sizes = {"320x180"};
    o.frames = 2;
    o.stageBudgetSeconds = 3.0;
    o.viewTableStepDeg = 0.5;
    o.gpuSize = "48x27";
    o.apertureSize = "160x90";
    o.trafficSize = "160x90";
  }
  std::vector<std::pair<int, int>> sizes;
  for (const std::string& s : o.sizes) {
    int w = 0, h = 0;
    if (!parseSize(s, w, h)) {
      std::fprintf(stderr, "fogbeam bench: --sizes: expected WIDTHxHEIGHT (e.g. 1280x720), got '%s'\n", s.c_str());
      return 2;
    }
    sizes.emplace_back(w, h);
  }
  auto scene = loadScene(o.scene);
  if (!scene) {
    std::fprintf(stderr, "fogbeam bench: %s\n", scene.error().message.c_str());
    return 2;
  }
  const unsigned threads = o.threads == 0 ? std::max(1u, std::thread::hardware_concurrency()) : o.threads;
  const std::string cpu = cpuModel();
  std::printf("fogbeam bench: %s\n", o.scene.c_str());
  std::printf("  machine   %s, %u logical cores; %u threads\n", cpu.c_str(), std::thread::hardware_concurrency(), threads);
  std::printf("  compiler  GCC %s; build type %s; flags '%s'\n", __VERSION__, FOGBEAM_BUILD_TYPE, compileFlags().c_str());
  std::unique_ptr<GlSurfacePass> gl;
  if (auto created = GlSurfacePass::create()) gl = std::move(created).value();
  else std::printf("  surface   GL unavailable (%s); CPU planes only\n", created.error().message.c_str());
  const std::string road = scene->gltf_path ? "glTF " + *scene->gltf_path + (gl ? "" : " (not drawn without GL)") : "planes only";
  std::printf("  scene     %zu lamps, %zu planes, K_t %.4f /m, %s; geometry: %s\n", scene->lamps.size(),
              scene->planes.size(), scene->fog.extinction_per_m, describe(scene->fog.phase).c_str(), road.c_str());
  if (gl) std::printf("  surface   GL: %s (its buffers feed the airlight stages); CPU planes timed too\n", gl->description().c_str());

  if (o.onlyTraffic) {
    json root;
    root["traffic"] = trafficStage(o, threads, gl.get());
    printTraffic(root["traffic"]);
    return writeJson(root, o.jsonPath) ? 0 : 1;
  }
  const auto t0 = Clock::now();
  auto ref = AirlightImageEvaluator::build(*scene, AirlightMethod::Reference, {}, threads);
  auto seed = AirlightImageEvaluator::build(*scene, AirlightMethod::Seed, {}, threads);
  const auto tAcc = Clock::now();
  FastPathOptions fast;
  fast.view_table_step_deg = o.viewTableStepDeg;
  auto acc = AirlightImageEvaluator::build(*scene, AirlightMethod::Accurate, {}, threads, fast);
  const double accBuildMs = msSince(tAcc), buildMs = msSince(t0);
  for (const auto* e : {&ref, &seed, &acc})
    if (!*e) {
      std::fprintf(stderr, "fogbeam bench: %s\n", e->error().message.c_str());
      return 2;
    }
  std::printf("  tables    %.0f ms for all three methods (accurate %.0f ms)\n", buildMs, accBuildMs);
  Evaluators ev{std::move(ref).value(), std::move(seed).value(), std::move(acc).value()};
  std::printf("  airlight  %s\n", ev.accurate.describe().c_str());
  ThreadPool pool(threads);

  json root;
  root["machine"] = {{"cpu", cpu}, {"logical_cores", std::thread::hardware_concurrency()}};
  root["compiler"] = std::string("GCC ") + __VERSION__;
  root["build_type"] = FOGBEAM_BUILD_TYPE;
  root["flags"] = compileFlags();
  root["threads"] = threads;
  root["scene"] = {{"file", o.scene},
                   {"lamps", scene->lamps.size()},
                   {"planes", scene->planes.size()},
                   {"extinction_per_m", scene->fog.extinction_per_m},
                   {"phase", describe(scene->fog.phase)},
                   {"geometry", road}};
  root["gl"] = {{"available", gl != nullptr}, {"note", gl ? gl->description() : std::string("no EGL")}};
  root["frames"] = o.frames;
  root["table_build_ms"] = {{"all", buildMs}, {"accurate", accBuildMs}};
  root["airlight_paths"] = ev.accurate.describe();
  root["sizes"] = json::array();
  for (const auto& [w, h] : sizes) {
    json r = benchSize(*scene, w, h, o, ev, pool, gl.get());
    printSize(r);
    std::fflush(stdout);
    root["sizes"].push_back(std::move(r));
  }
  root["additions"] = benchAdditions(*scene, o, threads, gl.get());
  printAdditions(root["additions"]);
  return writeJson(root, o.jsonPath) ? 0 : 1;
}

}  // namespace fogbeam::cli
