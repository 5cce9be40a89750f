// `fogbeam render`: one frame of a scene file to EXR (and PNG).
#include "commands.hpp"
#include "exr_writer.hpp"
#include "png_writer.hpp"

#include <fogbeam/gl/surface_pass.hpp>
#include <fogbeam/render/airlight_image.hpp>
#include <fogbeam/render/frame.hpp>
#include <fogbeam/render/lamp_effects.hpp>
#include <fogbeam/render/surface.hpp>
#include <fogbeam/scene/scene.hpp>

#include <chrono>
#include <cstdio>
#include <map>
#include <memory>
#include <string>

namespace fogbeam::cli {

namespace {

struct RenderOptions {
  std::string scene, out, png, method = "accurate", surface = "auto";
  bool full = false;
  double exposure = 0.0;
  int coarseStep = SubsamplingOptions{}.coarse_step;
  double tolerance = SubsamplingOptions{}.rel_tolerance;
  std::string movingLamps = "pencil";
  unsigned threads = 0;
  // Issue 7's additions; empty: as the scene's [glow], [glare], [render] say.
  std::string glow, glare, airlightDevice;
  bool methodGiven = false;
};

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
    if (glow && l.apsf_terms > 0)
      std::printf("  %10.4g %6.2f %5.2f %10.4g", l.glow_source_cd, l.glow_scale, l.glow_share, l.glow_peak_cd_m2);
    else if (glow)
      std::printf("  %-36s", "  (no glow: K_t R < 1.1)");
    std::printf("  %s\n", l.name.c_str());
  }
  if (order.size() > kMaxRows) std::printf("    ... %zu more\n", order.size() - kMaxRows);
}

/// "on" / "off" / "" (scene default) → the flag.
bool switchOf(const std::string& v, bool sceneDefault) { return v.empty() ? sceneDefault : v == "on"; }

int run(const RenderOptions& o) {
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
  if (o.surface != "cpu") {
    auto created = GlSurfacePass::create();
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
    renderSurfacesCpu(*scene, surface);
  }
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
    fast.moving_lamps = o.movingLamps == "per-ray" ? MovingLampPath::PerRay : MovingLampPath::Pencil;
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
  if (!o.png.empty()) {
    const auto bytes = toneMapSrgb8(layers.composite, o.exposure);
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
    std::printf("  airlight view tables        %8.1f ms  (vehicle-mounted lamps; reused while the rig and fog stay)\n",
                1e3 * airlight.table_seconds);
    std::printf("  airlight                    %8.1f ms  (%zu of %zu pixels evaluated, %.1f %%%s)\n",
                1e3 * (airlight.seconds - airlight.table_seconds), airlight.evaluated, n,
                100.0 * static_cast<double>(airlight.evaluated) / static_cast<double>(n), o.full ? ", --full" : "");
  }
  std::printf("  airlight paths              %s\n", paths.c_str());
  if (anyEffect) {
    std::printf("  glow                        %8.1f ms  (%s)\n", 1e3 * effects.glow_seconds,
                fx.glow.enabled ? "Narasimhan-Nayar APSF, energy-matched to single scattering" : "off");
    std::printf("  glare                       %8.1f ms  (%s)\n", 1e3 * effects.glare_seconds,
                fx.glare.enabled ? "CIE 146 veiling luminance" : "off");
    printEffects(effects, fx.glow.enabled, fx.glare.enabled);
  }
  std::printf("  wrote %s%s%s (PNG exposure %+.1f EV)\n", o.out.c_str(), o.png.empty() ? "" : " and ", o.png.c_str(),
              o.exposure);
  return 0;
}

}  // namespace

void addRenderCommand(CLI::App& app, int& exitCode) {
  auto o = std::make_shared<RenderOptions>();
  auto* sub = app.add_subcommand("render", "Render one frame of a scene file (TOML, docs/scene.md) to OpenEXR and PNG");
  sub->add_option("--scene", o->scene, "scene file (TOML); lengths in m, angles in deg, intensities in cd")
      ->required()
      ->check(CLI::ExistingFile);
  sub->add_option("--out", o->out,
                  "OpenEXR file, 32-bit float linear layers: R,G,B composite; airlight.R/G/B; surface.R/G/B; "
                  "overlay.R/G/B (A = airlight + glow + glare + ambient in-scatter); transmittance.Y; distance.Z (m, inf = "
                  "sky); glow.R/G/B and glare.R/G/B when on; luminance in cd/m2")
      ->required();
  sub->add_option("--png", o->png, "also write the composite tone-mapped to 8-bit sRGB PNG");
  sub->add_option("--method", o->method, "airlight method: seed | accurate | reference (default accurate)")
      ->each([o](const std::string&) { o->methodGiven = true; });
  sub->add_option("--glow", o->glow, "glow around lamps (multiple scattering): on | off (default: the scene's [glow])")
      ->check(CLI::IsMember({"on", "off"}));
  sub->add_option("--glare", o->glare,
                  "driver's disability glare (CIE 146 veiling luminance): on | off (default: the scene's [glare])")
      ->check(CLI::IsMember({"on", "off"}));
  sub->add_option("--airlight", o->airlightDevice,
                  "where the airlight is computed: cpu (tables, SIMD, subsampling) | gpu (accurate method in GLSL in the "
                  "surface pass) (default: the scene's [render] airlight, else cpu)")
      ->check(CLI::IsMember({"cpu", "gpu"}));
  sub->add_flag("--full", o->full, "evaluate every pixel (no adaptive subsampling)");
  sub->add_option("--moving-lamps", o->movingLamps,
                  "measured and spot lamps fixed in the world (not mount = \"vehicle\"): pencil (default) | per-ray")
      ->check(CLI::IsMember({"pencil", "per-ray"}));
  sub->add_option("--exposure", o->exposure,
                  "PNG exposure in EV: x = L * 2^EV / (1 cd/m2), Reinhard x/(1+x), sRGB (default 0: 1 cd/m2 = mid-grey)");
  sub->add_option("--coarse-step", o->coarseStep,
                  "subsampling: initial block size in pixels; 0 (default): 16 where 16 px span at most 0.8 deg, else 8")
      ->check(CLI::Range(0, 256));
  sub->add_option("--tolerance", o->tolerance,
                  "subsampling: relative error allowed between a block's centre and its bilinear prediction (default 0.005)")
      ->check(CLI::Range(0.0, 1.0));
  sub->add_option("--threads", o->threads, "worker threads (default: all cores)");
  sub->add_option("--surface", o->surface,
                  "surface layer: auto (GL through EGL if available, else CPU), gl (fail without EGL), cpu (planes only)")
      ->check(CLI::IsMember({"auto", "gl", "cpu"}));
  sub->callback([o, &exitCode] { exitCode = run(*o); });
}

}  // namespace fogbeam::cli
