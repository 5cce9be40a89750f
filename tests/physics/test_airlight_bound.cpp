// AirlightBound (the most a lamp's single scattering can add to a ray at angle γ from it)
// against the accurate method per ray: never below it, for measured, spot and isotropic lamps,
// every phase function, finite and infinite rays; and tight where its two inequalities are
// equalities (thin fog, isotropic lamp and phase, a ray to infinity).
#include <fogbeam/physics/airlight.hpp>
#include <fogbeam/physics/airlight_bound.hpp>
#include <fogbeam/physics/math.hpp>
#include <fogbeam/physics/photometry_io.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>
#include <string>
#include <vector>

namespace fogbeam {
namespace {

std::shared_ptr<const Profile> shipped(const char* name) {
  auto p = loadProfileFile(std::string(FOGBEAM_CONFIG_DIR) + "/lamps/" + name);
  EXPECT_TRUE(p.has_value()) << name;
  return p.value();
}

// A unit vector at angle gamma from `axis`, at azimuth phi about it.
Vec3 atAngle(const Vec3& axis, double gamma, double phi) {
  const Vec3 a = glm::normalize(axis);
  const Vec3 t = glm::normalize(glm::cross(a, std::abs(a.z) < 0.9 ? Vec3(0, 0, 1) : Vec3(1, 0, 0)));
  const Vec3 b = glm::cross(a, t);
  return std::cos(gamma) * a + std::sin(gamma) * (std::cos(phi) * t + std::sin(phi) * b);
}

TEST(AirlightBound, NeverBelowTheAccurateMethod) {
  std::vector<std::shared_ptr<const Profile>> profiles{shipped("low_beam.ies"), shipped("tail_lamp.ies"),
                                                        shipped("high_beam.ies"), shipped("front_fog.ies")};
  profiles.push_back(makeProfile(IsotropicProfile{800.0}).value());
  profiles.push_back(makeProfile(SpotProfile{5000.0, radians(10.0), radians(25.0)}).value());
  std::vector<Phase> phases{IsotropicPhase{}, HenyeyGreensteinPhase{0.75}, HenyeyGreensteinPhase{0.9},
                            HenyeyGreensteinPhase{-0.3}, makeFogMie(10.0).value(), makeFogMie(40.0).value()};
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  int checked = 0, tightish = 0;
  double worst = 0.0;  // largest L / bound seen
  for (const Phase& phase : phases) {
    const AirlightBound bound(phase);
    for (const auto& profile : profiles) {
      for (int trial = 0; trial < 6; ++trial) {
        Medium fog;
        fog.extinction_per_m = std::log(20.0) / (30.0 + 300.0 * u(rng));
        fog.albedo = 0.8 + 0.2 * u(rng);
        fog.phase = phase;
        Lamp lamp;
        const double d = 3.0 + 150.0 * u(rng) * u(rng);
        const Vec3 eye(0.0, 0.0, 1.2);
        lamp.position_m = eye + atAngle(Vec3(1, 0, 0), kPi * u(rng), 2.0 * kPi * u(rng)) * d;
        lamp.worldFromLamp = worldFromYawPitchRoll(2.0 * kPi * u(rng), 0.5 * (u(rng) - 0.5), 0.0);
        lamp.profile = profile;
        auto ev = AirlightEvaluator::build(lamp, fog, AirlightMethod::Accurate);
        ASSERT_TRUE(ev.has_value()) << ev.error().message;
        const double f = AirlightBound::factor(profile->peak().intensity_cd, d, fog.extinction_per_m, fog.albedo);
        const Vec3 toLamp = (lamp.position_m - eye) / d;
        for (int r = 0; r < 24; ++r) {
          // Angles from 0.01° to 180°, denser near the lamp, where the bound matters.
          const double gamma = r == 23 ? kPi : radians(0.01) * std::pow(18000.0, u(rng));
          const Vec3 dir = atAngle(toLamp, gamma, 2.0 * kPi * u(rng));
          const double len = u(rng) < 0.3 ? std::numeric_limits<double>::infinity() : 2.0 * d * u(rng) + 0.5;
          const double l = ev->evaluate(Ray{eye, dir, len});
          const double b = f * bound.scale(gamma);
          ASSERT_LE(l, b * (1.0 + 1e-6) + 1e-12)
              << describe(phase) << " lamp " << profile->peak().intensity_cd << " cd at " << d << " m, gamma "
              << gamma * 180.0 / kPi << " deg, ray " << len << " m";
          if (l > 0.0) worst = std::max(worst, l / b);
          if (l > 0.1 * b) ++tightish;
          ++checked;
        }
      }
    }
  }
  // Not vacuous: some rays come within a factor of 10 of the bound.
  EXPECT_GT(tightish, 10) << "of " << checked;
  std::printf("%d rays; the largest L / bound %.3f; %d within a factor of 10\n", checked, worst, tightish);
}

// Thin fog, isotropic lamp and phase function, a ray to infinity: I = I_max, u + r ≈ D and the
// integral runs to θ = π/2, so the bound is the airlight itself (to O(K_t D)).
TEST(AirlightBound, TightWhereItsInequalitiesAreEqualities) {
  const AirlightBound bound(IsotropicPhase{});
  Medium fog;
  fog.extinction_per_m = 1e-6;
  fog.albedo = 1.0;
  fog.phase = IsotropicPhase{};
  Lamp lamp;
  lamp.position_m = Vec3(20.0, 0.0, 0.0);
  lamp.profile = makeProfile(IsotropicProfile{1000.0}).value();
  auto ev = AirlightEvaluator::build(lamp, fog, AirlightMethod::Accurate);
  ASSERT_TRUE(ev.has_value());
  const double f = AirlightBound::factor(1000.0, 20.0, 1e-6, 1.0);
  for (double deg : {2.0, 10.0, 45.0, 90.0, 135.0}) {
    const double g = radians(deg);
    const double l = ev->evaluate(Ray{Vec3(0.0), Vec3(std::cos(g), std::sin(g), 0.0), std::numeric_limits<double>::infinity()});
    const double b = f * bound.scale(g);
    EXPECT_LE(l, b) << deg;
    EXPECT_GT(l, 0.98 * b) << deg;  // the table's steps (0.044°) and e^{−K_t(u + r)} ≤ e^{−K_t D}
  }
}

TEST(AirlightBound, ConeHalfAngleIsWhereTheBoundFallsBelowTheLimit) {
  const AirlightBound bound(HenyeyGreensteinPhase{0.85});
  const double f = AirlightBound::factor(30000.0, 200.0, std::log(20.0) / 100.0, 1.0);
  for (double limit : {1e-2, 1e-3, 1e-4}) {
    const double cone = bound.coneHalfAngle(f, limit);
    ASSERT_LT(cone, kPi) << limit;
    EXPECT_LE(f * bound.scale(cone), limit);
    EXPECT_GT(f * bound.scale(cone - kPi / AirlightBound::kIntervals), limit);  // the smallest such node
  }
  // Wider for smaller limits; none when the limit is below the bound everywhere; the eye at the lamp.
  EXPECT_LT(bound.coneHalfAngle(f, 1e-2), bound.coneHalfAngle(f, 1e-4));
  EXPECT_GT(bound.coneHalfAngle(f, 1e-12), kPi);
  EXPECT_GT(bound.coneHalfAngle(AirlightBound::factor(1.0, 0.0, 0.03, 1.0), 1.0), kPi);
  EXPECT_GT(bound.coneHalfAngle(f, 0.0), kPi);
}

}  // namespace
}  // namespace fogbeam
