// The veil of the road lit by the driver's own lamps (core/src/render/ground_veil.hpp): the
// integral over directions to the road against its closed form for a uniform road and an
// isotropic phase function, and the road map's light against the lamps' direct light.
#include "ground_veil.hpp"

#include "test_media.hpp"

#include <fogbeam/physics/profile.hpp>
#include <fogbeam/render/fog_light.hpp>

#include <boost/math/special_functions/expint.hpp>
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <limits>
#include <vector>

namespace fogbeam {
namespace {

// A uniform road of luminance L under a horizontal ray at height h, isotropic scattering: every
// point of the ray sees the road over its lower hemisphere through e^{−K_t h / μ} of fog, so
// S = L / (4π) · 2π ∫_0^1 e^{−K_t h / μ} dμ = (L / 2) E_2(K_t h), the same all along the ray, and
// L_v = Ω K_t ∫_0^{15/K_t} e^{−K_t u} S du = Ω (L / 2) E_2(K_t h) (1 − e^{−15}).
TEST(GroundVeil, AlongAHorizontalRayOverAUniformRoad) {
  ground_veil::RoadMap road;
  road.foot = Vec3(0.0, 0.0, 0.0);
  road.r0 = 0.2;
  road.rings = 64;
  road.sectors = 36;
  road.logStep = std::log(1e5 / road.r0) / (road.rings - 1);
  const double lum[3] = {0.5, 1.0, 2.0};  // cd/m² per channel
  road.rgb.resize(static_cast<std::size_t>(road.rings * road.sectors) * 3);
  for (std::size_t k = 0; k < road.rgb.size(); ++k) road.rgb[k] = static_cast<float>(lum[k % 3]);
  for (const double kt : {0.02, 0.06, 0.15}) {
    for (const double h : {0.5, 1.2, 4.0}) {
      Medium fog = test::hgFog(kt, 0.9);
      fog.phase = IsotropicPhase{};
      const ground_veil::Ground ground{0.0, 0.1};
      const Vec3 eye(3.0, -2.0, h);
      const Vec3 w = glm::normalize(Vec3(1.0, 0.4, 0.0));
      const double exact = 0.9 * 0.5 * boost::math::expint(2, kt * h) * (1.0 - std::exp(-15.0));
      double fine[3] = {0, 0, 0}, coarse[3] = {0, 0, 0};
      const double end = ground_veil::alongRay(road, fog, ground, eye, w, 60, fine, 24, 24);
      EXPECT_TRUE(std::isinf(end));
      ground_veil::alongRay(road, fog, ground, eye, w, 12, coarse, 12, 12);  // LampEffects' grid
      for (int k = 0; k < 3; ++k) {
        EXPECT_NEAR(fine[k], exact * lum[k], 0.02 * exact * lum[k]) << "K_t " << kt << " h " << h;
        EXPECT_NEAR(coarse[k], exact * lum[k], 0.05 * exact * lum[k]) << "K_t " << kt << " h " << h;
      }
    }
  }
  // A ray down to the road ends on it, and gathers less than the horizontal one of the same eye.
  Medium fog = test::hgFog(0.06);
  fog.phase = IsotropicPhase{};
  double down[3] = {0, 0, 0}, level[3] = {0, 0, 0};
  const double end = ground_veil::alongRay(road, fog, ground_veil::Ground{0.0, 0.1}, Vec3(0, 0, 1.2),
                                           glm::normalize(Vec3(1.0, 0.0, -0.1)), 60, down, 24, 24);
  ground_veil::alongRay(road, fog, ground_veil::Ground{0.0, 0.1}, Vec3(0, 0, 1.2), Vec3(1.0, 0.0, 0.0), 60, level, 24, 24);
  EXPECT_NEAR(end, 1.2 * std::sqrt(1.0 + 0.01) / 0.1, 1e-9);
  EXPECT_GT(down[1], 0.0);
  EXPECT_LT(down[1], level[1]);
}

// The road map holds ρ E / π of the lamps' direct light, E = I cos i e^{−K_t r} / r², bilinear
// between its nodes; a lamp below the road lights none of it; no lamp, no map.
TEST(GroundVeil, TheRoadMapIsTheLampsDirectLightReflected) {
  const Medium fog = test::hgFog(0.05);
  auto iso = makeProfile(IsotropicProfile{2000.0});
  ASSERT_TRUE(iso.has_value());
  ground_veil::Lamp lamp;
  lamp.position_m = Vec3(1.0, 0.5, 0.7);
  lamp.profile = *iso;
  lamp.color[0] = 1.0;
  lamp.color[1] = 0.5;
  lamp.color[2] = 0.25;
  const ground_veil::Ground ground{0.1, 0.2};
  const Vec3 eye(0.0, 0.0, 1.3);
  const ground_veil::RoadMap map = ground_veil::roadMap({lamp}, fog, ground, eye, 192, 360);
  ASSERT_FALSE(map.empty());
  for (const Vec3& x : {Vec3(6.0, 0.3, 0.1), Vec3(15.0, -4.0, 0.1), Vec3(-8.0, 2.0, 0.1), Vec3(40.0, 10.0, 0.1)}) {
    const Vec3 d = x - lamp.position_m;
    const double r = glm::length(d);
    const double e = 2000.0 * (0.6 / r) * std::exp(-0.05 * r) / (r * r);
    double got[3];
    map.at(x.x, x.y, got);
    for (int k = 0; k < 3; ++k) EXPECT_NEAR(got[k], 0.2 * e * lamp.color[k] / kPi, 0.01 * 0.2 * e / kPi) << x.x;
  }
  ground_veil::Lamp under = lamp;
  under.position_m.z = 0.0;
  EXPECT_TRUE(ground_veil::roadMap({under}, fog, ground, eye).empty());
  EXPECT_TRUE(ground_veil::roadMap({}, fog, ground, eye).empty());
  EXPECT_TRUE(ground_veil::roadMap({lamp}, fog, ground_veil::Ground{0.1, 0.0}, eye).empty());
}

// With the surfaces' fog light (`[glow] surfaces`) the road's light is ρ (E_direct + E_fog) / π,
// E_fog the fog light's model (fog_light.hpp) for the lamp and the road's normal: an isotropic
// lamp's bins all hold its intensity. Near the lamp in thick fog the fog light is a large part of
// the road's light (0.2–15× the direct light, docs/airlight.md); it never takes any away.
TEST(GroundVeil, TheRoadMapHoldsTheFogLightTheSurfacesShow) {
  const Medium fog = test::hgFog(0.05);
  auto iso = makeProfile(IsotropicProfile{2000.0});
  ASSERT_TRUE(iso.has_value());
  auto table = FogLightTable::shipped(fog.phase, fog.albedo);
  ASSERT_TRUE(table.has_value()) << table.error().message;
  ground_veil::Lamp lamp;
  lamp.position_m = Vec3(1.0, 0.5, 0.7);
  lamp.profile = *iso;
  const ground_veil::Ground ground{0.1, 0.2};
  const Vec3 eye(0.0, 0.0, 1.3);
  const ground_veil::RoadMap direct = ground_veil::roadMap({lamp}, fog, ground, eye, 192, 360);
  const ground_veil::RoadMap withFog = ground_veil::roadMap({lamp}, fog, ground, eye, 192, 360, nullptr, table->get());
  ASSERT_FALSE(withFog.empty());
  const std::vector<double> means((*table)->bins(), 2000.0);
  double lo = 1e300, hi = 0.0;
  for (const Vec3& x : {Vec3(6.0, 0.3, 0.1), Vec3(15.0, -4.0, 0.1), Vec3(-8.0, 2.0, 0.1), Vec3(40.0, 10.0, 0.1)}) {
    const Vec3 d = lamp.position_m - x;
    const double r = glm::length(d);
    const double eDirect = 2000.0 * (0.6 / r) * std::exp(-0.05 * r) / (r * r);
    const double eFog = 0.05 * 0.05 * (*table)->irradiance(0.05 * r, d.z / r, means.data());
    ASSERT_GT(eFog, 0.0) << x.x;
    double got[3], only[3];
    withFog.at(x.x, x.y, got);
    direct.at(x.x, x.y, only);
    EXPECT_NEAR(got[0], 0.2 * (eDirect + eFog) / kPi, 0.01 * 0.2 * (eDirect + eFog) / kPi) << x.x;
    EXPECT_NEAR(only[0], 0.2 * eDirect / kPi, 0.01 * 0.2 * eDirect / kPi) << x.x;
    lo = std::min(lo, eFog / eDirect);
    hi = std::max(hi, eFog / eDirect);
  }
  std::printf("  fog light / direct light on the road 6-40 m from a lamp 0.6 m above it (K_t 0.05 /m): %.2f-%.2f\n", lo, hi);
}

}  // namespace
}  // namespace fogbeam
