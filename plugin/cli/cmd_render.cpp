// `fogbeam render`: one frame of a scene file to EXR (and PNG).
#include "cmd_render.hpp"
#include "exr_writer.hpp"
#include "png_writer.hpp"

#include <fogbeam/gl/surface_pass.hpp>
#include <fogbeam/render/airlight_image.hpp>
#include <fogbeam/render/exposure.hpp>
#include <fogbeam/render/frame.hpp>
#include <fogbeam/render/lamp_effects.hpp>
#include <fogbeam/render/surface.hpp>
#include <fogbeam/render/surface_shading.hpp>
#include <fogbeam/util/thread_pool.hpp>
#include <fogbeam/scene/scene.hpp>

#include <chrono>
#include <cstdio>
#include <map>
#include <memory>
#include <string>

namespace fogbeam::cli {

namespace {

/// The lamp name without the " [k/N]" of an aperture's point lamps (scene.hpp, expandSceneLamp).
std::string baseName(const std::string& name) {
  const auto open = name.rfind(" [");
  if (open == std::string::npos || name.back() != ']' || name.find('/', open) == std::string::npos) return name;
  return name.substr(0, open);
}

/// Per-lamp glow and glare figures, the point lamps of one aperture summed (illuminance, glow
/// peak) or taken from the first (distance, optical distance, λ, share).
void printEffects(const LampEffectsReport& r, bool glow, bool glare) {
  struct Row {
    LampEffectsReport::Lamp sum;
    int points = 0;
  };
  std::vector<std::string> order;
  std::map<std::string, Row> rows;
  for (const auto& l : r.lamps) {
    if (!l.visible) continue;
    const std::string name = baseName(l.name);
    auto [it, fresh] = rows.try_emplace(name);
    if (fresh) {
      order.push_back(name);
      it->second.sum = l;
      it->second.sum.name = name;
    } else {
      it->second.sum.eye_illuminance_lx += l.eye_illuminance_lx;
      it->second.sum.glow_peak_cd_m2 += l.glow_peak_cd_m2;
      it->second.sum.intensity_cd += l.intensity_cd;  // luminous: each point's share
      it->second.sum.glow_source_cd += l.glow_source_cd;
    }
    ++it->second.points;
  }
  std::printf("  lamps in view: %zu (of %zu point lamps); illuminance at the eye %.4g lx\n", order.size(),
              r.lamps.size(), r.eye_illuminance_lx);
  if (glare)
    std::printf("  glare (CIE 146): veiling luminance at the image centre %.4g cd/m2\n", r.veiling_luminance_cd_m2);
  constexpr std::size_t kMaxRows = 16;
  if (!order.empty())
    std::printf("    %7s %6s %10s %10s%s  %s\n", "R m", "K_t R", "I cd", "E lx",
                glow ? "   glow: src cd lambda share  peak cd/m2" : "", "lamp");
  for (std::size_t k = 0; k < order.size() && k < kMaxRows; ++k) {
    const auto& l = rows[order[k]].sum;
    std::printf("    %7.1f %6.2f %10.4g %10.4g", l.distance_m, l.optical_distance, l.intensity_cd, l.eye_illuminance_lx);
    if (glow && l.glow_from_table)  // the multiple-scattering tables: no energy match (λ column "table")
      std::printf("  %10.4g %6s %5.2f %10.4g", l.glow_source_cd, "table", l.glow_share, l.glow_peak_cd_m2);
    else if (glow && l.apsf_terms > 0)
      std::printf("  %10.4g %6.2f %5.2f %10.4g", l.glow_source_cd, l.glow_scale, l.glow_share, l.glow_peak_cd_m2);
    else if (glow)
      std::printf("  %-36s", "  (no glow: K_t R < 1.1)");
    std::printf("  %s\n", l.name.c_str());
  }
  if (order.size() > kMaxRows) std::printf("    ... %zu more\n", order.size() - kMaxRows);
}

/// "on" / "off" / "" (scene default) → the flag.
bool switchOf(const std::string& v, bool sceneDefault) { return v.empty() ? sceneDefault : v == "on"; }

}  // namespace

int runRender(const RenderOptions& o) {
  auto method = parseAirlightMethod(o.method);
  if (!method) {
    std::fprintf(stderr, "fogbeam render: %s\n", method.error().message.c_str());
    return 2;
  }
  auto scene = loadScene(o.scene);
  if (!scene) {
    std::fprintf(stderr, "fogbeam render: %s\n", scene.error().message.c_str());
    return 2;
  }
  SceneEffects fx = scene->effects;
  fx.glow.enabled = switchOf(o.glow, fx.glow.enabled);
  fx.glare.enabled = switchOf(o.glare, fx.glare.enabled);
  fx.glow.surfaces = switchOf(o.fogLight, fx.glow.surfaces);
  scene->effects.glow = fx.glow;  // the surface pass reads the fog light's switch from the scene
  if (!o.airlightDevice.empty()) fx.render.airlight = o.airlightDevice == "gpu" ? AirlightDevice::Gpu : AirlightDevice::Cpu;
  const bool gpuAirlight = fx.render.airlight == AirlightDevice::Gpu;
  if (gpuAirlight && *method != AirlightMethod::Accurate) {
    if (o.methodGiven) {
      std::fprintf(stderr, "fogbeam render: the GPU airlight path computes the accurate method only (--method %s "
                           "asked for); use --airlight cpu for the others\n", o.method.c_str());
      return 2;
    }
  }
  if (gpuAirlight && o.surface == "cpu") {
    std::fprintf(stderr, "fogbeam render: airlight = \"gpu\" runs in the GL surface pass: not with --surface cpu\n");
    return 2;
  }
  // Surface layer: the GL pass (EGL, headless) when available, else the CPU planes renderer.
  using Clock = std::chrono::steady_clock;
  SurfaceBuffers surface;
  std::string surfaceName = "CPU, planes only";
  double surfaceMs = 0.0;
  std::unique_ptr<GlSurfacePass> gl;
  // The view tables' cache directory also keeps the fog light's table and annulus maps.
  const std::string tableCache = tableCacheDirFor(o.tableCache);
  if (o.surface != "cpu") {
    GlOptions glOptions;
    glOptions.table_cache_dir = tableCache;
    auto created = GlSurfacePass::create(glOptions);
    if (created) {
      gl = std::move(created).value();
    } else if (o.surface == "gl" || gpuAirlight) {
      std::fprintf(stderr, "fogbeam render: %s\n", created.error().message.c_str());
      return 1;
    } else {
      std::fprintf(stderr, "fogbeam render: note: no GL surface pass (%s); using the CPU planes renderer\n",
                   created.error().message.c_str());
    }
  }
  AirlightImage airlight;
  if (gpuAirlight) {
    GpuAirlightOptions gpu;
    gpu.pieces = fx.render.gpu_pieces;
    if (Status s = gl->setAirlight(gpu); !s) {
      std::fprintf(stderr, "fogbeam render: %s\n", s.error().message.c_str());
      return 2;
    }
  }
  std::string cacheError;  // a fog-light table or map the surface pass could not store
  auto t0 = Clock::now();
  if (gl) {
    const Status s = gpuAirlight ? gl->render(*scene, surface, airlight.rgb) : gl->render(*scene, surface);
    if (!s) {
      std::fprintf(stderr, "fogbeam render: %s\n", s.error().message.c_str());
      return 1;
    }
    surfaceName = "GL: " + gl->description();
  } else {
    if (scene->gltf_path)
      std::fprintf(stderr, "fogbeam render: note: the CPU surface pass draws planes only; glTF '%s' is not drawn\n",
                   scene->gltf_path->c_str());
    SurfaceShader shader;  // planes and the bonnet, SIMD (renderSurfacesCpu is its double-precision oracle)
    shader.setTableCacheDir(tableCache);
    kernels::ShadeFrame frame;
    ThreadPool pool(o.threads);
    shader.render(*scene, frame, surface, &pool);
    cacheError = shader.takeTableCacheError();
  }
  if (gl) cacheError = gl->takeTableCacheError();
  // Not fatal: the image is the same, the next run builds the table or map again.
  if (!cacheError.empty())
    std::fprintf(stderr, "fogbeam render: fog-light table or map not cached: %s\n", cacheError.c_str());
  surfaceMs = std::chrono::duration<double, std::milli>(Clock::now() - t0).count();

  const std::size_t pixels = static_cast<std::size_t>(surface.width) * static_cast<std::size_t>(surface.height);
  double buildMs = 0.0;
  std::string paths;
  if (gpuAirlight) {
    airlight.width = surface.width;
    airlight.height = surface.height;
    airlight.evaluated = pixels;
    airlight.seconds = 1e-3 * gl->stats().airlight_ms;
    paths = "GPU: accurate method in GLSL, " + std::to_string(fx.render.gpu_pieces) + " pieces per ray for measured lamps";
  } else {
    t0 = Clock::now();
    FastPathOptions fast;
    fast.moving_lamps = parseMovingLampPath(o.movingLamps).value_or(MovingLampPath::Pencil);
    fast.table_cache_dir = tableCache;
    auto evaluator = AirlightImageEvaluator::build(*scene, *method, {}, o.threads, fast);
    if (!evaluator) {
      std::fprintf(stderr, "fogbeam render: %s\n", evaluator.error().message.c_str());
      return 2;
    }
    buildMs = std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
    SubsamplingOptions sub;
    sub.full = o.full;
    sub.coarse_step = o.coarseStep;
    sub.rel_tolerance = o.tolerance;
    evaluator->evaluate(*scene, surface, sub, airlight);
    paths = evaluator->describe();
  }

  // Glow and glare (issue 7): layers in front of the surfaces, composited with the airlight.
  std::vector<float> glowLayer, glareLayer;
  LampEffectsReport effects;
  const bool anyEffect = fx.glow.enabled || fx.glare.enabled;
  if (anyEffect) {
    auto lampEffects = LampEffects::build(*scene, fx.glow, fx.glare, std::make_shared<ThreadPool>(o.threads));
    if (!lampEffects) {
      std::fprintf(stderr, "fogbeam render: %s\n", lampEffects.error().message.c_str());
      return 2;
    }
    lampEffects->evaluate(*scene, surface, glowLayer, glareLayer, effects);
  }

  FrameLayers layers;
  compositeFrame(scene->fog, surface, airlight, layers, EffectLayers{&glowLayer, &glareLayer});
  if (Status s = exr::writeFrameLayers(layers, o.out); !s) {
    std::fprintf(stderr, "fogbeam render: %s\n", s.error().message.c_str());
    return 1;
  }
  // The PNG's exposure: --exposure EV, or the frame's automatic night exposure (exposure.hpp).
  const double exposureEv = o.exposure ? *o.exposure : autoExposureEv(layers.composite, layers.width, layers.height);
  if (!o.png.empty()) {
    const auto bytes = toneMapSrgb8(layers.composite, exposureEv);
    png::RgbImage img(layers.width, layers.height);
    for (int j = 0; j < layers.height; ++j)
      for (int i = 0; i < layers.width; ++i) {
        const std::size_t k = 3 * (static_cast<std::size_t>(j) * static_cast<std::size_t>(layers.width) + static_cast<std::size_t>(i));
        img.set(i, j, {bytes[k], bytes[k + 1], bytes[k + 2]});
      }
    if (Status s = png::writePng(img, o.png); !s) {
      std::fprintf(stderr, "fogbeam render: %s\n", s.error().message.c_str());
      return 1;
    }
  }
  const std::size_t n = pixels;
  std::printf("fogbeam render: %s, %dx%d, %zu lamps, method %s, airlight on the %s\n", o.scene.c_str(), layers.width,
              layers.height, scene->lamps.size(), gpuAirlight ? "accurate" : o.method.c_str(),
              gpuAirlight ? "GPU" : "CPU");
  if (gpuAirlight) {
    std::printf("  surface pass + airlight     %8.1f ms  (%s)\n", surfaceMs, surfaceName.c_str());
    std::printf("  airlight (GPU time)         %8.1f ms  (every pixel)\n", 1e3 * airlight.seconds);
  } else {
    std::printf("  surface pass                %8.1f ms  (%s)\n", surfaceMs, surfaceName.c_str());
    std::printf("  airlight tables             %8.1f ms\n", buildMs);
    std::printf("  airlight view tables        %8.1f ms  (vehicle-mounted lamps; %s)\n", 1e3 * airlight.table_seconds,
                airlight.view_tables_loaded > 0 ? "loaded from the table cache"
                                                : "built; reused while the rig and fog stay");
    if (!airlight.table_cache_error.empty())
      std::fprintf(stderr, "fogbeam render: table cache: %s\n", airlight.table_cache_error.c_str());
    std::printf("  airlight                    %8.1f ms  (%zu of %zu pixels evaluated, %.1f %%%s)\n",
                1e3 * (airlight.seconds - airlight.table_seconds), airlight.evaluated, n,
                100.0 * static_cast<double>(airlight.evaluated) / static_cast<double>(n), o.full ? ", --full" : "");
  }
  std::printf("  airlight paths              %s\n", paths.c_str());
  if (anyEffect) {
    // Which model drew the glow: the tables (the default) unless the fog's phase function has
    // none, then the APSF, as LampEffects chooses (lamp_effects.hpp).
    bool fromTable = false;
    for (const auto& l : effects.lamps) fromTable = fromTable || l.glow_from_table;
    const char* glowModel = !fx.glow.enabled ? "off"
                            : fromTable      ? "multiple-scattering tables, orders >= 2 (path-traced)"
                            : fx.glow.model == GlowModel::Table
                                ? "no table for this phase function: Narasimhan-Nayar APSF, energy-matched"
                                : "Narasimhan-Nayar APSF, energy-matched to single scattering";
    std::printf("  glow                        %8.1f ms  (%s)\n", 1e3 * effects.glow_seconds, glowModel);
    std::printf("  glare                       %8.1f ms  (%s)\n", 1e3 * effects.glare_seconds,
                fx.glare.enabled ? "CIE 146 veiling luminance" : "off");
    printEffects(effects, fx.glow.enabled, fx.glare.enabled);
  }
  std::printf("  wrote %s%s%s (PNG exposure %+.2f EV%s)\n", o.out.c_str(), o.png.empty() ? "" : " and ", o.png.c_str(),
              exposureEv, o.exposure ? "" : ", auto");
  return 0;
}

}  // namespace fogbeam::cli
