// `fogbeam render`: one frame of a scene file to EXR (and PNG).
#include "commands.hpp"
#include "exr_writer.hpp"
#include "png_writer.hpp"

#include <fogbeam/gl/surface_pass.hpp>
#include <fogbeam/render/airlight_image.hpp>
#include <fogbeam/render/frame.hpp>
#include <fogbeam/render/surface.hpp>
#include <fogbeam/scene/scene.hpp>

#include <chrono>
#include <cstdio>
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
};

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
    } else if (o.surface == "gl") {
      std::fprintf(stderr, "fogbeam render: %s\n", created.error().message.c_str());
      return 1;
    } else {
      std::fprintf(stderr, "fogbeam render: note: no GL surface pass (%s); using the CPU planes renderer\n",
                   created.error().message.c_str());
    }
  }
  auto t0 = Clock::now();
  if (gl) {
    if (Status s = gl->render(*scene, surface); !s) {
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

  t0 = Clock::now();
  FastPathOptions fast;
  fast.moving_lamps = o.movingLamps == "per-ray" ? MovingLampPath::PerRay : MovingLampPath::Pencil;
  auto evaluator = AirlightImageEvaluator::build(*scene, *method, {}, o.threads, fast);
  if (!evaluator) {
    std::fprintf(stderr, "fogbeam render: %s\n", evaluator.error().message.c_str());
    return 2;
  }
  const double buildMs = std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
  SubsamplingOptions sub;
  sub.full = o.full;
  sub.coarse_step = o.coarseStep;
  sub.rel_tolerance = o.tolerance;
  AirlightImage airlight;
  evaluator->evaluate(*scene, surface, sub, airlight);

  FrameLayers layers;
  compositeFrame(scene->fog, surface, airlight, layers);
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
  const std::size_t n = static_cast<std::size_t>(layers.width) * static_cast<std::size_t>(layers.height);
  std::printf("fogbeam render: %s, %dx%d, %zu lamps, method %s\n", o.scene.c_str(), layers.width, layers.height,
              scene->lamps.size(), o.method.c_str());
  std::printf("  surface pass                %8.1f ms  (%s)\n", surfaceMs, surfaceName.c_str());
  std::printf("  airlight tables             %8.1f ms\n", buildMs);
  std::printf("  airlight view tables        %8.1f ms  (vehicle-mounted lamps; reused while the rig and fog stay)\n",
              1e3 * airlight.table_seconds);
  std::printf("  airlight                    %8.1f ms  (%zu of %zu pixels evaluated, %.1f %%%s)\n",
              1e3 * (airlight.seconds - airlight.table_seconds), airlight.evaluated, n,
              100.0 * static_cast<double>(airlight.evaluated) / static_cast<double>(n), o.full ? ", --full" : "");
  std::printf("  airlight paths              %s\n", evaluator->describe().c_str());
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
                  "overlay.R/G/B (A = airlight + ambient in-scatter); transmittance.Y; distance.Z (m, inf = sky); "
                  "luminance in cd/m2")
      ->required();
  sub->add_option("--png", o->png, "also write the composite tone-mapped to 8-bit sRGB PNG");
  sub->add_option("--method", o->method, "airlight method: seed | accurate | reference (default accurate)");
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
