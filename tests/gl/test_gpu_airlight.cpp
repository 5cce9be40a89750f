// The GPU airlight path (GlSurfacePass::setAirlight, shaders/airlight_accurate.frag) against the
// CPU's accurate method per ray on the same frame (the GL pass's own distances): the same
// product integration of the same G-moment table, with uniform pieces for measured profiles
// where the CPU also cuts at the profile's feature lines. On llvmpipe here; the shader is the
// same on a hardware GPU. Skips when no EGL/OpenGL is available (FOGBEAM_REQUIRE_GL=1: failure).
#include <fogbeam/gl/surface_pass.hpp>
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

std::shared_ptr<const Profile> shipped(const char* name) {
  auto p = loadProfileFile(std::string(FOGBEAM_CONFIG_DIR) + "/lamps/" + name);
  EXPECT_TRUE(p.has_value()) << name;
  return p.value();
}

SceneLamp lampAt(const char* name, Vec3 pos, std::shared_ptr<const Profile> profile, double yawDeg = 0.0,
                 double pitchDeg = 0.0, Vec3 color = {1, 1, 1}) {
  SceneLamp sl;
  sl.name = name;
  sl.lamp.position_m = pos;
  sl.lamp.worldFromLamp = worldFromYawPitchRoll(radians(yawDeg), radians(pitchDeg), 0.0);
  sl.lamp.profile = std::move(profile);
  sl.lamp.color = color;
  return sl;
}

// A night road: the ego car's low beams, an oncoming car's low beams, a street lamp, a spot,
// and a following car's high beam behind the eye (rays ahead look straight away from it).
Scene road(int w, int h, const Phase& phase) {
  Scene s;
  s.fog.extinction_per_m = extinctionFromVisibility(80.0);
  s.fog.albedo = 0.95;
  s.fog.phase = phase;
  s.camera.position_m = {0.0, 0.37, 1.2};
  s.camera.width = w;
  s.camera.height = h;
  s.lamps.push_back(lampAt("ego left", {2.2, 0.7, 0.65}, shipped("low_beam.ies")));
  s.lamps.push_back(lampAt("ego right", {2.2, -0.7, 0.65}, shipped("low_beam.ies")));
  s.lamps.push_back(lampAt("oncoming", {40.0, 3.5, 0.65}, shipped("low_beam.ies"), 180.0, 0.6));
  s.lamps.push_back(lampAt("street", {25.0, -6.0, 8.0}, makeProfile(IsotropicProfile{4000.0}).value(), 0.0, 0.0,
                           {1.0, 0.85, 0.6}));
  s.lamps.push_back(
      lampAt("spot", {30.0, -3.0, 4.0}, makeProfile(SpotProfile{20000.0, radians(4.0), radians(14.0)}).value(), 160.0,
             20.0));
  s.lamps.push_back(lampAt("following", {-14.0, 0.5, 0.65}, shipped("high_beam.ies")));
  s.planes.push_back(Plane{{0, 0, 0}, {0, 0, 1}, 0.15});
  return s;
}

struct Comparison {
  double p50 = 0, p95 = 0, p99 = 0, max = 0;
  double sumRatio = 0;  ///< Σ GPU / Σ CPU over the compared pixels
  std::size_t pixels = 0;
};

// GPU airlight of `scene` against the CPU accurate method per ray on the GPU's own distances:
// relative error of the luminance where the CPU's is above 1e-3 of the frame's median.
Comparison compareWithCpu(const Scene& scene, int pieces) {
  Comparison c;
  auto gl = GlSurfacePass::create();
  if (!gl) {
    const char* require = std::getenv("FOGBEAM_REQUIRE_GL");
    if (environmentFailure(gl.error().message) && !(require && std::string(require) == "1")) return c;
    ADD_FAILURE() << gl.error().message;
    return c;
  }
  GpuAirlightOptions opt;
  opt.pieces = pieces;
  EXPECT_TRUE((*gl)->setAirlight(opt).has_value());
  SurfaceBuffers surf;
  std::vector<float> gpu;
  const Status st = (*gl)->render(scene, surf, gpu);
  EXPECT_TRUE(st.has_value()) << (st ? "" : st.error().message);
  if (!st) return c;
  FastPathOptions perRay;
  perRay.enabled = false;
  auto ev = AirlightImageEvaluator::build(scene, AirlightMethod::Accurate, {}, 2, perRay);
  EXPECT_TRUE(ev.has_value());
  AirlightImage cpu;
  ev->evaluate(scene, surf, SubsamplingOptions{.full = true}, cpu);
  std::vector<double> lum(cpu.rgb.size() / 3);
  for (std::size_t k = 0; k < lum.size(); ++k)
    lum[k] = static_cast<double>(cpu.rgb[3 * k]) + static_cast<double>(cpu.rgb[3 * k + 1]) + static_cast<double>(cpu.rgb[3 * k + 2]);
  std::vector<double> sorted = lum;
  std::sort(sorted.begin(), sorted.end());
  const double floor = 1e-3 * sorted[sorted.size() / 2];
  std::vector<double> rel;
  double sumGpu = 0, sumCpu = 0;
  for (std::size_t k = 0; k < lum.size(); ++k) {
    if (!(lum[k] > floor)) continue;
    const double g = static_cast<double>(gpu[3 * k]) + static_cast<double>(gpu[3 * k + 1]) + static_cast<double>(gpu[3 * k + 2]);
    rel.push_back(std::abs(g - lum[k]) / lum[k]);
    sumGpu += g;
    sumCpu += lum[k];
  }
  c.sumRatio = sumCpu > 0 ? sumGpu / sumCpu : 0;
  std::sort(rel.begin(), rel.end());
  c.pixels = rel.size();
  if (!rel.empty()) {
    c.p50 = rel[rel.size() / 2];
    c.p95 = rel[rel.size() * 95 / 100];
    c.p99 = rel[rel.size() * 99 / 100];
    c.max = rel.back();
  }
  std::printf(
      "  GPU vs CPU accurate (%d pieces): median %.2e, p95 %.2e, p99 %.2e, max %.2e over %zu pixels; sum ratio %.6f "
      "(GPU draw %.0f ms, %s)\n",
      pieces, c.p50, c.p95, c.p99, c.max, c.pixels, c.sumRatio, (*gl)->stats().airlight_ms, (*gl)->description().c_str());
  return c;
}

TEST(GpuAirlight, MatchesTheCpuAccurateMethodInForwardScatteringFog) {
  const Comparison c = compareWithCpu(road(96, 54, makeHenyeyGreenstein(0.85).value()), 64);
  if (c.pixels == 0) GTEST_SKIP() << "no usable EGL/OpenGL";
  EXPECT_GT(c.pixels, 3000u);
  EXPECT_LT(c.p95, 0.01);
  EXPECT_LT(c.p99, 0.01);
  EXPECT_NEAR(c.sumRatio, 1.0, 1e-3);
}

TEST(GpuAirlight, MatchesTheCpuAccurateMethodForFogMie) {
  const Comparison c = compareWithCpu(road(80, 45, makeFogMie(10.0).value()), 64);
  if (c.pixels == 0) GTEST_SKIP() << "no usable EGL/OpenGL";
  EXPECT_GT(c.pixels, 2000u);
  EXPECT_LT(c.p95, 0.01);
  EXPECT_LT(c.p99, 0.01);
  EXPECT_NEAR(c.sumRatio, 1.0, 1e-3);
}

TEST(GpuAirlight, RefusesBadOptionsAndAFrameWithoutTheStage) {
  auto gl = GlSurfacePass::create();
  if (!gl) GTEST_SKIP() << gl.error().message;
  GpuAirlightOptions bad;
  bad.pieces = 0;
  EXPECT_FALSE((*gl)->setAirlight(bad).has_value());
  EXPECT_FALSE((*gl)->airlightEnabled());
  const Scene scene = road(16, 9, makeHenyeyGreenstein(0.85).value());
  SurfaceBuffers surf;
  std::vector<float> air;
  EXPECT_FALSE((*gl)->render(scene, surf, air).has_value());
  ASSERT_TRUE((*gl)->setAirlight(GpuAirlightOptions{}).has_value());
  EXPECT_TRUE((*gl)->airlightEnabled());
  ASSERT_TRUE((*gl)->render(scene, surf, air).has_value());
  EXPECT_EQ(air.size(), 3u * 16u * 9u);
  ASSERT_TRUE((*gl)->setAirlight(std::nullopt).has_value());
  ASSERT_TRUE((*gl)->submit(scene).has_value());
  EXPECT_FALSE((*gl)->collect(surf, air).has_value());
}

// The G table follows the options it is used with, also when the stage was off in between: a
// pass switched from the default table to a coarse one gives what a fresh pass with the coarse
// table gives, and not the default table's image.
TEST(GpuAirlight, TableFollowsItsResolutionAcrossOffAndOn) {
  auto gl = GlSurfacePass::create();
  if (!gl) GTEST_SKIP() << gl.error().message;
  const Scene scene = road(24, 14, makeHenyeyGreenstein(0.85).value());
  GpuAirlightOptions coarse;
  coarse.table.g_table_theta = 128;
  coarse.table.g_table_k = 24;
  SurfaceBuffers surf;
  std::vector<float> fine, switched, fresh;
  ASSERT_TRUE((*gl)->setAirlight(GpuAirlightOptions{}).has_value());
  ASSERT_TRUE((*gl)->render(scene, surf, fine).has_value());
  ASSERT_TRUE((*gl)->setAirlight(std::nullopt).has_value());
  ASSERT_TRUE((*gl)->render(scene, surf).has_value());
  ASSERT_TRUE((*gl)->setAirlight(coarse).has_value());
  ASSERT_TRUE((*gl)->render(scene, surf, switched).has_value());
  auto other = GlSurfacePass::create();
  ASSERT_TRUE(other.has_value()) << other.error().message;
  ASSERT_TRUE((*other)->setAirlight(coarse).has_value());
  ASSERT_TRUE((*other)->render(scene, surf, fresh).has_value());
  EXPECT_EQ(switched, fresh);
  EXPECT_NE(switched, fine);
}

}  // namespace
}  // namespace fogbeam
