#include <fogbeam/physics/math.hpp>
#include <fogbeam/physics/medium.hpp>

#include <boost/math/quadrature/gauss_kronrod.hpp>
#include <gtest/gtest.h>

#include "test_scale.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <utility>

namespace fogbeam {
namespace {

// ∫ p dω over the sphere = 2π ∫_{−1}^{1} p(μ) dμ; the forward peak is split off at μ = 0.99.
//
// For fog-mie the rule's error estimate never gets below the 1e-12 asked, so it halves its
// intervals down to the depth limit (up to 2^20 pieces, 10^7 evaluations per integral) for the
// same digits: measured, depth 8 gives the same integrals to ~1e-12, and the bounds below are
// 1e-8. FOGBEAM_TEST_SCALE scales that budget of pieces (depth 18 at 0.25).
double sphereIntegral(const Phase& ph, int moment = 0) {
  auto f = [&](double mu) { return evalPhase(ph, mu) * (moment ? mu : 1.0); };
  using GK = boost::math::quadrature::gauss_kronrod<double, 61>;
  const unsigned depth = test::scaledDepth(20, 10);
  return 2.0 * kPi * (GK::integrate(f, -1.0, 0.99, depth, 1e-12) + GK::integrate(f, 0.99, 1.0, depth, 1e-12));
}

TEST(Math, FastAtan2AgreesWithTheLibraryWithinTwoUlp) {
  // fastAtan2 replaces std::atan2 in the pencil's rays: within 2 ulp over every octant and
  // 20 decades of magnitude, and the library's values at the signed zeros and infinities.
  std::uint64_t state = 12345;
  auto uniform = [&state] {  // xorshift64*: repeatable without <random>'s distributions
    state ^= state >> 12;
    state ^= state << 25;
    state ^= state >> 27;
    return static_cast<double>((state * 2685821657736338717ULL) >> 11) * 0x1.0p-53;
  };
  double worstUlp = 0.0;
  for (int i = 0; i < 400000; ++i) {
    const double y = (2.0 * uniform() - 1.0) * std::pow(10.0, 20.0 * uniform() - 10.0);
    const double x = (2.0 * uniform() - 1.0) * std::pow(10.0, 20.0 * uniform() - 10.0);
    const double want = std::atan2(y, x), got = fastAtan2(y, x);
    const double ulp = std::abs(std::nextafter(want, 10.0) - want);
    worstUlp = std::max(worstUlp, std::abs(got - want) / ulp);
  }
  EXPECT_LE(worstUlp, 2.0);
  const double inf = std::numeric_limits<double>::infinity();
  for (const auto& [y, x] : {std::pair{0.0, -1.0}, {-0.0, -1.0}, {0.0, 0.0}, {1.0, 0.0}, {-1.0, 0.0}, {inf, 1.0},
                             {1.0, -inf}, {-inf, -inf}, {3.0, 3.0}, {-2.0, 2.0}})
    EXPECT_EQ(fastAtan2(y, x), std::atan2(y, x)) << y << ", " << x;
  EXPECT_TRUE(std::isnan(fastAtan2(std::nan(""), 1.0)));
}

TEST(Phase, IsotropicIsNormalised) { EXPECT_NEAR(sphereIntegral(IsotropicPhase{}), 1.0, 1e-12); }

TEST(Phase, HenyeyGreensteinIsNormalisedForEveryG) {
  for (double g : {-0.9, -0.5, 0.0, 0.3, 0.6, 0.85, 0.9, 0.95}) {
    const Phase ph = makeHenyeyGreenstein(g).value();
    EXPECT_NEAR(sphereIntegral(ph), 1.0, 1e-9) << "g=" << g;
    EXPECT_NEAR(sphereIntegral(ph, 1), g, 1e-9) << "mean cosine, g=" << g;
  }
}

TEST(Phase, FogMieIsNormalisedAndForwardScatteringOverItsFittedRange) {
  for (double d : {5.0, 10.0, 20.0, 35.0, 50.0}) {
    const Phase ph = makeFogMie(d).value();
    EXPECT_NEAR(sphereIntegral(ph), 1.0, 1e-8) << "d=" << d;
    const double g = sphereIntegral(ph, 1);
    EXPECT_NEAR(meanCosine(ph), g, 1e-8) << "d=" << d;
    EXPECT_GT(g, 0.75) << "fog droplets scatter strongly forward, d=" << d;
    EXPECT_LT(g, 0.99);
  }
}

TEST(Phase, RejectsParametersOutsideTheirRange) {
  EXPECT_FALSE(makeHenyeyGreenstein(1.0).has_value());
  EXPECT_FALSE(makeHenyeyGreenstein(-1.0).has_value());
  EXPECT_FALSE(makeHenyeyGreenstein(std::nan("")).has_value());
  EXPECT_FALSE(makeFogMie(4.0).has_value());
  EXPECT_FALSE(makeFogMie(51.0).has_value());
  EXPECT_NE(makeFogMie(60.0).error().message.find("[5, 50]"), std::string::npos);
}

TEST(Medium, VisibilityIsMeteorologicalOpticalRangeAtFivePercent) {
  EXPECT_NEAR(extinctionFromVisibility(50.0), 0.0599146, 1e-6);  // ln 20 / 50
  EXPECT_NEAR(std::exp(-extinctionFromVisibility(123.0) * 123.0), 0.05, 1e-12);
  EXPECT_NEAR(visibilityFromExtinction(extinctionFromVisibility(75.0)), 75.0, 1e-12);
}

TEST(Medium, ValidationNamesTheBadField) {
  Medium m;
  m.extinction_per_m = 0.0;
  EXPECT_NE(m.validate().error().message.find("extinction_per_m"), std::string::npos);
  m.extinction_per_m = 0.05;
  m.albedo = 1.2;
  EXPECT_NE(m.validate().error().message.find("albedo"), std::string::npos);
  m.albedo = 0.9;
  m.ambient_cd_m2 = -1.0;
  EXPECT_NE(m.validate().error().message.find("ambient_cd_m2"), std::string::npos);
  m.ambient_cd_m2 = 0.0;
  EXPECT_TRUE(m.validate().has_value());
}

}  // namespace
}  // namespace fogbeam
