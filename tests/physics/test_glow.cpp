// Beyond single scattering (fogbeam/physics/glow.hpp): the Narasimhan–Nayar APSF series
// (convergence, energy normalisation, shape) and the CIE 146:2002 disability glare equation.
#include <fogbeam/physics/glow.hpp>

#include <boost/math/quadrature/gauss_kronrod.hpp>
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

namespace fogbeam {
namespace {

// The series converges: summing to a far smaller tolerance (many more terms) changes no value
// by more than the tolerance allows; below T = 1.1 it is refused.
TEST(Apsf, SeriesConverges) {
  for (double T : {1.2, 2.0, 4.0, 10.0})
    for (double q : {0.0, 0.5, 0.85, 0.95}) {
      auto coarse = Apsf::build(T, q, 1e-7);
      auto fine = Apsf::build(T, q, 1e-13);
      ASSERT_TRUE(coarse && fine) << T << " " << q;
      EXPECT_GT(fine->terms(), coarse->terms());
      // Relative to the peak (towards the lamp): the sum crosses 0 behind the eye.
      double worst = 0.0;
      const double peak = fine->series(1.0);
      for (double mu = -1.0; mu <= 1.0; mu += 0.05) worst = std::max(worst, std::abs(coarse->series(mu) - fine->series(mu)) / peak);
      EXPECT_LT(worst, 1e-5) << "T " << T << " q " << q;
      if (q == 0.85)
        std::printf("  APSF T = %.1f, q = 0.85: %d terms to 1e-7, %d to 1e-13; series at theta = 0: %.4g, 10 deg: %.4g, 90 deg: %.4g\n",
                    T, coarse->terms(), fine->terms(), fine->series(1.0), fine->series(std::cos(radians(10.0))),
                    fine->series(0.0));
    }
  EXPECT_FALSE(Apsf::build(1.0, 0.85).has_value());
  EXPECT_FALSE(Apsf::build(3.0, 1.0).has_value());
  EXPECT_FALSE(Apsf::build(3.0, -0.1).has_value());
}

// Energy: the net scattered flux through the sphere of radius R, 4πR² · 2π ∫ A μ dμ, over the
// source's power 4π I. Integrated over the Legendre sum numerically (not from the coefficients),
// it equals 1 + e^{−β_2 T}/T (only P_1 carries flux) and tends to 1 as the direct beam dies out:
// the normalisation C = 3 I K_t² / (4π) of glow.hpp.
TEST(Apsf, NetFluxCarriesTheSourcesPowerInTheDiffusionLimit) {
  const double kt = 0.03, I = 1000.0;
  for (double T : {2.0, 5.0, 10.0, 20.0, 40.0}) {
    for (double q : {0.5, 0.85}) {
      auto a = Apsf::build(T, q, 1e-12);
      ASSERT_TRUE(a.has_value());
      const double R = T / kt;
      auto f = [&](double mu) { return a->radiance(mu, I, kt) * mu; };
      const double flux = 4.0 * kPi * R * R * 2.0 * kPi *
                          boost::math::quadrature::gauss_kronrod<double, 61>::integrate(f, -1.0, 1.0, 15, 1e-12);
      const double ratio = flux / (4.0 * kPi * I);
      const double beta2 = 2.5 * (1.0 - q);
      EXPECT_NEAR(ratio, a->netFluxRatio(), 1e-6 * ratio) << T;
      EXPECT_NEAR(ratio, 1.0 + std::exp(-beta2 * T) / T, 1e-6) << T;
      if (T >= 10.0 && q == 0.85) {
        EXPECT_LT(ratio - 1.0, 3e-3) << T;
      }
      if (q == 0.85) std::printf("  APSF net flux / 4 pi I at T = %.0f: %.6f\n", T, ratio);
    }
  }
}

// Shape: more forward scattering (q) keeps the glow tighter around the lamp; more fog (T)
// spreads it. Measured as the share of the series at 10° against the lamp's direction.
TEST(Apsf, GlowNarrowsWithForwardScatteringAndSpreadsWithOpticalDistance) {
  auto spread = [](double T, double q) {
    auto a = Apsf::build(T, q, 1e-12);
    EXPECT_TRUE(a.has_value());
    return a->series(std::cos(radians(10.0))) / a->series(1.0);
  };
  EXPECT_LT(spread(3.0, 0.9), spread(3.0, 0.7));
  EXPECT_LT(spread(3.0, 0.7), spread(3.0, 0.3));
  EXPECT_LT(spread(1.5, 0.85), spread(3.0, 0.85));
  EXPECT_LT(spread(3.0, 0.85), spread(8.0, 0.85));
}

// CIE 146:2002: the general equation reduces to the small-angle one where pigmentation does
// not matter (θ ≤ 1°: within 1 %, 5 % up to 5°), pigmentation matters at wide angles, age raises the veil,
// and below 0.1° the value stays at the 0.1° one (the equation's domain).
TEST(DisabilityGlare, CieGeneralEquationMatchesItsLimits) {
  for (double th : {0.2, 0.5, 1.0, 2.0, 5.0})
    for (double age : {25.0, 45.0, 70.0}) {
      const double smallAngle = 10.0 / (th * th * th) + 5.0 / (th * th) * (1.0 + std::pow(age / 62.5, 4.0));
      const double tol = th <= 1.0 ? 0.01 : 0.05;  // the pigment term: 1.5 % at 2°, 4–5 % at 5°
      EXPECT_NEAR(veilingLuminancePerLux(th, age, 0.5), smallAngle, tol * smallAngle) << th << " " << age;
    }
  EXPECT_GT(veilingLuminancePerLux(60.0, 40.0, 1.0), 1.5 * veilingLuminancePerLux(60.0, 40.0, 0.0));
  EXPECT_GT(veilingLuminancePerLux(5.0, 75.0, 0.5), 1.5 * veilingLuminancePerLux(5.0, 25.0, 0.5));
  EXPECT_EQ(veilingLuminancePerLux(0.01, 40.0, 0.5), veilingLuminancePerLux(0.1, 40.0, 0.5));
  std::printf("  CIE 146 veil per lux (A = 40, p = 0.5): 1 deg %.3g, 5 deg %.3g, 20 deg %.3g cd/m2\n",
              veilingLuminancePerLux(1.0, 40, 0.5), veilingLuminancePerLux(5.0, 40, 0.5),
              veilingLuminancePerLux(20.0, 40, 0.5));
}

}  // namespace
}  // namespace fogbeam
