// The brute-force ray marcher (the benchmark's baseline) against the reference method.
#include <fogbeam/physics/photometry_io.hpp>
#include <fogbeam/render/raymarch.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <limits>
#include <string>

namespace fogbeam {
namespace {

Medium fog100m() {
  Medium m;
  m.extinction_per_m = extinctionFromVisibility(100.0);
  m.albedo = 1.0;
  m.phase = makeHenyeyGreenstein(0.85).value();
  return m;
}

Lamp lowBeam(Vec3 pos) {
  auto p = loadProfileFile(std::string(FOGBEAM_CONFIG_DIR) + "/lamps/low_beam.ies");
  EXPECT_TRUE(p.has_value());
  Lamp l;
  l.position_m = pos;
  l.profile = *p;
  return l;
}

Lamp streetLamp(Vec3 pos, double cd) {
  Lamp l;
  l.position_m = pos;
  l.profile = makeProfile(IsotropicProfile{cd}).value();
  return l;
}

Lamp spot(Vec3 pos, double yawDeg) {
  Lamp l;
  l.position_m = pos;
  l.worldFromLamp = worldFromYawPitchRoll(radians(yawDeg), radians(0.6), 0.0);
  l.profile = makeProfile(SpotProfile{20000.0, radians(4.0), radians(14.0)}).value();
  return l;
}

struct Case {
  const char* name;
  Lamp lamp;
  Ray ray;
};

double relError(double a, double ref) { return std::abs(a - ref) / std::abs(ref); }

TEST(RayMarch, ConvergesToReferenceAsStepsGrow) {
  const Medium m = fog100m();
  const Vec3 eye{0.0, 0.37, 1.2};
  const double inf = std::numeric_limits<double>::infinity();
  const Vec3 toRoad = glm::normalize(Vec3{30.0, -0.37, -1.2});
  const Vec3 ahead = glm::normalize(Vec3{1.0, 0.02, 0.01});
  const Vec3 upRight = glm::normalize(Vec3{1.0, -0.2, 0.15});
  const Case cases[] = {
      {"own low beam, ray to the road at 30 m", lowBeam({2.2, 0.7, 0.65}), Ray{eye, toRoad, glm::length(Vec3{30.0, -0.37, -1.2})}},
      {"own low beam, sky ray", lowBeam({2.2, -0.7, 0.65}), Ray{eye, ahead, inf}},
      {"street lamp 8 m high, sky ray", streetLamp({45.0, -2.5, 8.0}, 5000.0), Ray{eye, upRight, inf}},
      {"oncoming spot, ray ending at 60 m", spot({45.0, 3.5, 0.65}, 180.0), Ray{eye, ahead, 60.0}},
  };
  for (const Case& c : cases) {
    auto ref = AirlightEvaluator::build(c.lamp, m, AirlightMethod::Reference);
    ASSERT_TRUE(ref.has_value()) << ref.error().message;
    const double lRef = ref->evaluate(c.ray);
    ASSERT_GT(lRef, 1e-4) << c.name;
    const double e16 = relError(rayMarchAirlight(c.lamp, m, c.ray, 16), lRef);
    const double e256 = relError(rayMarchAirlight(c.lamp, m, c.ray, 256), lRef);
    const double e4096 = relError(rayMarchAirlight(c.lamp, m, c.ray, 4096), lRef);
    std::printf("%-40s ref %.5g cd/m2, rel. error N=16 %.2e, N=256 %.2e, N=4096 %.2e\n", c.name, lRef, e16, e256, e4096);
    EXPECT_LT(e4096, 0.01) << c.name;
    EXPECT_LT(e4096, e256 + 1e-6) << c.name;
    EXPECT_LT(e256, e16 + 1e-6) << c.name;
  }
}

TEST(RayMarch, SceneEvaluatorSumsLampsTimesColour) {
  Scene s;
  s.fog = fog100m();
  Lamp a = streetLamp({20.0, -2.5, 8.0}, 3000.0);
  a.color = {1.0, 0.5, 0.0};
  Lamp b = streetLamp({50.0, -2.5, 8.0}, 6000.0);
  s.lamps.push_back({"a", a});
  s.lamps.push_back({"b", b});
  auto ev = RayMarchEvaluator::build(s, 512);
  ASSERT_TRUE(ev.has_value()) << ev.error().message;
  const Ray ray{{0.0, 0.0, 1.2}, glm::normalize(Vec3{1.0, -0.1, 0.1}), 80.0};
  float rgb[3];
  ev->evaluateRay(ray, rgb);
  const double la = rayMarchAirlight(a, s.fog, ray, 512), lb = rayMarchAirlight(b, s.fog, ray, 512);
  EXPECT_NEAR(rgb[0], la + lb, 1e-5 * (la + lb));
  EXPECT_NEAR(rgb[1], 0.5 * la + lb, 1e-5 * (la + lb));
  EXPECT_NEAR(rgb[2], lb, 1e-5 * (la + lb));
}

TEST(RayMarch, RejectsZeroSteps) {
  Scene s;
  s.fog = fog100m();
  auto ev = RayMarchEvaluator::build(s, 0);
  ASSERT_FALSE(ev.has_value());
  EXPECT_NE(ev.error().message.find("step count"), std::string::npos);
}

}  // namespace
}  // namespace fogbeam
