// The GLSL airlight pass against the CPU SIMD path on the same frame and tables: both evaluate
// the same table formula, so they agree to float rounding (and the GPU's transcendental
// functions) everywhere except in the discs where the CPU goes per ray.
// Skips when no EGL/OpenGL is available, like the surface-pass tests (FOGBEAM_REQUIRE_GL=1
// turns that into a failure).
#include <fogbeam/gl/airlight_pass.hpp>
#include <fogbeam/physics/photometry_io.hpp>
#include <fogbeam/render/airlight_image.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

namespace fogbeam {
namespace {

bool environmentFailure(const std::string& why) {
  return why.rfind("no EGL available", 0) == 0 || why.rfind("could not create an OpenGL", 0) == 0 ||
         why.rfind("EGL platform", 0) == 0 || why.rfind("OpenGL 4.3 or later", 0) == 0;
}

Scene benchLike(int w, int h) {
  Scene s;
  s.fog.extinction_per_m = extinctionFromVisibility(100.0);
  s.fog.albedo = 1.0;
  s.fog.phase = makeHenyeyGreenstein(0.85).value();
  s.camera.position_m = {0.0, 0.37, 1.2};
  s.camera.width = w;
  s.camera.height = h;
  auto low = loadProfileFile(std::string(FOGBEAM_CONFIG_DIR) + "/lamps/low_beam.ies");
  EXPECT_TRUE(low.has_value());
  for (double y : {0.7, -0.7}) {
    SceneLamp sl;
    sl.name = y > 0 ? "left" : "right";
    sl.lamp.position_m = {2.2, y, 0.65};
    sl.lamp.profile = *low;
    sl.mount = LampMount::Vehicle;
    s.lamps.push_back(sl);
  }
  for (double x : {15.0, 45.0}) {
    SceneLamp sl;
    sl.name = "street";
    sl.lamp.position_m = {x, -2.75, 8.0};
    sl.lamp.profile = makeProfile(IsotropicProfile{4000.0}).value();
    sl.lamp.color = {1.0, 0.85, 0.6};
    s.lamps.push_back(sl);
  }
  s.planes.push_back(Plane{{0, 0, 0}, {0, 0, 1}, 0.15});
  return s;
}

// Renders `scene` with the GL pass and the CPU kernels (full evaluation) and compares them
// outside the per-ray discs.
void expectGlMatchesCpu(const Scene& scene) {
  auto gl = GlAirlightPass::create();
  if (!gl) {
    const char* require = std::getenv("FOGBEAM_REQUIRE_GL");
    if (environmentFailure(gl.error().message) && !(require && std::string(require) == "1"))
      GTEST_SKIP() << "no usable EGL/OpenGL: " << gl.error().message;
    FAIL() << gl.error().message;
  }
  const int w = scene.camera.width, h = scene.camera.height;
  SurfaceBuffers surf;
  renderSurfacesCpu(scene, surf);
  FastPathOptions fast;
  fast.view_table_step_deg = 0.5;  // a small table: this test checks agreement, not accuracy
  auto ev = AirlightImageEvaluator::build(scene, AirlightMethod::Accurate, {}, 2, fast);
  ASSERT_TRUE(ev.has_value());
  AirlightImage cpu;
  ev->evaluate(scene, surf, SubsamplingOptions{.full = true}, cpu);
  const auto view = ev->fastPathView();
  ASSERT_TRUE(view.complete);
  ASSERT_TRUE(view.viewTables && !view.viewTables->empty());
  std::vector<float> rgb;
  const Status st = (*gl)->render(scene.camera, view, surf, rgb);
  ASSERT_TRUE(st) << st.error().message;
  ASSERT_EQ(rgb.size(), cpu.rgb.size());
  const double f = scene.camera.focalLengthPixels();
  const Vec2 c = scene.camera.principalPoint();
  std::size_t compared = 0, skipped = 0, bad = 0;
  double maxRel = 0.0;
  for (int j = 0; j < h; ++j)
    for (int i = 0; i < w; ++i) {
      const double a = (c.x - (i + 0.5)) / f, b = (c.y - (j + 0.5)) / f;
      bool guarded = false;
      for (const auto& g : view.guards) guarded |= (a - g[0]) * (a - g[0]) + (b - g[1]) * (b - g[1]) <= g[2];
      if (guarded) {
        ++skipped;
        continue;
      }
      const std::size_t k = 3 * (static_cast<std::size_t>(j) * static_cast<std::size_t>(w) + static_cast<std::size_t>(i));
      for (int ch = 0; ch < 3; ++ch) {
        const double x = static_cast<double>(cpu.rgb[k + static_cast<std::size_t>(ch)]);
        const double y = static_cast<double>(rgb[k + static_cast<std::size_t>(ch)]);
        const double rel = std::abs(x - y) / std::max(std::abs(x), 1e-4);
        maxRel = std::max(maxRel, rel);
        if (rel > 1e-3) {
          if (bad < 5) ADD_FAILURE() << "pixel " << i << "," << j << " channel " << ch << ": CPU " << x << " GL " << y;
          ++bad;
        }
      }
      ++compared;
    }
  std::printf("  GL vs CPU: %zu pixels compared, %zu in per-ray discs skipped, max relative difference %.2e (%s)\n",
              compared, skipped, maxRel, (*gl)->description().c_str());
  EXPECT_EQ(bad, 0u);
  EXPECT_GT(compared, static_cast<std::size_t>(w * h * 9 / 10));
}

TEST(GlAirlightPass, MatchesCpuKernelsOnTheSameFrame) { expectGlMatchesCpu(benchLike(192, 108)); }

// One channel of a multi-screen cab: the view axis near the image's left edge and below its
// top (half-angles 10.6° left, 44.1° right, 6.6° up, 28.1° down; f = 166.3 px).
TEST(GlAirlightPass, MatchesCpuKernelsForAnOffAxisCamera) {
  Scene scene = benchLike(192, 108);
  scene.camera.principal_px = Vec2(31.0, 19.25);
  expectGlMatchesCpu(scene);
}

}  // namespace
}  // namespace fogbeam
