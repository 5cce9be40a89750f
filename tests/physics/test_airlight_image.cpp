// The airlight layer: subsampled against full per-pixel evaluation, and the CPU surface layer
// against its formula. Scenes are built in code (the scene-file parser has its own tests).
#include <fogbeam/physics/photometry_io.hpp>
#include <fogbeam/render/airlight_image.hpp>
#include <fogbeam/render/surface.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

namespace fogbeam {
namespace {

Scene nightRoad(int width, int height) {
  Scene s;
  s.fog.extinction_per_m = extinctionFromVisibility(80.0);
  s.fog.albedo = 0.95;
  s.fog.phase = makeHenyeyGreenstein(0.85).value();
  s.camera.position_m = {0.0, 0.35, 1.2};
  s.camera.width = width;
  s.camera.height = height;
  auto low = loadProfileFile(std::string(FOGBEAM_CONFIG_DIR) + "/lamps/low_beam.ies");
  EXPECT_TRUE(low.has_value());
  auto add = [&](const char* name, Vec3 pos, double yawDeg) {
    Lamp l;
    l.position_m = pos;
    l.worldFromLamp = worldFromYawPitchRoll(radians(yawDeg), radians(0.57), 0.0);
    l.profile = *low;
    s.lamps.push_back({name, l});
  };
  add("ego-left", {2.0, 0.7, 0.65}, 0.0);
  add("ego-right", {2.0, -0.7, 0.65}, 0.0);
  add("oncoming-left", {45.0, 4.2, 0.65}, 180.0);
  add("oncoming-right", {45.0, 2.8, 0.65}, 180.0);
  Lamp street;
  street.position_m = {25.0, -6.0, 8.0};
  street.profile = makeProfile(IsotropicProfile{3000.0}).value();
  s.lamps.push_back({"street", street});
  s.planes.push_back(Plane{{0, 0, 0}, {0, 0, 1}, 0.15});
  return s;
}

TEST(AirlightImage, SubsampledMatchesFullWithinOnePercentP95) {
  const Scene scene = nightRoad(256, 144);
  SurfaceBuffers surf;
  renderSurfacesCpu(scene, surf);
  auto ev = AirlightImageEvaluator::build(scene, AirlightMethod::Accurate);
  ASSERT_TRUE(ev.has_value());
  AirlightImage full, sub;
  ev->evaluate(scene, surf, SubsamplingOptions{.full = true}, full);
  ev->evaluate(scene, surf, SubsamplingOptions{}, sub);
  ASSERT_EQ(full.evaluated, 256u * 144u);
  std::vector<double> rel;
  for (std::size_t k = 0; k < 256u * 144u; ++k) {
    const double a = full.rgb[3 * k], b = sub.rgb[3 * k];
    rel.push_back(std::abs(b - a) / std::max(a, 1e-3));
  }
  std::sort(rel.begin(), rel.end());
  const double p95 = rel[rel.size() * 95 / 100], mx = rel.back();
  std::printf("subsampled: %zu of %zu pixels evaluated (%.1f %%), p95 %.3g max %.3g; full %.0f ms, sub %.0f ms\n",
              sub.evaluated, full.evaluated, 100.0 * static_cast<double>(sub.evaluated) / static_cast<double>(full.evaluated),
              p95, mx, 1e3 * full.seconds, 1e3 * sub.seconds);
  EXPECT_LE(p95, 0.01);
  EXPECT_LT(sub.evaluated, full.evaluated / 2);
}

TEST(SurfaceCpu, RoadLitByOwnBeamMatchesLambertFormulaAndDistances) {
  Scene scene = nightRoad(160, 90);
  scene.fog.ambient_cd_m2 = 0.01;
  SurfaceBuffers surf;
  renderSurfacesCpu(scene, surf);
  // Pixel on the road: distance is the ray–plane distance, luminance the formula.
  const int i = 80, j = 70;
  const Vec3 d = scene.camera.rayDirection(i + 0.5, j + 0.5);
  const double t = -scene.camera.position_m.z / d.z;
  const auto k = static_cast<std::size_t>(j * 160 + i);
  EXPECT_NEAR(surf.distance[k], t, 1e-4 * t);
  const Vec3 x = scene.camera.position_m + t * d;
  double l = 0.0;
  for (const auto& sl : scene.lamps) l += lambertianLuminance(sl.lamp, scene.fog, x, {0, 0, 1}, 0.15);
  const double tr = std::exp(-scene.fog.extinction_per_m * t);
  EXPECT_NEAR(surf.rgb[3 * k], l * tr + 0.01 * (1 - tr), 1e-5 * l);
  // Sky above the horizon: infinite distance, ambient only.
  EXPECT_TRUE(std::isinf(surf.distance[5 * 160 + 80]));
  EXPECT_NEAR(surf.rgb[3 * (5 * 160 + 80)], 0.01, 1e-7);
}

}  // namespace
}  // namespace fogbeam
